"""Where the complete calibration's error comes from (issue 32): the paper's Eq. 6 result,
``M_ij = M_i^A M_j^B`` with M_i^A scaled by the merge's r (Eq. 5's, or the stage's step
where ``scale.reference`` chose it: ``scale.json``'s ``chosen``), split into its sources by
putting the truth in place of all but one of them.

The sources:

registration A's focal length
    The complete calibration takes it as it is. Its statistical uncertainty
    (``focal_std_pct``) is what registration A's own bundle adjustment says of it
    (:func:`plenocal.calib.reg_a.uncertainty.focal_std_px`): the shots of an array are parallel and
    a parallel array does not fix the focal length (it trades off against depth); only the
    hand-held shots' rotations and forward offsets do, and with them the hand-held geometry
    (``handheld``: how far their axes turn from the array's) sets the focal length's
    precision.
registration A's poses
    The shots' centres and orientations, after A's own similarity to the truth, for the
    array and the hand-held shots apart.
the merge's scale
    the r the merge used (Eq. 5's or the step's) against the true r; ``scale_source``
    names which. Eq. 5's own r is judged apart (``gt_errors``' ``scale.r_eq5_err_pct``).
the rig (registration B)
    Every view's place in its set against the true set.

For each of A's poses, the scale and the rig, ``only_<source>`` is the complete
calibration built from the truth with that one source as estimated (rigid alignment to the
truth, as :func:`plenocal.verify.gt_errors.complete_errors` aligns): its centre RMSE and
largest rotation error are that source's share of the error. The focal length enters the
result as the views' K only (its effect on the poses is inside A's poses). ``dominant``
names the source with the largest share of the centres' error.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from plenocal.artifacts.reg_a import RegistrationA
from plenocal.camera import PinholeCamera, invert_pose
from plenocal.names import central_view, is_handheld_shot, key_shot, key_view, view_key


def _rms(v: list[float]) -> float | None:
    return float(np.sqrt(np.mean(np.square(v)))) if v else None


def compose(shot_poses: Mapping[str, np.ndarray],
            set_poses: Mapping[str, Mapping[str, np.ndarray]],
            truth: Mapping[str, PinholeCamera]) -> dict[str, PinholeCamera]:
    """Eq. 6 with given parts: view j of shot i at ``shot_poses[i] @ set_poses[i][j]``
    (camera-to-world, cam_to_central), with the truth's K and size (the focal length is
    judged on its own)."""
    out = {}
    for shot, M in shot_poses.items():
        for view, B in set_poses[shot].items():
            key = view_key(shot, view)
            if key in truth:
                t = truth[key]
                out[key] = PinholeCamera(t.K, np.asarray(M) @ np.asarray(B), t.width, t.height)
    return out


def true_sets(truth: Mapping[str, PinholeCamera], n_views: int
              ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, np.ndarray]]]:
    """The truth as Eq. 6's parts: each shot's central-view pose, and each view's pose in
    its shot's central frame."""
    c = central_view(n_views)
    shots = sorted({key_shot(k) for k in truth if key_view(k) == c})
    poses = {s: truth[view_key(s, c)].cam_to_world for s in shots}
    sets = {}
    for s in shots:
        inv = invert_pose(poses[s])
        sets[s] = {key_view(k): inv @ cam.cam_to_world for k, cam in truth.items()
                   if key_shot(k) == s}
    return poses, sets


def _errors(calib: Mapping[str, PinholeCamera], truth: Mapping[str, PinholeCamera]) -> dict:
    from plenocal.verify.gt_errors import complete_errors  # noqa: PLC0415

    e = complete_errors(calib, truth)
    return {"centre_rmse_mm": e["centre_rmse_mm"], "rotation_max_deg": e["rotation_err_deg"]["max"]}


def handheld_geometry(truth: Mapping[str, PinholeCamera], n_views: int) -> dict:
    """How far the hand-held shots' optical axes turn from the array's (true poses): the
    lever that fixes registration A's focal length."""
    c = central_view(n_views)
    axes = {key_shot(k): cam.R[:, 2] for k, cam in truth.items() if key_view(k) == c}
    array = [a for s, a in axes.items() if not is_handheld_shot(s)]
    hand = {s: a for s, a in axes.items() if is_handheld_shot(s)}
    if not array or not hand:
        return {"count": len(hand), "axis_angle_deg": None}
    mean = np.mean(array, axis=0)
    mean /= np.linalg.norm(mean)
    ang = [float(np.degrees(np.arccos(np.clip(a @ mean, -1.0, 1.0)))) for a in hand.values()]
    return {"count": len(hand), "axis_angle_deg": {"mean": float(np.mean(ang)),
                                                   "max": float(np.max(ang)),
                                                   "min": float(np.min(ang))}}


