"""The files one stage writes and another reads (plenocal.artifacts): each written and
read by one definition, with a format version that a reader checks."""

from __future__ import annotations

import zlib

import pytest
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture

from plenocal.artifacts.disparity import FORMAT, VERSION, disparity_record, read_disparity
from plenocal.artifacts.stage_warnings import read_warnings, warning_list, warnings_of
from plenocal.convert import ConvertSettings, ShotConversion
from plenocal.convert.setup import ConverterSetup, read_setup, write_setup
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_json, write_json
from plenocal.optics import PlenopticOptics
from plenocal.report.sources import WARNING_SOURCES


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
                             shot.settings.percentiles, shot.warnings)
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


# ---------------------------------------------------------------------------
# The stages' warnings: one shape, a list of strings
# ---------------------------------------------------------------------------

REPORT_READS = dict(WARNING_SOURCES)  # what the report reads each output's warnings with


def _setup(warnings) -> ConverterSetup:
    return ConverterSetup(mla="keplerian", tile=6, grid_mode="auto", refined=False,
                          lattice=None, decided_on="x01_y01.png", mla_source="setting",
                          tile_source="setting", mla_match_scores=None, grid_check={},
                          warnings=warnings)


def test_producers_write_warnings_as_a_list_of_strings(tmp_path):
    """Every producer of a ``warnings`` list writes it in the one shape, and the report's
    reader of that output gives the messages back unchanged (registration A's
    features.json: tests/test_sfm.py)."""
    shot = _shot()
    shot.warnings = ["lenslet.png: only 12 % of the micro images have a confident size"]
    doc = shot.disparity()
    assert doc["warnings"] == shot.warnings
    write_json(tmp_path / "disparity.json", doc)
    assert REPORT_READS["views/{cam}/disparity.json"](tmp_path / "disparity.json") == (
        tuple(shot.warnings))
    setup = _setup(("x01_y01.png: grid check: the calib.xml grid drifts up to 2.1 px",))
    assert setup.to_dict()["warnings"] == list(setup.warnings)
    write_setup(tmp_path / "convert_setup.json", setup)
    assert read_setup(tmp_path / "convert_setup.json") == setup
    assert REPORT_READS["views/convert_setup.json"](tmp_path / "convert_setup.json") == (
        setup.warnings)
    # another shape never reaches a file
    for bad in ([{"message": "few features"}], ["  "], [None]):
        with pytest.raises(TypeError, match="non-empty strings"):
            warning_list(bad)
        with pytest.raises(TypeError, match="non-empty strings"):
            _setup(tuple(bad)).to_dict()
        shot.warnings = bad
        with pytest.raises(TypeError, match="non-empty strings"):
            shot.disparity()


def test_warnings_of_another_shape_are_refused_with_file_key_and_remedy(tmp_path):
    doc = _shot().disparity()
    assert warnings_of({"warnings": ["a", "b"]}, "x.json", "rerun") == ("a", "b")
    for name, raw, what in (("dict.json", [{"message": "few features"}], "entry 0"),
                            ("str.json", "few features", "is a str, not a list"),
                            ("empty.json", ["ok", ""], "entry 1")):
        write_json(tmp_path / name, {**doc, "warnings": raw})
        with pytest.raises(ValueError, match=rf"{name}: key 'warnings'.*{what}.*convert the "
                                             r"shot \(rule convert"):
            REPORT_READS["views/{cam}/disparity.json"](tmp_path / name)
        write_json(tmp_path / name, {"keypoints": {}, "warnings": raw})
        with pytest.raises(ValueError, match=rf"{name}: key 'warnings'.*rerun rule features_a"):
            REPORT_READS["reg_a/features.json"](tmp_path / name)
    write_json(tmp_path / "none.json", {k: v for k, v in doc.items() if k != "warnings"})
    with pytest.raises(ValueError, match=r"none\.json: no key 'warnings'.*convert the shot"):
        REPORT_READS["views/{cam}/disparity.json"](tmp_path / "none.json")
    setup = _setup(("a",)).to_dict()
    write_json(tmp_path / "setup.json", {**setup, "warnings": [{"message": "a"}]})
    with pytest.raises(ValueError, match=r"setup\.json: key 'warnings', entry 0.*rule "
                                         "convert_setup"):
        read_setup(tmp_path / "setup.json")
    write_json(tmp_path / "setup.json", {k: v for k, v in setup.items() if k != "warnings"})
    with pytest.raises(ValueError, match=r"setup\.json: no key 'warnings'"):
        read_setup(tmp_path / "setup.json")
    with pytest.raises(FileNotFoundError, match="features.json.*rerun rule features_a"):
        read_warnings(tmp_path / "absent.json", "features.json", "rerun rule features_a")


