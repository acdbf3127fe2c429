"""``plenocal convert`` (plenocal.cli): options, outputs, errors and exit codes."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from synth.lenslets import lenslet_from_patch_size, random_texture

from plenocal.cli import (
    build_parser,
    command_line_block,
    convert_config,
    main,
    validate_convert_block,
)
from plenocal.config import stage_defaults
from plenocal.convert.prefilter import OPTIMAL_A
from plenocal.grid import MicrolensGrid
from plenocal.io.files import read_image, write_image
from plenocal.io.raytrix import LensType, RayCalib, read_calib, write_calib
from plenocal.names import view_names


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "plenocal.cli", *args], capture_output=True,
                          text=True, timeout=120)


@pytest.fixture(scope="module")
def shot(tmp_path_factory) -> tuple[Path, Path]:
    """A small lenslet image (one textured plane, patch size 7 px, D = 23.2 px) and its
    calib.xml, the file's grid 1.5 px off the micro images (so auto refines)."""
    folder = tmp_path_factory.mktemp("shot")
    s3 = math.sqrt(3) / 2
    true = RayCalib(diameter=23.2, offset=(2.0, -1.0), rotation=math.pi / 2, lens_border=1.0,
                    lens_base_x=(0.0, 1.0), lens_base_y=(s3, 0.5),
                    lens_types=(LensType(0, (0.0, 0.0), 1.0, 100.0),), source="true")
    img = lenslet_from_patch_size(MicrolensGrid(true, 480, 400), 7.0,
                                  random_texture(256, 1.5, 3), 0.5)
    lenslet, calib = folder / "lenslet.png", folder / "calib.xml"
    write_image(lenslet, img)
    write_calib(RayCalib(**{**true.__dict__, "offset": (3.5, -1.0), "source": "x"}), calib)
    return lenslet, calib


def test_help_explains_every_option():
    r = _cli("convert", "--help")
    assert r.returncode == 0
    for opt in ("--views", "--galilean", "--mla", "--tile-size", "--grid", "--bit-depth",
                "--set", "-o", "disparity.json", "patch_size.npy", "patch_size.png"):
        assert opt in r.stdout, opt
    sub = build_parser()._subparsers._group_actions[0].choices["convert"]
    for action in sub._actions:
        assert action.help, f"{action.dest} has no help"


def test_version_names_the_libraries_that_decide_the_bytes():
    from importlib.metadata import version  # noqa: PLC0415

    r = _cli("--version")
    assert r.returncode == 0
    line = r.stdout.strip()
    assert line.startswith(f"plenocal {version('plenocal')} (numpy {version('numpy')}, ")
    for name in ("opencv-python-headless", "pycolmap", "scipy", "numba", "snakemake"):
        assert f"{name} {version(name)}" in line, name
    assert f"Python {sys.version.split()[0]})" in line


