"""Which shots the joint refinement's points tie together (:mod:`plenocal.calib.refine`),
and where the groups they leave apart go.

Rule view_matches matches each shot with its nearest shots only, which split two captures
of ten in two: then one held frame fixes its own group only, and each other group is put
back where Eq. 6 places it relative to the held one (:func:`shot_groups`,
:func:`place_groups`; refine.json's ``shot_groups`` and a warning say so).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from plenocal.calib.groups import Groups
from plenocal.calib.rig_model import RigModel, frame_poses, rigid3d
from plenocal.camera import invert_pose, pose

if TYPE_CHECKING:
    from pycolmap import Reconstruction


def shot_groups(ties: list[frozenset[str]], shots: Iterable[str]) -> list[list[str]]:
    """The shots as the points ``ties`` (:func:`point_shots`) tie them: two shots are in
    one group where a chain of points links them. Several groups where the matches leave
    them apart (rule view_matches pairs each shot with its nearest shots only, which can
    split the array in two): then no point fixes where one group lies relative to another.
    Each group sorted, the groups by their first shot."""
    groups = Groups(shots)
    for seen in ties:
        first, *rest = sorted(seen)
        for other in rest:
            groups.join(other, first)
    return groups.groups()


def point_shots(rec: Reconstruction, model: RigModel) -> list[frozenset[str]]:
    """The shots that see each of the adjustment's points (those seen by two or more: the
    points that tie shots together)."""
    shot_of_frame = {fid: shot for shot, fid in model.frame_of_shot.items()}
    # each image's shot looked up once, not once per observation (1.2 million on the
    # default data: 2.6 -> 1.2 s, the same sets)
    shot_of_image = {i: shot_of_frame[rec.image(i).frame_id] for i in rec.images}
    out = []
    for pid in rec.point3D_ids():
        seen = frozenset(shot_of_image[el.image_id] for el in rec.point3D(pid).track.elements)
        if len(seen) > 1:
            out.append(seen)
    return out


def shot_ties(ties: list[frozenset[str]], shots: list[str],
              to: set[str] | None = None) -> dict[str, int]:
    """Per shot of ``shots``, how many of the points ``ties`` (:func:`point_shots`) it
    shares with another shot, or with one of the shots ``to``: the points that tie its
    pose to them (a shot whose points are its own only is held by nothing but the loss and
    the solver's steps)."""
    out = dict.fromkeys(shots, 0)
    for seen in ties:
        for shot in seen:
            if shot in out and (seen - {shot}) & (seen if to is None else to):
                out[shot] += 1
    return out


def place_groups(rec: Reconstruction, model: RigModel, eq6_poses: Mapping[str, np.ndarray],
                 groups: list[list[str]], hold_shot: str) -> dict[str, float]:
    """Put every group of shots (:func:`shot_groups`) that the held shot's does not hold
    where Eq. 6 puts it relative to that group: the gauge of the adjustment is one rigid
    motion per group (the rig, shared by all, fixes one scale for all), and the held frame
    fixes only its own group's; the others drift along theirs as the solver's steps take
    them (on a capture of the wide geometry, 6.7 mm along the views' axes while the rig's
    baselines rescaled the array by 1.7 %). The similarity that best maps the held group's
    Eq. 6 poses onto its adjusted ones (:func:`plenocal.verify.gt_errors.pose_similarity`)
    carries Eq. 6's other poses into the adjustment's frame; each other group, frames and
    points, is moved by the rigid motion that best fits it onto them (which leaves every
    reprojection as it is). Returns each moved group's correction (mm, largest centre
    move) by its first shot."""
    from plenocal.verify.gt_errors import pose_similarity  # noqa: PLC0415

    ref = next(g for g in groups if hold_shot in g)
    now = frame_poses(rec, model)

    def fit(shots, src, dst, with_scale):
        return pose_similarity(np.array([src[k][:3, 3] for k in shots]),
                               np.array([dst[k][:3, 3] for k in shots]),
                               [src[k][:3, :3] for k in shots],
                               [dst[k][:3, :3] for k in shots], with_scale=with_scale)

    s, R, t = fit(ref, eq6_poses, now, len(ref) > 1)
    target = {k: pose(R @ M[:3, :3], s * R @ M[:3, 3] + t) for k, M in eq6_poses.items()}
    moved = {}
    for group in groups:
        if group is ref:
            continue
        _, Rg, tg = fit(group, now, target, False)
        G = pose(Rg, tg)
        for shot in group:
            rec.frame(model.frame_of_shot[shot]).rig_from_world = rigid3d(
                invert_pose(G @ now[shot]))
        frames = {model.frame_of_shot[k] for k in group}
        for pid in rec.point3D_ids():
            p = rec.point3D(pid)
            if rec.image(p.track.elements[0].image_id).frame_id in frames:
                p.xyz = Rg @ np.asarray(p.xyz, dtype=float) + tg
        moved[group[0]] = 1000.0 * max(float(np.linalg.norm(G[:3, :3] @ now[k][:3, 3] + tg
                                                            - now[k][:3, 3])) for k in group)
    return moved
