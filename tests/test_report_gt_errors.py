"""Errors against ground truth: exact inputs give zero error, known perturbations give
the hand-computed error, and the targets of issues 4 and 5 decide pass/fail."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from plenocal.artifacts.reg_a import RegistrationA
from plenocal.camera import PinholeCamera, intrinsics, pose, rotation_angle_deg, umeyama
from plenocal.verify.gt_errors import array_step_m, gt_errors, pose_similarity

N = 3
W, H = 201, 151
F = 1000.0
STEP = 0.01
B = 2e-4  # baseline per view step (m)
PP = 0.8  # principal-point shift per view step (px)


def rot(axis, deg):
    a = np.asarray(axis, dtype=float)
    return cv2.Rodrigues(a / np.linalg.norm(a) * math.radians(deg))[0]


def shots():
    out = {}
    for row in range(2):
        for col in range(3):
            out[f"x{col:02d}_y{row:02d}"] = pose(np.eye(3), [col * STEP, row * STEP, 0.0])
    out["hand00"] = pose(rot([0, 1, 0.3], 8.0), [0.012, -0.02, 0.01])
    out["hand01"] = pose(rot([1, 0.2, 0], -6.0), [-0.02, 0.015, -0.005])
    return out


def rig_views(baseline=B, pp=PP):
    views = {}
    for r in range(N):
        for c in range(N):
            h, v = c - 1, r - 1
            K = intrinsics(F, (W - 1) / 2 + h * pp, (H - 1) / 2 + v * pp)
            views[f"{r}_{c}"] = (K, pose(np.eye(3), [h * baseline, v * baseline, 0.0]))
    return views


def truth():
    out = {}
    for s, M in shots().items():
        for k, (K, MB) in rig_views().items():
            out[f"{s}/{k}"] = PinholeCamera(K, M @ MB, W, H)
    return out


def rig_doc(baseline=B, pp=PP):
    return {"model": "exact", "n_views": N, "width": W, "height": H, "focal_px": F,
            "views": {k: {"K": K, "cam_to_central": M}
                      for k, (K, M) in rig_views(baseline, pp).items()}}


# the SfM frame: world_sfm = (R0^T (X - t0)) / r_true
R0 = rot([0.2, 1.0, -0.4], 30.0)
T0 = np.array([0.3, -0.1, 0.5])
R_TRUE = 0.02  # metres per SfM unit


def to_sfm(M):
    A = np.eye(4)
    A[:3, :3] = R0.T
    A[:3, 3] = -R0.T @ T0
    out = A @ M
    out[:3, 3] /= R_TRUE
    return out


def reg_a(focal=F, turn=None):
    poses = {s: to_sfm(M) for s, M in shots().items()}
    if turn is not None:
        poses["x01_y00"] = poses["x01_y00"].copy()
        poses["x01_y00"][:3, :3] = poses["x01_y00"][:3, :3] @ rot([0, 0, 1], turn)
    return RegistrationA(focal_px=focal, width=W, height=H, mapper="incremental",
                         cameras={s: PinholeCamera(np.eye(3), M, W, H) for s, M in poses.items()})


def calib(global_scale=1.0, focal_scale=1.0):
    G = pose(rot([1, 1, 0], 12.0), [0.05, 0.0, -0.2])
    out = {}
    for k, cam in truth().items():
        M = G @ cam.cam_to_world
        M[:3, 3] *= global_scale
        K = cam.K.copy()
        K[0, 0] *= focal_scale
        K[1, 1] *= focal_scale
        out[k] = PinholeCamera(K, M, W, H)
    return out


def test_exact_inputs_give_zero_error_and_pass():
    t = truth()
    res = gt_errors(t, reg_a=reg_a(), rig=rig_doc(), r=R_TRUE, calib=calib())
    a, b, sc, al = (res["registration_a"], res["registration_b"], res["scale"],
                    res["complete"])
    assert a["n_shots"] == 8
    assert a["focal_err_pct"] == pytest.approx(0.0, abs=1e-9)
    assert a["centre_rmse_pct_step"] == pytest.approx(0.0, abs=1e-6)
    assert a["rotation_err_deg"]["max"] == pytest.approx(0.0, abs=1e-5)
    assert a["scale_m_per_sfm_unit"] == pytest.approx(R_TRUE, rel=1e-9)
    assert a["array_step_m"] == pytest.approx(STEP)
    assert b["n_sets"] == 8
    assert b["baseline_err_pct"] == pytest.approx(0.0, abs=1e-6)
    assert b["pp_shift_err_px"] == pytest.approx(0.0, abs=1e-6)
    assert b["baseline_m_truth"] == pytest.approx(B)
    assert sc["err_pct"] == pytest.approx(0.0, abs=1e-9)
    assert al["n_views"] == 8 * N * N
    assert al["centre_rmse_mm"] == pytest.approx(0.0, abs=1e-6)
    assert al["rotation_err_deg"]["max"] == pytest.approx(0.0, abs=1e-5)
    assert all(c["pass"] for c in res["checks"]), res["checks"]


def test_known_perturbations_are_measured():
    res = gt_errors(truth(), reg_a=reg_a(focal=F * 1.003, turn=0.1),
                    rig=rig_doc(baseline=B * 1.015, pp=PP + 0.7), r=R_TRUE * 1.005,
                    calib=calib(global_scale=1.001))
    a, b = res["registration_a"], res["registration_b"]
    assert a["focal_err_pct"] == pytest.approx(0.3, rel=1e-6)
    # one of 8 shots turned by 0.1 deg about one axis: the orientation fit turns the
    # gauge by phi = atan2(sin 0.1, 7 + cos 0.1) ~ 0.1 / 8 about it
    phi = math.degrees(math.atan2(math.sin(math.radians(0.1)),
                                  7 + math.cos(math.radians(0.1))))
    assert a["rotation_err_deg"]["max"] == pytest.approx(0.1 - phi, rel=1e-4)
    assert a["per_shot"]["x01_y00"]["rotation_err_deg"] == pytest.approx(0.1 - phi, rel=1e-4)
    assert a["per_shot"]["x00_y00"]["rotation_err_deg"] == pytest.approx(phi, rel=1e-4)
    assert b["baseline_err_pct"] == pytest.approx(1.5, rel=1e-6)
    assert b["pp_shift_err_px"] == pytest.approx(0.7, rel=1e-6)
    # alpha-equivalent = atan(pp / f): relative error of the shift, to first order
    assert b["alpha_err_pct"] == pytest.approx(100 * (math.atan((PP + 0.7) / F)
                                                      / math.atan(PP / F) - 1), rel=1e-6)
    # the gauge's turn by phi changes the least-squares scale at second order only
    assert res["scale"]["err_pct"] == pytest.approx(0.5, rel=1e-4)
    # a metric scale error of +0.1 % shows as the similarity scale back to the truth
    assert res["complete"]["residual_scale_err_pct"] == pytest.approx(
        100 * (1 / 1.001 - 1), rel=1e-6)
    assert res["complete"]["centre_rmse_mm"] > 0.0
    verdict = {c["name"]: c["pass"] for c in res["checks"]}
    assert verdict["a_focal_pct"] is True  # 0.3 % <= 0.5 %
    assert verdict["a_rotation_deg"] is False  # 0.0875 deg > 0.05 deg
    assert verdict["b_baseline_pct"] is False  # 1.5 % > 1 %
    assert verdict["b_pp_px"] is False  # 0.7 px > 0.5 px
    assert verdict["scale_pct"] is True
    assert verdict["all_scale_pct"] is True  # 0.1 % <= 0.3 %
    assert verdict["all_focal_pct"] is True


def test_the_complete_calibration_is_judged_by_issue_32s_targets():
    # a focal length 0.15 % long and the centres 0.4 % too far apart: past issue 32's 0.1 %
    # and 0.3 %, with the registrations' own targets untouched
    res = gt_errors(truth(), calib=calib(global_scale=1.004, focal_scale=1.0015))
    verdict = {c["name"]: (c["pass"], c["target"]) for c in res["checks"]}
    assert verdict["all_focal_pct"] == (False, 0.1)
    assert verdict["all_scale_pct"] == (False, 0.3)
    assert res["complete"]["focal_err_pct"]["max"] == pytest.approx(0.15, rel=1e-6)
    close = gt_errors(truth(), calib=calib(global_scale=1.002, focal_scale=1.0009))
    verdict = {c["name"]: c["pass"] for c in close["checks"]}
    assert verdict["all_focal_pct"] is True and verdict["all_scale_pct"] is True
    assert {c["name"]: c["target"] for c in close["checks"]}["all_rotation_deg"] == 0.02


def test_missing_stages_leave_checks_open_and_bad_truth_is_named():
    res = gt_errors(truth(), calib=calib())
    verdict = {c["name"]: c["pass"] for c in res["checks"]}
    assert verdict["a_focal_pct"] is None and verdict["all_centre_mm"] is True
    lonely = {"x00_y00/1_1": truth()["x00_y00/1_1"]}
    assert array_step_m(lonely, N) is None
    with pytest.raises(ValueError, match="share 1 views"):
        gt_errors(truth(), calib={"x00_y00/1_1": calib()["x00_y00/1_1"]})


def test_an_array_of_one_shot_is_measured_in_millimetres():
    """A capture whose array is one shot (beside the hand-held ones) has no array step:
    registration A's centres are given in millimetres, their check in % of the step left
    open (it stopped rule gt_errors, and with it the report, before)."""
    keep = ("x00_y00", "hand00", "hand01")
    t = {k: c for k, c in truth().items() if k.split("/")[0] in keep}
    a0 = reg_a(focal=F * 1.002)
    a = RegistrationA(focal_px=a0.focal_px, width=W, height=H, mapper="incremental",
                      cameras={s: c for s, c in a0.cameras.items() if s in keep})
    res = gt_errors(t, reg_a=a, rig=rig_doc(), r=R_TRUE, calib=calib())
    ra = res["registration_a"]
    assert ra["n_shots"] == 3 and ra["array_step_m"] is None
    assert ra["centre_rmse_pct_step"] is None
    assert ra["centre_aligned"]["centre_rmse_pct_step"] is None
    assert ra["centre_rmse_mm"] == pytest.approx(0.0, abs=1e-6)
    assert ra["focal_err_pct"] == pytest.approx(0.2, abs=1e-9)
    verdict = {c["name"]: c["pass"] for c in res["checks"]}
    assert verdict["a_centre_pct_step"] is None and verdict["a_focal_pct"] is True


def test_pose_similarity_recovers_a_known_similarity_and_ignores_centre_depth_noise():
    rng = np.random.default_rng(3)
    R_true = rot([0.3, -1.0, 0.2], 25.0)
    s_true, t_true = 2.5, np.array([0.1, -0.4, 0.9])
    # centres nearly in a plane (an array), orientations varied (hand-held shots)
    src_c = np.c_[rng.uniform(-0.03, 0.03, (12, 2)), rng.normal(0, 1e-3, 12)]
    src_R = [rot(rng.normal(size=3), rng.uniform(0, 10)) for _ in range(12)]
    dst_c = s_true * src_c @ R_true.T + t_true
    dst_R = [R_true @ r for r in src_R]
    s, R, t = pose_similarity(src_c, dst_c, src_R, dst_R)
    assert s == pytest.approx(s_true, rel=1e-12)
    np.testing.assert_allclose(R, R_true, atol=1e-12)
    np.testing.assert_allclose(t, t_true, atol=1e-12)
    # 20 um of depth noise on the true centres tilts a centre-only fit, not this one
    noisy = dst_c + np.c_[np.zeros((12, 2)), rng.normal(0, 2e-5, 12)] @ R_true.T
    _, R_pose, _ = pose_similarity(src_c, noisy, src_R, dst_R)
    _, R_centre, _ = umeyama(src_c, noisy)
    assert rotation_angle_deg(R_pose, R_true) < 1e-9
    assert rotation_angle_deg(R_centre, R_true) > 0.01


def test_the_complete_calibrations_focal_error_keeps_its_sign():
    """``focal_err_pct`` holds the absolute errors' statistics; ``focal_err_signed_pct``
    their signed mean (a focal length 0.3 % short: 0.3 and -0.3)."""
    short = {k: PinholeCamera(np.diag([0.997, 0.997, 1.0]) @ c.K, c.cam_to_world, W, H)
             for k, c in calib().items()}
    al = gt_errors(truth(), reg_a=reg_a(), rig=rig_doc(), r=R_TRUE, calib=short)["complete"]
    assert al["focal_err_pct"]["mean"] == pytest.approx(0.3, rel=1e-6)
    assert al["focal_err_signed_pct"] == pytest.approx(-0.3, rel=1e-6)


def test_the_worst_view_by_rotation_is_named_beside_the_worst_by_centre():
    """One shot of the calibration turned by 0.05 deg about its central view's centre
    (every view of it with it, as the rig holds them), another's views moved by 0.2 mm:
    ``worst_rotation_view`` names a view of the turned shot, ``worst_view`` (by centre
    error) one of the moved shot."""
    cams = calib()
    turned, moved = "hand01", "x02_y01"
    centre = cams[f"{turned}/1_1"].centre
    turn = rot([0.3, 1.0, 0.0], 0.05)
    T = pose(turn, centre - turn @ centre)
    out = {}
    for k, cam in cams.items():
        M = cam.cam_to_world
        if k.startswith(f"{turned}/"):
            M = T @ M
        elif k.startswith(f"{moved}/"):
            M = M.copy()
            M[:3, 3] += [0.0, 2e-4, 0.0]
        out[k] = PinholeCamera(cam.K, M, W, H)
    al = gt_errors(truth(), calib=out)["complete"]
    assert al["worst_rotation_view"].startswith(f"{turned}/")
    assert al["worst_view"].startswith(f"{moved}/")
    assert al["rotation_err_deg"]["max"] == pytest.approx(0.05, rel=0.2)