def test_missing_file_and_malformed_xml_exit_2(tmp_path, shot):
    lenslet, calib = shot
    r = _cli("convert", str(tmp_path / "none.png"), str(calib), "-o", str(tmp_path / "o"))
    assert r.returncode == 2
    assert "none.png" in r.stderr and "not found" in r.stderr
    r = _cli("convert", str(lenslet.parent), str(calib), "-o", str(tmp_path / "o"))
    assert r.returncode == 2
    assert f"{lenslet.parent}: a folder, where the lenslet image file is asked for" in r.stderr
    # a palette PNG converted without a word (its 256 colours read as the readout)
    from PIL import Image  # noqa: PLC0415

    Image.new("P", (64, 48)).save(tmp_path / "palette.png")
    r = _cli("convert", str(tmp_path / "palette.png"), str(calib), "-o", str(tmp_path / "o"))
    assert r.returncode == 2
    assert "palette.png: a palette image, not the camera's readout" in r.stderr, r.stderr
    # a device that exists (it was called "not found")
    r = _cli("convert", str(lenslet), os.devnull, "-o", str(tmp_path / "o"))
    assert r.returncode == 2
    assert f"{os.devnull}: not a regular file (a device or a pipe), where the calib.xml" in r.stderr
    bad = tmp_path / "bad.xml"
    bad.write_text("<RayCalibData><diameter>23")
    r = _cli("convert", str(lenslet), str(bad), "-o", str(tmp_path / "o"))
    assert r.returncode == 2
    assert "bad.xml" in r.stderr and "malformed" in r.stderr
    r = _cli("convert", str(lenslet), str(calib), "-o", str(tmp_path / "o"), "--grid", "x")
    assert r.returncode == 2
    r = _cli("convert", str(lenslet), str(calib), "-o", str(tmp_path / "o"), "--set",
             "tile_sise=4")
    assert r.returncode == 2
    assert "tile_sise" in r.stderr
    for n in ("0", "4"):  # checked before the frame is read
        r = _cli("convert", str(lenslet), str(calib), "-o", str(tmp_path / "o"), "--views", n)
        assert r.returncode == 2 and "--views: an odd number" in r.stderr, r.stderr
        assert "grid check" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_options_map_onto_the_convert_keys():
    p = build_parser()
    a = p.parse_args(["convert", "l.png", "c.xml", "-o", "d", "--galilean", "--tile-size",
                      "auto", "--grid", "refine", "--bit-depth", "12", "--set",
                      "upsample=1.5", "--set", "patch_size.block_samples=9"])
    cfg = convert_config(a)
    assert cfg == {"mla": "galilean", "tile_size": "auto", "grid": "refine", "bit_depth": 12,
                   "upsample": 1.5, "patch_size": {"block_samples": 9},
                   "blend": {"prefilter": OPTIMAL_A}}
    a = p.parse_args(["convert", "l.png", "c.xml", "-o", "d", "--tile-size", "9"])
    cfg = convert_config(a)
    # the rest: the schema's defaults (grid auto, mla auto), the frame prefiltered
    assert cfg == {"tile_size": 9, "blend": {"prefilter": OPTIMAL_A}}
    assert validate_convert_block(cfg)["grid"] == validate_convert_block(cfg)["mla"] == "auto"
    with pytest.raises(SystemExit):
        p.parse_args(["convert", "l.png", "c.xml", "-o", "d", "--tile-size", "big"])
    with pytest.raises(SystemExit):
        p.parse_args(["convert", "l.png", "c.xml", "-o", "d", "--galilean", "--mla",
                      "keplerian"])


def test_the_command_line_prefilters_the_frame_and_the_workflow_does_not():
    """plenocal convert's views are prefiltered (blend.prefilter OPTIMAL_A, > 0); the
    config's default, which the workflow's views for the calibration take, stays 0; --set
    blend.prefilter=0 gives the workflow's block, key for key."""
    p = build_parser()
    plain = ["convert", "l.png", "c.xml", "-o", "d"]
    block = validate_convert_block(convert_config(p.parse_args(plain)))
    assert OPTIMAL_A > 0 and block["blend"]["prefilter"] == OPTIMAL_A
    assert block == command_line_block()
    assert stage_defaults("convert.blend")["prefilter"] == 0
    off = validate_convert_block(convert_config(p.parse_args(
        [*plain, "--set", "blend.prefilter=0"])))
    assert off == validate_convert_block({}) and off != block
    # a nested key beside it keeps the prefilter
    other = command_line_block({"blend": {"wide_slots": 5}, "mla": "galilean"})
    assert other["blend"]["prefilter"] == OPTIMAL_A and other["blend"]["wide_slots"] == 5
    assert other["mla"] == "galilean"


def test_convert_writes_what_rule_convert_writes(tmp_path, shot, capsys):
    lenslet, calib = shot
    out = tmp_path / "views"
    rc = main(["convert", str(lenslet), str(calib), "-o", str(out), "--views", "3",
               "--tile-size", "6", "--mla", "keplerian"])
    assert rc == 0
    err = capsys.readouterr().err
    assert "grid check" in err and "9/9 views of" in err and "rendered and written" in err
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([f"{v}.png" for v in view_names(3)]
                           + ["disparity.json", "patch_size.npy", "patch_size.png"])
    stats = json.loads((out / "disparity.json").read_text())
    assert stats["n_views"] == 3 and stats["tile"] == 6
    g = stats["grid_check"]
    assert g["mode"] == "auto" and g["refined"] is True  # the file is 1.5 px off
    assert g["drift_max_px"] == pytest.approx(1.5, abs=0.3)
    views = [read_image(out / f"{v}.png") for v in view_names(3)]
    assert all(v.shape == views[0].shape and v.dtype == np.uint8 for v in views)
    assert views[0].shape[:2] == (stats["height"], stats["width"])
    patch = np.load(out / "patch_size.npy")
    assert len(patch) == stats["used_lenses"]
    assert np.median(patch) == pytest.approx(7.0, abs=1.0)
    # --grid file keeps the file's grid
    out2 = tmp_path / "file"
    assert main(["convert", str(lenslet), str(calib), "-o", str(out2), "--views", "3",
                 "--tile-size", "6", "--mla", "keplerian", "--grid", "file", "-q"]) == 0
    assert json.loads((out2 / "disparity.json").read_text())["grid_check"]["refined"] is False


