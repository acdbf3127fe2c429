"""A real capture through the whole workflow (README, "Bringing a real capture"): the
tiny simulator's lenslet images, calib.xml and camera.yaml copied into a dataset with
no `simulate` block. The default target, every `--until` and the report run; nothing
that needs ground truth is asked for. Bad input stops before any job, naming the file
and the key."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import ROOT, clone, snakemake, snakemake_each, workflow_copy

from plenocal.artifacts.results import read_reprojection_table

pytestmark = pytest.mark.workflow

NAME = "capture"


def real_config() -> dict:
    """The tiny config's stage settings, the dataset without its simulate block (SfM of
    all views from scratch left off: it is no check of a real capture's path)."""
    cfg = yaml.safe_load((ROOT / "tests" / "tiny" / "config.yaml").read_text())
    tiny = cfg.pop("datasets")["tiny"]
    cfg["datasets"] = {NAME: {"views": tiny["views"], "mla": "keplerian"}}
    cfg.setdefault("sfm", {}).setdefault("baseline", {})["from_scratch"] = False
    return cfg


def make_capture(src_run: Path, dest: Path) -> Path:
    work = workflow_copy(dest)
    data = work / "data" / NAME
    (data / "lenslet").mkdir(parents=True)
    for p in sorted((src_run / "data" / "tiny" / "lenslet").glob("*.png")):
        shutil.copy2(p, data / "lenslet" / p.name)
    for name in ("calib.xml", "camera.yaml"):
        shutil.copy2(src_run / "data" / "tiny" / name, data / name)
    (work / "config.yaml").write_text(yaml.safe_dump(real_config(), sort_keys=False))
    return work


@pytest.fixture(scope="module")
def real_run(tiny_complete_run, tmp_path_factory) -> Path:
    work = make_capture(tiny_complete_run, tmp_path_factory.mktemp("real"))
    proc = snakemake(work)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    return work


def test_real_capture_runs_the_default_target(real_run: Path):
    res = real_run / "results" / NAME
    shots = sorted(p.stem for p in (real_run / "data" / NAME / "lenslet").glob("*.png"))
    from plenocal.artifacts.cameras import read_cameras

    views = read_cameras(res / "calibration" / "cameras.json")
    assert sorted({k.split("/")[0] for k in views}) == shots and len(views) == 10 * 3 * 3
    for rel in ("reg_a/reg_a.json", "reg_b/rig.json", "merge/scale.json",
                "eval/reprojection.json", "eval/synthesis_exp3.json", "report/index.html"):
        assert (res / rel).is_file(), rel
    # nothing that needs ground truth was made or asked for
    assert not (res / "ground_truth").exists() and not (res / "eval" / "gt_errors.json").exists()
    assert not (res / "convert" / "quality.json").exists()
    table1 = read_reprojection_table(res / "eval" / "reprojection.json").rows
    assert "ground_truth" not in table1 and "complete" in table1
    html = (res / "report" / "index.html").read_text()
    first = html[:html.index('id="table1"')]
    assert "Real capture" in first and 'id="not-checked"' in first
    assert re.search(r'<p id="table1-verdict">.*?0\.927', html)
    assert 'id="warnings"' in first
    # and nothing is left to do
    proc = snakemake(real_run, "-n")
    assert "Nothing to be done" in proc.stdout + proc.stderr, (proc.stdout + proc.stderr)[-2000:]