def error_sources(truth: Mapping[str, PinholeCamera], reg_a: RegistrationA,
                  rig_views: Mapping[str, np.ndarray], r: float, gt: Mapping,
                  focal_std_px: float | None = None, scale_source: str = "eq5") -> dict:
    """The split of the Eq. 6 result's error (module docstring). ``rig_views``: view ->
    cam_to_central of registration B; ``r``: the scale the merge used, ``scale_source``
    which one (``scale.json``'s ``chosen``: ``eq5`` or ``array_step``); ``gt``: the document of
    :func:`plenocal.verify.gt_errors.gt_errors` (its registration A and scale figures);
    ``focal_std_px``: registration A's focal length's standard deviation, where known."""
    a = gt["registration_a"]
    n = int(gt["n_views"])
    c = central_view(n)
    poses_t, sets_t = true_sets(truth, n)
    shots = sorted(s for s in poses_t if s in reg_a.poses)
    poses_t = {s: poses_t[s] for s in shots}
    # A's poses aligned to the truth by A's own similarity (its scale the true r)
    from plenocal.verify.gt_errors import pose_similarity  # noqa: PLC0415

    src = np.array([np.asarray(reg_a.poses[s])[:3, 3] for s in shots])
    dst = np.array([poses_t[s][:3, 3] for s in shots])
    s_a, R_a, t_a = pose_similarity(src, dst, [np.asarray(reg_a.poses[s])[:3, :3] for s in shots],
                                    [poses_t[s][:3, :3] for s in shots])
    aligned = {}
    for s in shots:
        M = np.eye(4)
        M[:3, :3] = R_a @ np.asarray(reg_a.poses[s])[:3, :3]
        M[:3, 3] = s_a * R_a @ np.asarray(reg_a.poses[s])[:3, 3] + t_a
        aligned[s] = M
    r_true = float(a["scale_m_per_sfm_unit"])
    eps = float(r) / r_true - 1.0
    mean_c = np.mean([poses_t[s][:3, 3] for s in shots], axis=0)
    scaled = {}
    for s in shots:
        M = np.array(poses_t[s], dtype=float)
        M[:3, 3] = mean_c + (1.0 + eps) * (M[:3, 3] - mean_c)
        scaled[s] = M
    rig_sets = {s: dict(rig_views) for s in shots}
    only = {
        "a_poses": _errors(compose(aligned, sets_t, truth), truth),
        "scale": _errors(compose(scaled, sets_t, truth), truth),
        "rig": _errors(compose(poses_t, rig_sets, truth), truth),
    }
    per_shot = a["per_shot"]
    arr = [v["centre_err_mm"] for s, v in per_shot.items() if not is_handheld_shot(s)]
    hand = [v["centre_err_mm"] for s, v in per_shot.items() if is_handheld_shot(s)]
    arr_r = [v["rotation_err_deg"] for s, v in per_shot.items() if not is_handheld_shot(s)]
    hand_r = [v["rotation_err_deg"] for s, v in per_shot.items() if is_handheld_shot(s)]
    f_true = float(a["focal_px_truth"])
    dominant = max(only, key=lambda k: only[k]["centre_rmse_mm"])
    return {
        "a_focal_pct": float(a["focal_err_pct"]),
        "a_focal_std_pct": None if focal_std_px is None else 100.0 * focal_std_px / f_true,
        "a_focal_err_in_std": None if not focal_std_px
        else float(a["focal_px"] - f_true) / focal_std_px,
        "a_array_centre_mm": _rms(arr),
        "a_hand_centre_mm": _rms(hand),
        "a_array_rot_deg": max(arr_r) if arr_r else None,
        "a_hand_rot_deg": max(hand_r) if hand_r else None,
        "a_rot_deg": float(a["rotation_err_deg"]["max"]),
        "handheld": handheld_geometry(truth, n),
        "scale_pct": 100.0 * eps,
        "scale_source": scale_source,
        "rig_centre_mm": only["rig"]["centre_rmse_mm"],
        "only_a_poses_mm": only["a_poses"]["centre_rmse_mm"],
        "only_scale_mm": only["scale"]["centre_rmse_mm"],
        "only_rig_mm": only["rig"]["centre_rmse_mm"],
        "only": only,
        "dominant": {"a_poses": "registration A's poses", "scale": "the merge's scale",
                     "rig": "the rig"}[dominant],
        "central_view": c,
        "what": "only_<source>: the Eq. 6 result built from the truth with that source as "
                "estimated (centre RMSE mm, largest rotation deg, rigid alignment); the "
                "focal length enters as K only, its effect on the poses is inside A's poses",
    }