def test_foreign_grid_stops_as_in_the_workflow(tmp_path, shot):
    """A calib.xml whose pitch is 3 % off the micro images' (another camera's file): the
    grid check finds it foreign, and the command stops with exit 2 naming the file and the
    remedies, as rule convert_setup does (convert.grid_foreign: error), leaving no folder;
    ``--set grid_foreign=warn`` converts on it all the same, ``--grid refine`` on the
    lattice fitted to the image."""
    lenslet, calib = shot
    wrong = tmp_path / "other_camera.xml"
    c = read_calib(calib)
    write_calib(dataclasses.replace(c, diameter=c.diameter * 1.03), wrong)
    args = [str(lenslet), str(wrong), "--views", "3", "--tile-size", "6", "--mla",
            "keplerian"]
    r = _cli("convert", *args, "-o", str(tmp_path / "stop"))
    assert r.returncode == 2
    assert "other_camera.xml" in r.stderr and "not on the micro images" in r.stderr
    assert "--grid refine" in r.stderr and "grid_foreign=warn" in r.stderr
    assert not (tmp_path / "stop").exists()
    assert main(["convert", *args, "-o", str(tmp_path / "warn"), "--set",
                 "grid_foreign=warn", "-q"]) == 0
    g = json.loads((tmp_path / "warn" / "disparity.json").read_text())["grid_check"]
    assert g["foreign"] is True and g["refined"] is False
    assert main(["convert", *args, "-o", str(tmp_path / "refine"), "--grid", "refine",
                 "-q"]) == 0
    g = json.loads((tmp_path / "refine" / "disparity.json").read_text())["grid_check"]
    assert g["foreign"] is True and g["refined"] is True


def test_frame_without_texture_warns_that_the_mla_kind_is_assumed(tmp_path, shot, capsys):
    """A flat frame (a lens cap on, a white calibration shot without the white): the
    conversion runs, and says that it could not read the MLA kind and which it assumed,
    on stderr and in disparity.json."""
    lenslet, calib = shot
    flat = tmp_path / "flat.png"
    write_image(flat, np.full_like(read_image(lenslet), 128))
    assert main(["convert", str(flat), str(calib), "-o", str(tmp_path / "v"), "--views", "3",
                 "--tile-size", "6"]) == 0
    err = capsys.readouterr().err
    assert "the MLA kind cannot be read from this image" in err
    warnings = json.loads((tmp_path / "v" / "disparity.json").read_text())["warnings"]
    assert any("MLA kind cannot be read" in w for w in warnings)
    # the textured frame decides it, and says nothing of the kind
    assert main(["convert", str(lenslet), str(calib), "-o", str(tmp_path / "t"), "--views",
                 "3", "--tile-size", "6"]) == 0
    assert "cannot be read" not in capsys.readouterr().err


def test_output_folder_that_cannot_be_made_fails_before_the_work(tmp_path, shot):
    lenslet, calib = shot
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    r = _cli("convert", str(lenslet), str(calib), "-o", str(blocker / "views"))
    assert r.returncode == 2
    assert "cannot make the output folder" in r.stderr and "a_file" in r.stderr
    assert "grid check" not in r.stderr  # stopped before the frame was read


def test_output_folder_that_cannot_be_written_fails_before_the_work(tmp_path, shot):
    """A folder that exists but takes no file (``/sys`` refuses even root, whom permission
    bits do not stop): stopped before the frame is read, naming the folder."""
    lenslet, calib = shot
    sysfs = Path("/sys")
    if not sysfs.is_dir():
        pytest.skip("no /sys: not Linux")
    r = _cli("convert", str(lenslet), str(calib), "-o", str(sysfs))
    assert r.returncode == 2
    assert "/sys: cannot write to the output folder" in r.stderr and "-o" in r.stderr
    assert "grid check" not in r.stderr


