"""Eq. 6: merging registration A (scaled) and registration B, against hand-built cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plenocal import optics as o
from plenocal.artifacts.disparity import Conversion
from plenocal.artifacts.rig import RigB
from plenocal.calib import merge
from plenocal.calib.reg_b import rig
from plenocal.calib.reg_b.datasheet import Datasheet
from plenocal.camera import intrinsics


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def test_eq6_by_hand():
    R_A = rot_z(0.3) @ o.rotation_matrix(0.1, 0.05)
    M_A = np.eye(4)
    M_A[:3, :3] = R_A
    M_A[:3, 3] = (1.0, -2.0, 0.5)  # SfM units
    K = intrinsics(1800.0, 150.0, 112.0)
    # exact-model view: pure translation; paper-model view: translation and rotation
    M_e = np.eye(4)
    M_e[:3, 3] = (0.0015, 0.0, 0.0)
    M_p = o.view_extrinsic(-1, 2, 0.0015, 0.004)
    cams = merge.merge_cameras({"x00_y00": M_A}, {"1_3": (K, M_e), "4_1": (K, M_p)},
                               r=0.02, width=301, height=225)
    assert sorted(cams) == ["x00_y00/1_3", "x00_y00/4_1"]
    c = cams["x00_y00/1_3"]
    # centre: the scaled central position plus the rotated in-set offset (metres)
    np.testing.assert_allclose(c.centre, 0.02 * np.array([1.0, -2.0, 0.5]) + R_A @ [0.0015, 0, 0],
                               atol=1e-15)
    np.testing.assert_allclose(c.R, R_A, atol=1e-15)
    c = cams["x00_y00/4_1"]
    np.testing.assert_allclose(c.R, R_A @ M_p[:3, :3], atol=1e-15)
    np.testing.assert_allclose(c.centre, 0.02 * np.array([1.0, -2.0, 0.5])
                               + R_A @ np.array([-0.0015, 0.003, 0.0]), atol=1e-15)
    np.testing.assert_allclose(c.K, K)
    # the central view of registration B is the identity: M_i,centre = scaled M_i^A
    cams = merge.merge_cameras({"x00_y00": M_A}, {"2_2": (K, np.eye(4))}, 0.02, 301, 225)
    expected = np.eye(4)
    expected[:3, :3] = R_A  # the rotation kept, the centre scaled by hand
    expected[:3, 3] = (0.02, -0.04, 0.01)
    np.testing.assert_allclose(cams["x00_y00/2_2"].cam_to_world, expected, atol=1e-15)
    with pytest.raises(ValueError, match="scale"):
        merge.merge_cameras({"x00_y00": M_A}, {"2_2": (K, np.eye(4))}, 0.0, 301, 225)


def test_points_seen_by_a_merged_view_agree_with_the_scene():
    """A scene in metres, registration A seeing it in SfM units (scale 1/r): a point
    projects through the merged view like through the true view."""
    r = 0.013
    R = rot_z(-0.2) @ o.rotation_matrix(0.05, -0.02)
    true_centre = np.array([0.01, 0.02, -0.1])  # metres
    M_A = np.eye(4)
    M_A[:3, :3] = R
    M_A[:3, 3] = true_centre / r  # SfM units
    K = intrinsics(1800.0, 150.0 + 7.7, 112.0 - 15.4)
    M_B = np.eye(4)
    M_B[:3, 3] = (0.00146, -0.00292, 0.0)
    cam = merge.merge_cameras({"hand00": M_A}, {"0_3": (K, M_B)}, r, 301, 225)["hand00/0_3"]
    X_cam = np.array([0.01, -0.02, 0.6])  # in the true view's frame
    X = true_centre + R @ (M_B[:3, 3] + X_cam)
    uv, z = cam.project(X)
    np.testing.assert_allclose(uv, (K @ X_cam)[:2] / X_cam[2], atol=1e-9)
    assert z == pytest.approx(0.6)


def test_merge_with_a_rig_document():
    ds = Datasheet(0.0055, 2048, 1536, 600.0, 35.0, 0.13, (2.8,), 5.0, None, 10.0, 470.0,
                       740.0)
    conv = Conversion(-4.5, -3.0, 3.0971, 6.0, 23.92, 21.92, 301, 225, 5)
    doc = rig.build_rig(ds, [conv], 1799.5, 5, model="exact")
    views = RigB(doc).view_poses()
    cams = merge.merge_cameras({"x00_y00": np.eye(4), "x01_y00": np.eye(4)}, views, 1.0,
                               doc["width"], doc["height"])
    assert len(cams) == 50
    a, b = cams["x00_y00/2_3"], cams["x00_y00/2_2"]
    assert a.centre[0] - b.centre[0] == pytest.approx(doc["exact"]["B"] / 1000)
    assert a.K[0, 2] - b.K[0, 2] == pytest.approx(doc["exact"]["pp_shift_px"])


def test_merge_registrations_checks_its_inputs():
    """merge_registrations: Eq. 6 for the shots asked for; a shot registration A has no
    pose for, or a rig built on another focal length, is refused naming the file."""
    from plenocal.artifacts.reg_a import RegistrationA
    from plenocal.camera import PinholeCamera

    ds = Datasheet(0.0055, 2048, 1536, 600.0, 35.0, 0.13, (2.8,), 5.0, None, 10.0, 470.0,
                   740.0)
    conv = Conversion(-4.5, -3.0, 3.0971, 6.0, 23.92, 21.92, 301, 225, 5)
    doc = rig.build_rig(ds, [conv], 1799.5, 5, model="exact")
    K = intrinsics(1799.5, 150.0, 112.0)
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 3.0)
    reg_a = RegistrationA(1799.5, 301, 225, "incremental",
                          {"x00_y00": PinholeCamera(K, pose, 301, 225)})
    cams = merge.merge_registrations(reg_a, RigB(doc), 0.5, ["x00_y00"])
    assert len(cams) == 25
    np.testing.assert_allclose(cams["x00_y00/2_2"].centre, (0.5, 1.0, 1.5), atol=1e-12)
    with pytest.raises(ValueError, match=r"a\.json: registration A has no pose for x01_y00"):
        merge.merge_registrations(reg_a, RigB(doc), 0.5, ["x00_y00", "x01_y00"], "a.json")
    other = RegistrationA(1700.0, 301, 225, "incremental", reg_a.cameras)
    with pytest.raises(ValueError, match=r"r\.json was built with focal length .*rerun rig_b"):
        merge.merge_registrations(other, RigB(doc), 0.5, ["x00_y00"], rig_path="r.json")
