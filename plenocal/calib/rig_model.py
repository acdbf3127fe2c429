"""The joint refinement's COLMAP model (:mod:`plenocal.calib.refine`): one rig, a frame per
shot, a sensor per view, and what the refinement reads and sets of it.

* :func:`rig_reconstruction_of` builds a ``pycolmap.Reconstruction`` of one rig: each
  shot one frame (``rig_from_world``), each view one sensor (``sensor_from_rig``, the
  inverse of registration B's ``cam_to_central``; the central view the reference
  sensor), each sensor one PINHOLE camera shared by all shots;
* the frames' poses and centres, the rig's sensors, the cameras' focal lengths and
  principal points are read (:func:`frame_poses`, :func:`sensor_params`,
  :func:`shared_focal`, :func:`principal_points`) and set (:func:`set_intrinsics`,
  :func:`set_rig`, :func:`turn_frames`, :func:`rescale`);
* each image's camera (:func:`cameras_of`) and each observation's reprojection error
  (:func:`observation_errors`) in the internal convention.

Conventions: internal (OpenCV axes, camera-to-world, pixel centres at integers) in and
out; COLMAP's (cam_from_world, pixel centres at +0.5) only inside, through
:mod:`plenocal.calib.reg_a.colmap`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from plenocal.calib.reg_a import colmap as cm
from plenocal.camera import PinholeCamera, invert_pose, k_to_colmap
from plenocal.names import middle_view, split_key

if TYPE_CHECKING:
    from pycolmap import Reconstruction, Rigid3d, sensor_t


def rigid3d(M: np.ndarray) -> Rigid3d:
    """A 4x4 (or 3x4) rigid transform as a ``pycolmap.Rigid3d`` (rotation re-orthonormalised
    by SVD, as :func:`plenocal.calib.reg_a.colmap._rigid` does)."""
    import pycolmap  # noqa: PLC0415

    M = np.asarray(M, dtype=float)
    U, _, Vt = np.linalg.svd(M[:3, :3])
    return pycolmap.Rigid3d(pycolmap.Rotation3d(U @ Vt), M[:3, 3].copy())


def _camera_sensor(camera_id: int) -> sensor_t:
    import pycolmap  # noqa: PLC0415

    return pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=int(camera_id))


def colmap_params(K: np.ndarray) -> list[float]:
    Kc = k_to_colmap(K)
    return [float(Kc[0, 0]), float(Kc[1, 1]), float(Kc[0, 2]), float(Kc[1, 2])]


@dataclass
class RigModel:
    """The rig reconstruction's bookkeeping: sensor camera ids by view, frame ids by shot,
    the reference (central) view."""

    camera_of_view: dict[str, int]
    frame_of_shot: dict[str, int]
    central: str


def rig_reconstruction_of(image_names: Mapping[int, str],
                          points: Mapping[int, tuple[np.ndarray, list[tuple[int, int]]]],
                          keypoints: Mapping[str, np.ndarray],
                          views: Mapping[str, tuple[np.ndarray, np.ndarray]],
                          shot_poses: Mapping[str, np.ndarray], width: int, height: int
                          ) -> tuple[Reconstruction, RigModel]:
    """:func:`~plenocal.calib.track_sets.rig_reconstruction` of plain data: ``image_names``
    image id -> ``<shot>/<view>.png``, ``points`` point id -> (X, its track's (image id,
    keypoint index) pairs), added in the mapping's order, ``keypoints`` image name -> (n, 2)
    COLMAP's convention (:class:`plenocal.calib.central_tracks.TrackSet` holds the three)."""
    import pycolmap  # noqa: PLC0415

    names = sorted(views)
    central = identity_view(views)
    rec = pycolmap.Reconstruction()
    cam_of = {v: i + 1 for i, v in enumerate(names)}
    for v in names:
        rec.add_camera(pycolmap.Camera(model="PINHOLE", width=int(width), height=int(height),
                                       params=colmap_params(views[v][0]),
                                       camera_id=cam_of[v]))
    rig = pycolmap.Rig(rig_id=1)
    rig.add_ref_sensor(_camera_sensor(cam_of[central]))
    for v in names:
        if v != central:
            rig.add_sensor(_camera_sensor(cam_of[v]), rigid3d(invert_pose(views[v][1])))
    rec.add_rig(rig)
    images = {}
    for image_id in sorted(image_names):
        name = image_names[image_id]
        shot, view = split_key(name[:-4])
        if shot not in shot_poses or view not in cam_of:
            raise ValueError(f"{name}: not a view of the rig's shots")
        images[image_id] = (shot, view, name)
    shots = sorted(shot_poses)
    frame_of = {s: i + 1 for i, s in enumerate(shots)}
    for s in shots:
        frame = pycolmap.Frame(frame_id=frame_of[s], rig_id=1)
        frame.rig_from_world = rigid3d(invert_pose(shot_poses[s]))
        for image_id, (shot, view, _) in images.items():
            if shot == s:
                frame.add_data_id(pycolmap.data_t(sensor_id=_camera_sensor(cam_of[view]),
                                                  id=image_id))
        rec.add_frame(frame)
    for image_id, (shot, view, name) in images.items():
        new = pycolmap.Image(name=name, keypoints=keypoints[name],
                             camera_id=cam_of[view], image_id=image_id)
        new.frame_id = frame_of[shot]
        rec.add_image(new)
    for s in shots:
        rec.register_frame(frame_of[s])
    for xyz, elements in points.values():
        track = pycolmap.Track()
        for image_id, idx in elements:
            track.add_element(int(image_id), int(idx))
        rec.add_point3D(np.asarray(xyz, float), track)
    return rec, RigModel(cam_of, frame_of, central)