def test_recording_options_on_one_image_are_refused(tmp_path, shot):
    """``--size``, ``--frames``, ``--setup-frame``, ``--format yuv``, ``--yuv-matrix``,
    ``--yuv-range`` and ``--temporal`` are for a raw YUV recording: on a PNG they would be
    ignored, so they stop the command instead."""
    lenslet, calib = shot
    out = tmp_path / "o"
    r = _cli("convert", str(lenslet), str(calib), "-o", str(out), "--frames", "0:2",
             "--format", "yuv")
    assert r.returncode == 2
    assert "--frames and --format yuv: for a raw YUV recording" in r.stderr
    assert "lenslet.png is one image" in r.stderr and not out.exists()
    r = _cli("convert", str(lenslet), str(calib), "-o", str(out), "--size", "480x400",
             "--setup-frame", "0")
    assert r.returncode == 2 and "--size and --setup-frame" in r.stderr
    r = _cli("convert", str(lenslet), str(calib), "-o", str(out), "--yuv-matrix", "bt709",
             "--yuv-range", "full", "--temporal", "off")
    assert r.returncode == 2 and not out.exists()
    assert "--yuv-matrix and --yuv-range and --temporal: for a raw YUV recording" in r.stderr


def test_a_rerun_that_fails_leaves_the_previous_views(tmp_path, shot, monkeypatch):
    """A second conversion into the same folder that fails after writing views (here:
    disparity.json, written last, made to fail) leaves every file of the first run as it
    was and no staging folder: not half the views replaced by another setting's."""
    import plenocal.io.files as files_mod  # noqa: PLC0415

    lenslet, calib = shot
    out = tmp_path / "views"
    args = ["convert", str(lenslet), str(calib), "-o", str(out), "--views", "3", "--mla",
            "keplerian", "-q"]
    assert main([*args, "--tile-size", "6"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert len(before) == 9 + 3

    def fail(path, obj):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(files_mod, "write_json", fail)
    assert main([*args, "--tile-size", "5"]) == 2  # another view size: every file differs
    monkeypatch.undo()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_folder_of_another_view_set_is_refused_before_the_work(tmp_path, shot):
    """A 1 x 1 run into the folder of a 3 x 3 run would replace 0_0.png (then a corner
    view) and leave the other eight beside it: stopped before the frame is read, naming
    the files, the folder as it was; a 3 x 3 run again, or into a folder holding other
    files, goes ahead."""
    lenslet, calib = shot
    out = tmp_path / "views"
    args = [str(lenslet), str(calib), "-o", str(out), "--mla", "keplerian"]
    assert main(["convert", *args, "--views", "3", "-q"]) == 0
    (out / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    r = _cli("convert", *args, "--views", "1")
    assert r.returncode == 2
    assert (f"{out}: holds 0_1.png, 0_2.png, 1_0.png, 1_1.png, ... (8 in all) from an "
            "earlier conversion, which this one (1 x 1 views of one image)") in r.stderr
    assert "grid check" not in r.stderr  # stopped before the frame was read
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert main(["convert", *args, "--views", "3", "-q"]) == 0
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


FRAMES = Path(__file__).resolve().parents[2] / "shared" / "real" / "frames"


@pytest.mark.skipif(not FRAMES.is_dir(), reason="shared/real/frames not present")
def test_unverified_grid_warned_and_kept(tmp_path, capsys):
    """R42_klein_crop: a frame whose micro images the check cannot read (16 % of lenses
    measured; its file's grid is right). The conversion runs, warns, keeps the file's grid
    under auto and refines only when told to (--grid refine)."""
    args = ["convert", str(FRAMES / "R42_klein_crop.png"), str(FRAMES / "R42_klein_crop.xml"),
            "--views", "3", "--tile-size", "4"]
    assert main([*args, "-o", str(tmp_path / "auto")]) == 0
    err = capsys.readouterr().err
    assert "cannot confirm the calib.xml grid" in err
    g = json.loads((tmp_path / "auto" / "disparity.json").read_text())["grid_check"]
    assert g["verified"] is False and g["foreign"] is False and g["refined"] is False
    assert main([*args, "-o", str(tmp_path / "refine"), "--grid", "refine", "-q"]) == 0
    g = json.loads((tmp_path / "refine" / "disparity.json").read_text())["grid_check"]
    assert g["refined"] is True


@pytest.mark.skipif(not FRAMES.is_dir(), reason="shared/real/frames not present")
def test_another_cameras_calib_xml_on_a_frame_the_check_cannot_read_stops(tmp_path, capsys):
    """R42_klein_crop with Origami's calib.xml: the grid check measures none of the lenses
    it takes as lit and the micro images match nothing as either MLA kind (0.06 at best):
    the conversion stops before any view, naming the file and the remedies; with
    grid_foreign=warn it converts all the same. With its own file (0.96) it converts."""
    frame = str(FRAMES / "R42_klein_crop.png")
    args = ["--views", "1", "--tile-size", "4", "-q"]
    out = tmp_path / "foreign"
    assert main(["convert", frame, str(FRAMES / "Origami.xml"), "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    for words in ("Origami.xml", "microlens grid is not found in", "R42_klein_crop.png",
                  "--set grid_foreign=warn"):
        assert words in err, (words, err)
    assert not list(out.glob("*.png"))  # stopped before any view
    assert main(["convert", frame, str(FRAMES / "Origami.xml"), "-o", str(tmp_path / "warn"),
                 *args, "--set", "grid_foreign=warn"]) == 0
    assert (tmp_path / "warn" / "0_0.png").is_file()
    assert main(["convert", frame, str(FRAMES / "R42_klein_crop.xml"), "-o",
                 str(tmp_path / "own"), *args]) == 0


def _setup_file(folder: Path, lenslet: Path, calib: Path, **edits) -> Path:
    """The set-up ``plenocal convert`` would decide on ``lenslet`` (as rule convert_setup
    writes it), with ``edits`` made to its keys, written into ``folder``."""
    from plenocal.convert.setup import decide_setup  # noqa: PLC0415
    from plenocal.convert.shot import ConvertSettings  # noqa: PLC0415

    setup, _ = decide_setup(read_image(lenslet), read_calib(calib), 3,
                            ConvertSettings(mla="keplerian", tile_size=6), str(lenslet))
    doc = {**setup.to_dict(), **edits}
    path = folder / f"setup{len(list(folder.glob('setup*.json')))}.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_setup_of_another_frame_size_or_edited_out_of_range_is_refused(tmp_path, shot):
    """--setup with a frame of another size than the one it was decided on (a crop, another
    camera) converted into a mosaic of wrong lenses without a word: now refused, naming the
    set-up and both sizes; so are a negative or oversized D', a tile under 2 and an unknown
    MLA kind, naming the file and the key; and the options the set-up decides. Nothing is
    written; an option it does not decide (the blend's prefilter) still converts."""
    lenslet, calib = shot
    setup = _setup_file(tmp_path, lenslet, calib)
    crop = tmp_path / "crop.png"
    write_image(crop, read_image(lenslet)[:360, :440])
    out = tmp_path / "o"
    r = _cli("convert", str(crop), str(calib), "-o", str(out), "--views", "3", "--setup",
             str(setup))
    assert r.returncode == 2 and not out.exists()
    assert f"{setup}: decided on a 480x400 frame" in r.stderr
    assert f"{crop} is 440x360" in r.stderr
    for edits, words in (({"safe_diameter_px": -3.0}, "safe_diameter_px = -3.0: a number > 0"),
                         ({"safe_diameter_px": 500.0}, "safe_diameter_px = 500, wider than"),
                         ({"q_px": 0.0}, "q_px = 0.0: a number > 0"),
                         ({"tile": 0}, "tile = 0: a whole number >= 2"),
                         ({"mla": "foo"}, "mla = 'foo': one of keplerian, galilean")):
        bad = _setup_file(tmp_path, lenslet, calib, **edits)
        r = _cli("convert", str(lenslet), str(calib), "-o", str(out), "--views", "3",
                 "--setup", str(bad))
        assert r.returncode == 2 and not out.exists(), edits
        assert f"{bad}: {words}" in r.stderr, r.stderr
    for option in (["--tile-size", "5"], ["--mla", "galilean"], ["--grid", "refine"],
                   ["--set", "safe_diameter=10"], ["--set", "upsample=2"]):
        r = _cli("convert", str(lenslet), str(calib), "-o", str(out), "--views", "3",
                 "--setup", str(setup), *option)
        assert r.returncode == 2 and not out.exists(), option
        assert f"with --setup {setup}: the set-up decides" in r.stderr, r.stderr
    # views of another number than the set-up's are other cameras under the same names
    r = _cli("convert", str(lenslet), str(calib), "-o", str(out), "--views", "5",
             "--setup", str(setup))
    assert r.returncode == 2 and not out.exists()
    assert (f"--views 5 with --setup {setup}: the set-up was decided for 3 x 3 views"
            in r.stderr), r.stderr
    assert main(["convert", str(lenslet), str(calib), "-o", str(out), "--views", "3",
                 "--setup", str(setup), "--set", "blend.prefilter=0", "-q"]) == 0
    assert json.loads((out / "disparity.json").read_text())["tile"] == 6
    # a view spacing set by hand (convert.view_spacing_px) says nothing of the number
    spaced = _setup_file(tmp_path, lenslet, calib, q_px=2.5)
    assert main(["convert", str(lenslet), str(calib), "-o", str(tmp_path / "q"), "--views",
                 "5", "--setup", str(spaced), "-q"]) == 0


def test_an_input_where_an_output_goes_an_empty_path_and_bad_numbers_are_refused(
        tmp_path, shot):
    """A lenslet image inside the output folder under a view's name was replaced by that
    view; ``-o ''`` (an unset variable) wrote into the working folder; --views 20001 ran
    out of memory listing names; --tile-size 1 and --bit-depth 7 were told of config keys.
    Each now stops at once with a line naming the option or file."""
    lenslet, calib = shot
    out = tmp_path / "o"
    out.mkdir()
    inside = out / "1_1.png"
    inside.write_bytes(lenslet.read_bytes())
    r = _cli("convert", str(inside), str(calib), "-o", str(out), "--views", "3")
    assert r.returncode == 2
    assert f"{inside}: an input where the conversion writes one of its outputs" in r.stderr
    assert inside.read_bytes() == lenslet.read_bytes() and len(list(out.iterdir())) == 1
    r = _cli("convert", str(lenslet), str(calib), "-o", "")
    assert r.returncode == 2 and "-o: an empty path" in r.stderr
    r = _cli("convert", str(lenslet), str(calib), "-o", str(tmp_path / "n"), "--views", "101")
    assert r.returncode == 2 and "--views: an odd number 1..99" in r.stderr
    for option, words in ((["--tile-size", "1"], "--tile-size: 'auto' or a whole number >= 2"),
                          (["--bit-depth", "7"], "--bit-depth: 'auto' or a whole number 8..16")):
        r = _cli("convert", str(lenslet), str(calib), "-o", str(tmp_path / "n"), *option)
        assert r.returncode == 2 and words in r.stderr, r.stderr
    assert not (tmp_path / "n").exists()


def test_a_stop_or_a_full_disk_leaves_nothing_and_says_so(tmp_path, shot):
    """SIGTERM (a cluster's or kill's stop) and Ctrl-C in the middle of writing the views:
    exit 130 with one line, no traceback, and nothing of the run left (no staging folder,
    no folder it made); a full disk names the output folder and the remedy, where the
    system's words name nothing."""
    lenslet, calib = shot
    for how in ("SIGTERM", "SIGINT"):
        out = tmp_path / how
        code = (
            "import os, signal, sys\n"
            # as in a terminal: a test runner's worker may hand its children SIGINT ignored
            "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
            "import plenocal.io.files as f\n"
            "from plenocal.cli import main\n"
            "real = f.write_image\n"
            "def stop(path, img, *a, **k):\n"
            "    real(path, img, *a, **k)\n"
            "    if path.name == '1_1.png':\n"
            f"        os.kill(os.getpid(), signal.{how})\n"
            "f.write_image = stop\n"
            f"sys.exit(main(['convert', {str(lenslet)!r}, {str(calib)!r}, '-o', "
            f"{str(out)!r}, '--views', '3', '--mla', 'keplerian', '--threads', '1']))\n")
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 130, (how, r.stderr)
        assert f"stopped; nothing of this run was kept in {out}" in r.stderr
        assert "Traceback" not in r.stderr
        assert not out.exists(), sorted(p.name for p in out.rglob("*"))
    out = tmp_path / "full"
    code = (
        "import errno, sys\n"
        "import plenocal.io.files as f\n"
        "from plenocal.cli import main\n"
        "def full(path, img, *a, **k):\n"
        "    raise OSError(errno.ENOSPC, 'No space left on device')\n"
        "f.write_image = full\n"
        f"sys.exit(main(['convert', {str(lenslet)!r}, {str(calib)!r}, '-o', {str(out)!r}, "
        "'--views', '3', '--mla', 'keplerian', '--threads', '1']))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2, r.stderr
    assert (f"{out}: No space left on device while writing the outputs; free space there or "
            "choose another folder with -o") in r.stderr
    assert not out.exists()