def test_a_shot_replaced_by_an_older_file_is_converted_again(real_run: Path, tmp_path: Path):
    """A shot replaced by a file whose time stamp is older than its views (``cp -p``,
    ``rsync -a``, an unpacked archive) kept the old views: Snakemake compares time stamps.
    The conversions' params hold each file's fingerprint (plenocal.io.lenslet.fingerprint),
    so the replaced shot's conversion runs again; the same bytes under that older time
    stamp are not a change."""
    work = clone(real_run, tmp_path / "work")
    shot = work / "data" / NAME / "lenslet" / "x01_y00.png"
    old = shot.stat()
    # the shot mirrored, in a process of its own (cv2 before pycolmap: DESIGN.md)
    subprocess.run([sys.executable, "-c", "import sys, cv2; p = sys.argv[1]; cv2.imwrite(p, "
                    "cv2.flip(cv2.imread(p, cv2.IMREAD_UNCHANGED), 1))", str(shot)], check=True)
    os.utime(shot, ns=(old.st_atime_ns, old.st_mtime_ns - 10**12))
    proc = snakemake(work, "-n")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    assert re.search(r"views/x01_y00/analysis\.npz(?:.|\n)*?reason: Params have changed", out), \
        out[-3000:]
    # the same bytes under the same older time stamp in a fresh copy: nothing (the
    # fingerprint adds no rerun of its own; a newer time stamp reruns, as Snakemake does)
    again = clone(real_run, tmp_path / "again")
    other = again / "data" / NAME / "lenslet" / "x01_y00.png"
    os.utime(other, ns=(old.st_atime_ns, old.st_mtime_ns - 10**12))
    proc = snakemake(again, "-n")
    assert "Nothing to be done" in proc.stdout + proc.stderr, (proc.stdout + proc.stderr)[-2000:]


def test_every_until_builds_its_job_graph(real_run: Path, tmp_path: Path):
    """From a fresh copy of the capture (no results): each rule's --until dry run plans
    its jobs; the ground-truth rules plan none."""
    work = workflow_copy(tmp_path / "w")
    shutil.copytree(real_run / "data", work / "data")
    shutil.copy2(real_run / "config.yaml", work / "config.yaml")
    # one rule per line, a docstring may follow the name
    rules = [ln.split()[0] for ln in snakemake(work, "--list-rules").stdout.splitlines()
             if ln.strip()]
    assert "report" in rules and "convert_quality" in rules
    gt_rules = {"simulate", "simulate_setup", "ground_truth",
                "ground_truth_render", "ground_truth_render_set",
                "ground_truth_render_central", "gt_errors", "convert_quality"}
    # two dry runs at a time (one core each)
    procs = snakemake_each(work, [("-n", "--until", rule) for rule in rules])
    for rule, proc in zip(rules, procs, strict=True):
        out = proc.stdout + proc.stderr
        assert proc.returncode == 0, (rule, out[-2000:])
        jobs = set(re.findall(r"^(?:local)?rule (\w+):", out, flags=re.M))
        assert not jobs & gt_rules, (rule, jobs & gt_rules)
        if rule in ("convert_0", "map_a", "rig_b", "depth_a", "depth_b_0", "merge", "reprojection",
                    "synthesis_exp3", "report"):
            assert rule in jobs, (rule, out[-2000:])
    assert not (work / "results").exists()


def _bad(real_run: Path, dest: Path, change) -> tuple[str, Path]:
    work = workflow_copy(dest)
    shutil.copytree(real_run / "data" / NAME / "lenslet", work / "data" / NAME / "lenslet")
    for name in ("calib.xml", "camera.yaml"):
        shutil.copy2(real_run / "data" / NAME / name, work / "data" / NAME / name)
    shutil.copy2(real_run / "config.yaml", work / "config.yaml")
    change(work / "data" / NAME)
    proc = snakemake(work, "-n")
    assert proc.returncode != 0
    assert not (work / "results").exists()
    return proc.stdout + proc.stderr, work