def cameras_of(rec: Reconstruction) -> dict[str, PinholeCamera]:
    """Every image of a rig reconstruction -> its camera (internal convention)."""
    out = {}
    for image_id in sorted(rec.images):
        im = rec.image(image_id)
        out[im.name[:-4]] = cm.pinhole_from_colmap(im, rec.camera(im.camera_id))
    return out


def observation_errors(rec: Reconstruction, work_dir: str | Path | None = None) -> np.ndarray:
    """Reprojection error (px) of every observation of ``rec``'s points, in the internal
    convention (read back through COLMAP's binary files, as Table I reads them)."""
    from plenocal.verify import reprojection as rp  # noqa: PLC0415

    obs, ids, xyz = rp.read_model(rec, work_dir)
    cams = cameras_of(rec)
    errs = [np.linalg.norm(cams[name[:-4]].project(xyz[rows])[0] - uv, axis=1)
            for name, rows, uv in rp.image_observations(obs, ids, sorted(obs))]
    return np.concatenate(errs) if errs else np.zeros(0)


def frame_centres(rec: Reconstruction, model: RigModel) -> dict[str, np.ndarray]:
    """Each shot's rig (central view) centre, world coordinates (:func:`frame_poses`)."""
    return {shot: M[:3, 3] for shot, M in frame_poses(rec, model).items()}


def spread(centres: Mapping[str, np.ndarray]) -> float:
    """RMS distance of the centres from their mean: the array's size."""
    P = np.array([centres[k] for k in sorted(centres)])
    return float(np.sqrt(((P - P.mean(axis=0)) ** 2).sum(axis=1).mean()))


def frame_poses(rec: Reconstruction, model: RigModel) -> dict[str, np.ndarray]:
    """Each shot's rig (central view) cam_to_world, world coordinates."""
    out = {}
    for shot, fid in model.frame_of_shot.items():
        M = np.eye(4)
        M[:3, :] = np.asarray(rec.frame(fid).rig_from_world.matrix(), dtype=float)
        out[shot] = invert_pose(M)
    return out


def rescale(rec: Reconstruction, factor: float) -> None:
    """Scale ``rec`` by ``factor`` about the world origin: its points, its frames and its
    rig's sensor translations (COLMAP's ``Reconstruction.transform`` scales all three), a
    gauge of the adjustment wherever the rig's size is not held."""
    import pycolmap  # noqa: PLC0415

    rec.transform(pycolmap.Sim3d(float(factor), pycolmap.Rotation3d(), np.zeros(3)))


def sensor_params(rec: Reconstruction) -> dict[int, np.ndarray]:
    """The rig's sensor_from_rig parameters (quaternion xyzw, translation) by camera id."""
    rig = rec.rig(1)
    return {s.id: np.asarray(rig.sensor_from_rig(s).params, dtype=float).copy()
            for s in rig.non_ref_sensors}


def shared_focal(rec: Reconstruction, model: RigModel) -> tuple[float, dict[str, float]]:
    """The mean of the sensors' focal lengths (fx, fy) weighted by their observations,
    and each sensor's."""
    counts = {cid: 0 for cid in model.camera_of_view.values()}
    for image_id in rec.images:
        im = rec.image(image_id)
        counts[im.camera_id] += im.num_points3D
    per = {v: 0.5 * float(rec.camera(cid).params[0] + rec.camera(cid).params[1])
           for v, cid in model.camera_of_view.items()}
    w = np.array([counts[model.camera_of_view[v]] for v in sorted(per)], dtype=float)
    f = np.array([per[v] for v in sorted(per)])
    if w.sum() <= 0:
        raise ValueError("refinement: no sensor has an observation")
    return float((w * f).sum() / w.sum()), per


def set_intrinsics(rec: Reconstruction, model: RigModel,
                   views: Mapping[str, tuple[np.ndarray, np.ndarray]],
                   offsets: Mapping[str, np.ndarray] | None = None) -> None:
    """Each sensor's camera as ``views`` gives it (registration B's K); with ``offsets``
    (view -> (dx, dy) px), its principal point moved by them."""
    for v, cid in model.camera_of_view.items():
        params = colmap_params(views[v][0])
        if offsets is not None:
            params[2] += float(offsets[v][0])
            params[3] += float(offsets[v][1])
        rec.camera(cid).params = params