def test_a_setup_file_that_is_not_one_is_named_with_its_key(tmp_path):
    """``plenocal convert --setup FILE`` (and the workflow's readers) on a file that is not
    a convert_setup.json: one ConvertError naming the file, the key where one is missing
    or wrong, and the remedy; no JSON, Unicode, key or type error escapes."""
    from plenocal.convert.errors import ConvertError  # noqa: PLC0415

    good = _setup(()).to_dict()
    cases = {
        "truncated.json": ('{"format": "x"', r"not JSON"),
        "binary.json": (b"\x89PNG\r\n\x1a\n\xff\xfe\x00", r"not JSON"),
        "list.json": ("[1, 2]", r"a JSON list, not an object"),
        "no_key.json": ({k: v for k, v in good.items() if k != "tile"}, r"key 'tile'"),
        "wrong_kind.json": ({**good, "tile": "ten"}, r"not of its kind.*'ten'"),
        "no_lattice_dict.json": ({**good, "lattice": 3}, r"not of its kind"),
    }
    for name, (content, why) in cases.items():
        path = tmp_path / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        elif isinstance(content, str):
            path.write_text(content)
        else:
            write_json(path, content)
        with pytest.raises(ConvertError, match=rf"{name}: .*{why}.*leave --setup out"):
            read_setup(path)
    write_json(tmp_path / "ok.json", good)
    assert read_setup(tmp_path / "ok.json") == _setup(())


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

    from plenocal.artifacts.rig import InverseCheck, RigB, read_rig, write_rig

    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    views = {f"{r}_{c}": {"K": K, "cam_to_central": np.eye(4)} for r in range(3) for c in range(3)}
    doc = {"model": "exact", "n_views": 3, "width": 101, "height": 81, "focal_px": 100.0,
           "depth_range_m": [0.4, 0.8], "symbols": {"X_n": 470.0, "X_f": 740.0},
           "views": views, "check": {"verdict": "fail", "rel_diff_B": 0.12,
                                     "rel_diff_alpha": None, "tolerance": 0.05}}
    write_rig(tmp_path / "rig.json", doc)
    rig = read_rig(tmp_path / "rig.json")
    assert isinstance(rig, RigB) and rig.depth_range_m == (0.4, 0.8) and rig.focal_px == 100.0
    assert rig.check == InverseCheck("fail", rel_diff_B=0.12, tolerance=0.05)
    assert rig.check.failed
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


def test_rig_check_is_typed_and_a_rename_is_an_error(tmp_path):
    """The inverse check of Eqs. 2-3 (rig.json's ``check``) as build_rig writes it is read
    into an InverseCheck; a key of it renamed or left out on the producing side is an
    error when writing and when reading (the report would otherwise drop its warning)."""
    import numpy as np

    from plenocal.artifacts.rig import InverseCheck, read_rig, write_rig
    from plenocal.calib.reg_b.paper_model import inverse_check

    sym = {"P": 0.0055, "F": 35.0, "F_m_px": 6363.6, "D_max_px": -2.0, "D_min_px": -3.0}
    judged = inverse_check(sym, 470.0, 740.0, 0.5, 0.001)
    skipped = inverse_check(sym, None, None, 0.5, 0.001)
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    doc = {"model": "paper", "n_views": 1, "width": 101, "height": 81, "focal_px": 100.0,
           "depth_range_m": [0.4, 0.8], "symbols": sym,
           "views": {"0_0": {"K": K, "cam_to_central": np.eye(4)}}}
    path = tmp_path / "rig.json"
    for check in (judged, skipped):
        write_rig(path, {**doc, "check": check})
        typed = read_rig(path).check
        assert typed.verdict == check["verdict"]
    assert typed == InverseCheck("skipped", reason=skipped["reason"])
    write_rig(path, {**doc, "check": judged})
    c = read_rig(path).check
    assert (c.rel_diff_B, c.rel_diff_alpha, c.tolerance) == pytest.approx(
        (judged["rel_diff_B"], judged["rel_diff_alpha"], judged["tolerance"]), rel=1e-11)
    for key in ("verdict", "rel_diff_B", "rel_diff_alpha", "tolerance"):
        renamed = {("result" if k == key else k): v for k, v in judged.items()}
        with pytest.raises(ValueError, match=rf"new\.json: .*'check\.{key}'.*build_rig"):
            write_rig(tmp_path / "new.json", {**doc, "check": renamed})
        write_json(tmp_path / "old.json", {**read_json(path), "check": renamed})
        with pytest.raises(ValueError, match=rf"old\.json: .*'check\.{key}'.*rule rig_b"):
            read_rig(tmp_path / "old.json")
    write_json(tmp_path / "old.json", {**read_json(path), "check": {**judged, "verdict": "FAIL"}})
    with pytest.raises(ValueError, match=r"'check\.verdict' = 'FAIL' is not one of pass, fail"):
        read_rig(tmp_path / "old.json")
    with pytest.raises(ValueError, match="rig.json would lack key 'check'"):
        write_rig(tmp_path / "new.json", doc)


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


def test_png_levels_store_the_same_pixels_and_are_deterministic(tmp_path):
    """write_image: the lenslet images' level (stored, LENSLET_PNG_LEVEL) and the default
    give the same pixels back; the same input gives the same bytes."""
    import numpy as np

    from plenocal.io.files import LENSLET_PNG_LEVEL, read_image, write_image

    img = (np.random.default_rng(3).integers(0, 4096, (40, 60, 3)) << 4).astype(np.uint16)
    sizes = {}
    for level in (LENSLET_PNG_LEVEL, 1):
        a, b = tmp_path / f"a{level}.png", tmp_path / f"b{level}.png"
        write_image(a, img, level=level)
        write_image(b, img, level=level)
        assert a.read_bytes() == b.read_bytes()
        assert np.array_equal(read_image(a), img)
        sizes[level] = a.stat().st_size
    assert sizes[LENSLET_PNG_LEVEL] > sizes[1]  # stored: no compression
    # stored data is unfiltered (filter type 0 on every row: a filter only helps zlib)
    data, pos = (tmp_path / f"a{LENSLET_PNG_LEVEL}.png").read_bytes(), 8
    idat = b""
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        if data[pos + 4:pos + 8] == b"IDAT":
            idat += data[pos + 8:pos + 8 + n]
        pos += 12 + n
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(40, 1 + 60 * 3 * 2)
    assert (rows[:, 0] == 0).all()