def test_bad_input_stops_before_any_job(real_run: Path, tmp_path: Path):
    def upper(d: Path):
        (d / "lenslet" / "hand01.png").rename(d / "lenslet" / "hand01.PNG")
        (d / "lenslet" / "notes.txt").write_text("shot at 2 pm\n")

    out, _ = _bad(real_run, tmp_path / "a", upper)
    assert "hand01.PNG (rename it to .png)" in out and "notes.txt" in out, out[-2000:]

    def units(d: Path):
        doc = yaml.safe_load((d / "camera.yaml").read_text())
        doc["pixel_size_mm"] = "5.5 um"
        (d / "camera.yaml").write_text(yaml.safe_dump(doc))

    out, _ = _bad(real_run, tmp_path / "b", units)
    assert "camera.yaml: pixel_size_mm = '5.5 um'" in out, out[-2000:]

    def micrometres(d: Path):
        doc = yaml.safe_load((d / "camera.yaml").read_text())
        doc["mla"]["pitch_mm"] = 1000 * doc["mla"]["pitch_mm"]
        (d / "camera.yaml").write_text(yaml.safe_dump(doc))

    out, _ = _bad(real_run, tmp_path / "c", micrometres)
    assert "mla.pitch_mm" in out and "micrometres" in out, out[-2000:]

    def other_sensor(d: Path):  # a plausible pixel size, but not this camera's
        doc = yaml.safe_load((d / "camera.yaml").read_text())
        doc["pixel_size_mm"] = 0.00345
        (d / "camera.yaml").write_text(yaml.safe_dump(doc))

    out, _ = _bad(real_run, tmp_path / "c2", other_sensor)
    assert "camera.yaml: mla.pitch_mm = 0.13: with pixel_size_mm = 0.00345" in out, out[-2000:]
    assert f"data/{NAME}/calib.xml gives a diameter of" in out, out[-2000:]

    # issue 34: a typo in camera.yaml hid the Eqs. 2-3 check (and the report's warning)
    def typo(d: Path):
        doc = yaml.safe_load((d / "camera.yaml").read_text())
        doc["scene"] = {"near": doc["scene"]["near_mm"], "far": doc["scene"]["far_mm"]}
        (d / "camera.yaml").write_text(yaml.safe_dump(doc))

    out, _ = _bad(real_run, tmp_path / "d", typo)
    assert re.search(r"camera\.yaml: scene\.(far|near): unknown key - did you mean "
                     r"scene\.(far|near)_mm\?", out), out[-2000:]

    # issue 34: other scripts' digits passed the name check, then failed unnamed
    def digits(d: Path):
        (d / "lenslet" / "x00_y00.png").rename(d / "lenslet" / "x\u0660\u0660_y\u0660\u0660.png")

    out, _ = _bad(real_run, tmp_path / "e", digits)
    assert "move or rename x\u0660\u0660_y\u0660\u0660.png" in out, out[-2000:]

    # a corner shot missing: Snakemake's MissingInputException for depth_view named none
    def corner(d: Path):
        (d / "lenslet" / "x00_y00.png").unlink()

    out, _ = _bad(real_run, tmp_path / "f", corner)
    assert "grid from x00_y00: x00_y00 missing" in out, out[-2000:]

    # a calib.xml cut short: found by the first job before, as a traceback
    def calib(d: Path):
        (d / "calib.xml").write_text((d / "calib.xml").read_text()[:200])

    out, _ = _bad(real_run, tmp_path / "g", calib)
    assert "calib.xml: <document>: malformed XML" in out, out[-2000:]

    # a copy cut short passed the dry run and failed in its conversion job (a review)
    def cut(d: Path):
        png = d / "lenslet" / "x01_y00.png"
        png.write_bytes(png.read_bytes()[:5000])

    out, _ = _bad(real_run, tmp_path / "h", cut)
    assert "x01_y00.png: a truncated PNG, cut short" in out, out[-2000:]

    # a key given twice in config.yaml: Snakemake's loader kept the last one silently
    def twice(d: Path):
        config = d.parent.parent / "config.yaml"
        text = config.read_text()
        assert "\n    views: 3\n" in text
        config.write_text(text.replace("\n    views: 3\n", "\n    views: 5\n    views: 3\n"))

    out, _ = _bad(real_run, tmp_path / "i", twice)
    assert f"config.yaml: datasets.{NAME}.views: given twice (lines" in out, out[-2000:]