def principal_points(rec: Reconstruction, model: RigModel) -> dict[str, np.ndarray]:
    """Each view's principal point (COLMAP's pixel convention), px."""
    return {v: np.array(rec.camera(cid).params[2:4], dtype=float)
            for v, cid in model.camera_of_view.items()}


def turn_of_shift(shift_px: np.ndarray, focal_px: float) -> np.ndarray:
    """The turn of a camera (3 x 3, applied to camera coordinates: x right, y down, z
    forward) that moves its image as the shift ``shift_px`` = (dx, dy) of its principal
    point does, exactly at the image centre, to first order elsewhere: the least rotation
    that takes the optical axis to the direction (dx / f, dy / f, 1), about the axis
    (-dy, dx, 0) by ``atan(|shift| / f)`` (Rodrigues' formula)."""
    d = np.asarray(shift_px, dtype=float)
    norm = float(np.hypot(d[0], d[1]))
    if norm == 0.0:
        return np.eye(3)
    k = np.array([-d[1], d[0], 0.0]) / norm
    angle = math.atan(norm / focal_px)
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * Kx + (1.0 - math.cos(angle)) * (Kx @ Kx)


def turn_frames(rec: Reconstruction, model: RigModel, turn: np.ndarray, hold_shot: str) -> None:
    """Turn every frame of ``rec`` by ``turn`` in its own (rig) axes, and the world about
    the held shot's rig so that its frame keeps its pose: with ``H`` the held frame's
    rig_from_world, the points go to ``T p`` with ``T = H^-1 R H`` and each frame's
    rig_from_world ``F`` to ``R F T^-1`` (for the held one ``H`` again). What every frame
    sees moves as if each view's principal point had moved by the shift of
    :func:`turn_of_shift`: the common shift of the focal pass taken back into the frames
    (:func:`~plenocal.calib.refine.warm_start`)."""
    R4 = np.eye(4)
    R4[:3, :3] = turn
    H = np.eye(4)
    H[:3, :] = np.asarray(rec.frame(model.frame_of_shot[hold_shot]).rig_from_world.matrix(),
                          dtype=float)
    T = invert_pose(H) @ R4 @ H
    A, b = T[:3, :3], T[:3, 3]
    for pid in rec.point3D_ids():
        point = rec.point3D(pid)
        point.xyz = A @ np.asarray(point.xyz, dtype=float) + b
    T_inv = invert_pose(T)
    for fid in sorted(model.frame_of_shot.values()):
        F = np.eye(4)
        F[:3, :] = np.asarray(rec.frame(fid).rig_from_world.matrix(), dtype=float)
        rec.frame(fid).rig_from_world = rigid3d(R4 @ F @ T_inv)


def set_rig(rec: Reconstruction, model: RigModel,
            views: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> None:
    rig = rec.rig(1)
    for v, cid in model.camera_of_view.items():
        if v != model.central:
            rig.set_sensor_from_rig(_camera_sensor(cid), rigid3d(invert_pose(views[v][1])))


def identity_view(views: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> str:
    """The rig's view at the identity pose, its central view (``views``:
    :meth:`RigB.view_poses`; by pose, where :func:`plenocal.names.central_view` names it by
    the grid's size)."""
    central = [v for v in views if np.allclose(views[v][1], np.eye(4), atol=1e-12)]
    if len(central) != 1:
        raise ValueError("the rig has no view at the identity pose (its central view): "
                         "rerun rule rig_b")
    return central[0]


def with_focal(K: np.ndarray, focal: float) -> np.ndarray:
    out = np.array(K, dtype=float)
    out[0, 0] = out[1, 1] = focal
    return out


def rig_views_from_model(rec: Reconstruction, model: RigModel) -> dict[str, np.ndarray]:
    """The rig's sensors as cam_to_central (internal), by view."""
    rig = rec.rig(1)
    out = {model.central: np.eye(4)}
    for v, cid in model.camera_of_view.items():
        if v != model.central:
            M = np.eye(4)
            M[:3, :] = np.asarray(rig.sensor_from_rig(_camera_sensor(cid)).matrix(), dtype=float)
            out[v] = invert_pose(M)
    return out


def rig_views_from_cameras(cameras: Mapping[str, PinholeCamera], shot: str,
                           central: str | None = None) -> dict[str, np.ndarray]:
    """The rig as a calibration places one shot's views: view -> cam_to_central (the
    central view ``central``, by default the centre of the shot's N x N names)."""
    names = sorted(split_key(k)[1] for k in cameras if split_key(k)[0] == shot)
    if not names:
        raise ValueError(f"no view of shot {shot}")
    c = central or middle_view(names)
    inv = invert_pose(cameras[f"{shot}/{c}"].cam_to_world)
    return {v: inv @ cameras[f"{shot}/{v}"].cam_to_world for v in names}
