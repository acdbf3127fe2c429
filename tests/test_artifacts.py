"""The files one stage writes and another reads (plenocal.artifacts): each written and
read by one definition, with a format version that a reader checks."""

from __future__ import annotations

import pytest
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture

from plenocal.artifacts.disparity import FORMAT, VERSION, disparity_record, read_disparity
from plenocal.convert import ConvertSettings, ShotConversion
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_json, write_json
from plenocal.optics import PlenopticOptics


def _shot() -> ShotConversion:
    opt = PlenopticOptics(focal_length=0.035, focus_distance=0.6, mla_pitch=130e-6,
                          mla_f_number=2.8, k=5.0, pixel_size=5.5e-6, width=400, height=300)
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, 400, 300)
    img = lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, 1))
    return ShotConversion(img, calib, 5, ConvertSettings(tile_size=6))


def test_disparity_round_trip(tmp_path):
    shot = _shot()
    doc = shot.disparity()
    assert doc["format"] == FORMAT and doc["version"] == VERSION
    write_json(tmp_path / "disparity.json", doc)
    conv = read_disparity(tmp_path / "disparity.json")
    # (write_json keeps 12 significant digits)
    assert (conv.d_min, conv.d_max) == pytest.approx((min(doc["D_min"], doc["D_max"]),
                                                      max(doc["D_min"], doc["D_max"])), rel=1e-11)
    assert (conv.q, conv.tile, conv.pitch_px) == pytest.approx(
        (doc["q_px"], doc["tile"], doc["D_px"]), rel=1e-11)
    assert (conv.width, conv.height, conv.n_views, conv.mla) == (
        shot.layout.width, shot.layout.height, 5, shot.mla)
    # the record is the writer's, whoever calls it
    again = disparity_record(shot.layout, shot.calib, shot.used_patch,
                             shot.patch.confident[shot.layout.lens_index],
                             shot.settings.percentiles)
    assert {k: doc[k] for k in again} == again


def test_disparity_of_another_version_or_damaged_is_refused(tmp_path):
    doc = _shot().disparity()
    for name, bad in (("old.json", {k: v for k, v in doc.items() if k != "format"}),
                      ("v0.json", dict(doc, version=VERSION + 1))):
        write_json(tmp_path / name, bad)
        with pytest.raises(ValueError, match=rf"{name}: not a disparity.json of version"):
            read_disparity(tmp_path / name)
    write_json(tmp_path / "cut.json", {k: v for k, v in doc.items() if k != "q_px"})
    with pytest.raises(ValueError, match="without key 'q_px'"):
        read_disparity(tmp_path / "cut.json")
    write_json(tmp_path / "mla.json", dict(doc, mla="plenoptic"))
    with pytest.raises(ValueError, match="'plenoptic' is not an MLA kind"):
        read_disparity(tmp_path / "mla.json")
    with pytest.raises(FileNotFoundError, match="convert the shot"):
        read_disparity(tmp_path / "absent.json")
    assert read_json(tmp_path / "cut.json")["format"] == FORMAT


def test_scale_round_trip_and_estimator(tmp_path):
    from plenocal.artifacts.scale import ScaleResult, read_scale, write_scale

    res = ScaleResult(r=0.021, r_median=0.020, r_median_of_ratios=0.0205, estimator="median",
                      r_i={"x00_y00": 0.021}, r_i_median_of_ratios={"x00_y00": 0.0205},
                      n_pixels={"x00_y00": 100}, spread={"relative": 0.0, "n_shots": 1},
                      percentiles=(10.0, 90.0))
    assert res.r_used == 0.020
    write_scale(tmp_path / "scale.json", res)
    doc = read_json(tmp_path / "scale.json")
    assert doc["format"] == "plenocal.scale" and doc["r_used"] == 0.020
    assert read_scale(tmp_path / "scale.json") == res
    with pytest.raises(ValueError, match="scale.estimator = 'mode'"):
        ScaleResult(r=1.0, r_median=1.0, r_median_of_ratios=1.0, estimator="mode")
    write_json(tmp_path / "old.json", {"r": 0.02, "r_used": 0.02})
    with pytest.raises(ValueError, match=r"old\.json: not a scale.json of version 1.*rule scale"):
        read_scale(tmp_path / "old.json")
    with pytest.raises(FileNotFoundError, match="run rule scale"):
        read_scale(tmp_path / "none.json")


def test_rig_round_trip_and_checks(tmp_path):
    import numpy as np

    from plenocal.artifacts.rig import RigB, read_rig, write_rig

    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    views = {f"{r}_{c}": {"K": K, "cam_to_central": np.eye(4)} for r in range(3) for c in range(3)}
    doc = {"model": "exact", "n_views": 3, "width": 101, "height": 81, "focal_px": 100.0,
           "depth_range_m": [0.4, 0.8], "symbols": {"X_n": 470.0, "X_f": 740.0},
           "views": views}
    write_rig(tmp_path / "rig.json", doc)
    rig = read_rig(tmp_path / "rig.json")
    assert isinstance(rig, RigB) and rig.depth_range_m == (0.4, 0.8) and rig.focal_px == 100.0
    cams = rig.set_cameras("hand01")
    assert sorted(cams)[0] == "hand01/0_0" and cams["hand01/1_1"].width == 101
    write_json(tmp_path / "few.json", {**read_json(tmp_path / "rig.json"),
                                       "views": {"0_0": views["0_0"]}})
    with pytest.raises(ValueError, match="1 views for n_views = 3"):
        read_rig(tmp_path / "few.json")
    write_json(tmp_path / "old.json", doc)
    with pytest.raises(ValueError, match=r"old\.json: not a rig.json of version 1.*rule rig_b"):
        read_rig(tmp_path / "old.json")
    cut = {k: v for k, v in read_json(tmp_path / "rig.json").items() if k != "symbols"}
    write_json(tmp_path / "cut.json", cut)
    with pytest.raises(ValueError, match="without key 'symbols'"):
        read_rig(tmp_path / "cut.json")


def test_reg_a_round_trip(tmp_path):
    import numpy as np

    from plenocal.artifacts.reg_a import RegistrationA, read_reg_a, write_reg_a
    from plenocal.camera import PinholeCamera

    K = np.array([[900.0, 0, 249.5], [0, 900.0, 187.5], [0, 0, 1]])
    M = np.eye(4)
    M[:3, 3] = (0.5, 0.0, 0.0)
    reg = RegistrationA(focal_px=900.0, width=500, height=376, mapper="global",
                        cameras={"x01_y00": PinholeCamera(K, M, 500, 376)},
                        stats={"num_points3D": 12})
    write_reg_a(tmp_path / "reg_a.json", reg)
    back = read_reg_a(tmp_path / "reg_a.json")
    assert (back.focal_px, back.width, back.mapper, back.stats) == (900.0, 500, "global",
                                                                   {"num_points3D": 12})
    np.testing.assert_array_equal(back.poses["x01_y00"], M)
    write_json(tmp_path / "old.json", {"focal_px": 900.0, "poses": {"x01_y00": M}})
    with pytest.raises(ValueError, match=r"old\.json: not a reg_a.json of version 1.*map_a"):
        read_reg_a(tmp_path / "old.json")
    doc = read_json(tmp_path / "reg_a.json")
    doc["cameras"]["x01_y00"]["K"] = [[1.0]]
    write_json(tmp_path / "bad.json", doc)
    with pytest.raises(ValueError, match="camera x01_y00: K must be 3x3"):
        read_reg_a(tmp_path / "bad.json")