def test_a_simulate_block_never_overwrites_a_capture(real_run: Path, tmp_path: Path):
    """A 'simulate' block added to a real capture's dataset: the simulator would write
    calib.xml, camera.yaml and the lenslet images over the capture's. The run stops before
    any job, naming what is there, and every file keeps its bytes."""
    work = workflow_copy(tmp_path / "w")
    shutil.copytree(real_run / "data" / NAME, work / "data" / NAME)
    before = {p: p.read_bytes() for p in sorted((work / "data" / NAME).rglob("*"))
              if p.is_file()}
    cfg = yaml.safe_load((real_run / "config.yaml").read_text())
    cfg["datasets"][NAME]["simulate"] = {}
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    proc = snakemake(work, "--until", "simulate_setup")
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert (f"data/{NAME}/ already holds calib.xml, camera.yaml, lenslet that the simulator "
            "did not write") in out, out[-2000:]
    assert f"Remove the 'simulate' block from datasets.{NAME}" in out, out[-2000:]
    after = {p: p.read_bytes() for p in sorted((work / "data" / NAME).rglob("*"))
             if p.is_file()}
    assert after == before


# --- shots given as videos (README, "Bringing a real capture") ------------------------

#: the shots given as 10-bit YUV recordings, and the frame to calibrate on: the shot that
#: convert_setup decides on (common.smk full_set_cam) named MPEG-style, a hand-held shot
#: bare (its size and bit depth from the config)
VIDEO_FRAMES = {"x01_y01": 1, "hand01": 2}


def video_frames(png: Path, k: int) -> list:
    """Three frames (RGB in [0, 1]) of a recording whose frame ``k`` is the PNG's content,
    the others the PNG inverted and flipped: a wrong frame cannot pass for it."""
    from plenocal.io.files import read_image, to_float

    rgb = to_float(read_image(png))
    frames = [1.0 - rgb, rgb[::-1]]
    frames.insert(k, rgb)
    return frames


def give_as_videos(lenslet: Path) -> dict:
    """Replace VIDEO_FRAMES' PNGs in ``lenslet/`` by 10-bit YUV recordings; the chosen
    frame is the PNG's content. Returns {shot: (recording, its format)}."""
    from plenocal.io.yuv import YuvFormat, rgb_to_yuv, write_frame

    out = {}
    for shot, k in VIDEO_FRAMES.items():
        frames = video_frames(lenslet / f"{shot}.png", k)
        H, W = frames[0].shape[:2]
        fmt = YuvFormat(W, H, 10)
        name = f"{shot}_{W}x{H}_30fps_10bit.yuv" if shot.startswith("x") else f"{shot}.yuv"
        with open(lenslet / name, "wb") as fh:
            for rgb in frames:
                write_frame(fh, rgb_to_yuv(rgb, 10), fmt)
        (lenslet / f"{shot}.png").unlink()
        out[shot] = (lenslet / name, fmt)
    return out


@pytest.fixture(scope="module")
def video_capture(tiny_complete_run, tmp_path_factory) -> tuple[Path, dict]:
    """A copy of the real capture whose VIDEO_FRAMES shots are recordings, its PNG shots
    converted with convert.bit_depth 8 (theirs: a frame read with that would fail)."""
    work = make_capture(tiny_complete_run, tmp_path_factory.mktemp("video"))
    videos = give_as_videos(work / "data" / NAME / "lenslet")
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg["datasets"][NAME]["video"] = {"frame": dict(VIDEO_FRAMES), "size": "1280x960",
                                      "bit_depth": 10}
    cfg.setdefault("convert", {})["bit_depth"] = 8
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return work, videos


def test_shots_given_as_videos_convert_their_frame(video_capture, tiny_complete_run):
    import json

    import numpy as np

    from plenocal.convert.video import lenslet_frame
    from plenocal.io.files import read_image
    from plenocal.io.yuv import read_frame

    work, videos = video_capture
    proc = snakemake(work, "--until", "convert")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert set(re.findall(r"^(?:local)?rule (lenslet_frame):", out, flags=re.M)) \
        == {"lenslet_frame"}
    res = work / "results" / NAME
    assert not (res / "reg_a").exists()  # --until convert stopped there
    for shot, (path, fmt) in videos.items():
        frame = read_image(res / "lenslet" / f"{shot}.png")
        assert frame.dtype == np.uint16 and frame.shape == (fmt.height, fmt.width, 3)
        # the chosen frame, as `plenocal convert` makes it of a frame
        assert np.array_equal(frame, lenslet_frame(read_frame(path, fmt, VIDEO_FRAMES[shot]),
                                                   10))
        # ... which is the PNG's content (10-bit YUV 4:2:0 of it), not another frame
        png = read_image(tiny_complete_run / "data" / "tiny" / "lenslet" / f"{shot}.png")
        diff = np.abs(frame / 257.0 - png).mean()  # 1.1-1.5 (the wrong frames: 50-55)
        assert diff < 5.0, (shot, diff)
        assert not (work / "data" / NAME / "lenslet" / f"{shot}.png").exists()
        assert (res / "logs" / "lenslet_frame" / f"{shot}.log").is_file()
        # converted with 16 significant bits (convert.bit_depth 8 is the PNGs')
        views = res / "views" / shot
        assert json.loads((views / "disparity.json").read_text())["bit_depth"] == 16
        assert (views / "views.json").is_file()
        assert all((views / f"{r}_{c}.png").is_file() for r in range(3) for c in range(3))
        # its central view is the PNG's (the tiny run's conversion of the same image)
        centre = read_image(views / "1_1.png").astype(float)
        ref = read_image(tiny_complete_run / "results" / "tiny" / "views" / shot / "1_1.png")
        assert centre.shape == ref.shape
        diff = np.abs(centre - ref).mean()  # 0.7-0.8 (from the wrong frames: 47)
        assert diff < 3.0, (shot, diff)
    png_shot = res / "views" / "x00_y00" / "disparity.json"
    assert json.loads(png_shot.read_text())["bit_depth"] == 8
    # the converter's set-up was decided on a frame, read with 16 bits too
    setup = json.loads((res / "views" / "convert_setup.json").read_text())
    assert setup["decided_on"] == f"results/{NAME}/lenslet/x01_y01.png"


def test_video_settings_are_checked_before_any_job(video_capture, tmp_path: Path):
    """One case through the workflow (the others: tests/test_lenslet_folder.py)."""
    work, _ = video_capture
    dest = workflow_copy(tmp_path / "w")
    shutil.copytree(work / "data", dest / "data")
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg["datasets"][NAME]["video"]["frame"]["x01_y01"] = 3
    (dest / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    proc = snakemake(dest, "-n")
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0 and not (dest / "results").exists()
    assert (f"datasets.{NAME}.video.frame.x01_y01 = 3: " in out
            and "holds 3 frames (0..2): give an index below 3" in out), out[-2000:]


def test_raw_bayer_shots_are_demosaiced_by_the_workflow(tiny_complete_run, tmp_path: Path):
    """A real capture whose shots are raw one-channel RGGB readouts (the tiny run's lenslet
    images mosaicked) with ``convert.bayer: RGGB``: rule convert_setup and the conversions
    demosaic them, and each shot's central view is the colour frame's within the
    demosaicing's error."""
    import numpy as np

    from plenocal.convert.demosaic import mosaic
    from plenocal.io.files import read_image, write_image

    work = make_capture(tiny_complete_run, tmp_path / "bayer")
    shots = sorted((work / "data" / NAME / "lenslet").glob("*.png"))
    for path in shots:
        write_image(path, mosaic(read_image(path), "RGGB"))
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg.setdefault("convert", {})["bayer"] = "RGGB"
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    proc = snakemake(work, "--until", "convert")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    res = work / "results" / NAME
    for path in shots:
        centre = read_image(res / "views" / path.stem / "1_1.png").astype(float)
        ref = read_image(tiny_complete_run / "results" / "tiny" / "views" / path.stem
                         / "1_1.png").astype(float)
        assert centre.shape == ref.shape, path.stem
        diff = np.abs(centre - ref).mean() / ref.mean()
        assert diff < 0.03, (path.stem, diff)
