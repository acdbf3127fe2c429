"""A real capture's lenslet folder with shots given as raw YUV recordings
(plenocal.io.lenslet, config ``datasets.<d>.video``): what is read, and the errors, each
naming the file, the key and the remedy. Fast: tiny files, no workflow (the workflow's
run: tests/test_workflow_real.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from plenocal.config import ConfigError, validate_config
from plenocal.convert.video import lenslet_frame
from plenocal.io.lenslet import (
    CaptureError,
    VideoShot,
    check_capture,
    extract_frame,
    png_size,
    scan_lenslet_folder,
    video_shot_from_params,
)
from plenocal.io.yuv import DEFAULT_MATRIX, DEFAULT_RANGE, YuvFormat, read_frame

W, H = 24, 16  # two digits each: MPEG-style names
FMT = YuvFormat(W, H, 10)


def video_block(**video) -> dict:
    """The dataset's video block as the workflow gets it (validated, defaults filled)."""
    cfg = validate_config({"datasets": {"d": {"views": 3, "video": video}}})
    return cfg["datasets"]["d"]["video"]


def recording(path: Path, frames: int = 3, fmt: YuvFormat = FMT, extra: int = 0) -> Path:
    rng = np.random.default_rng(0)
    data = rng.integers(64, 940, size=frames * fmt.frame_samples).astype(fmt.dtype)
    path.write_bytes(data.tobytes() + b"\0" * extra)
    return path


def folder(tmp_path: Path, *names: str) -> Path:
    d = tmp_path / "lenslet"
    d.mkdir()
    for name in names:
        if name.endswith(".yuv"):
            recording(d / name)
        else:
            (d / name).write_bytes(b"")
    return d


def scan(d: Path, video: dict | None, sensor=None):
    return scan_lenslet_folder(d, "d", video, sensor)


def test_pngs_and_recordings(tmp_path: Path):
    d = folder(tmp_path, "x00_y00.png", f"x01_y00_{W}x{H}_30fps_10bit.yuv", "hand00.yuv",
               ".DS_Store")
    shots = scan(d, video_block(frame=2, size=f"{W}x{H}", bit_depth=10), sensor=(W, H))
    assert list(shots) == ["hand00", "x00_y00", "x01_y00"]
    assert shots["x00_y00"] == d / "x00_y00.png"
    v = shots["x01_y00"]
    assert isinstance(v, VideoShot) and v.fmt == FMT and v.frame == 2 and v.frames == 3
    # the command line's colour defaults
    assert (v.matrix, v.range) == (DEFAULT_MATRIX, DEFAULT_RANGE)
    # one frame per shot
    shots = scan(d, video_block(frame={"x01_y00": 0, "hand00": 1}, size=f"{W}x{H}",
                                bit_depth=10))
    assert shots["x01_y00"].frame == 0 and shots["hand00"].frame == 1
    assert shots["hand00"].fmt == FMT


def test_extracted_frame_is_the_converters(tmp_path: Path):
    path = recording(tmp_path / f"x00_y00_{W}x{H}_10bit.yuv")
    shot = scan_lenslet_folder(tmp_path, "d", video_block(frame=1, matrix="bt601",
                                                          range="full"))["x00_y00"]
    again = video_shot_from_params(path, shot.params())
    image = extract_frame(again)
    assert image.dtype == np.uint16 and image.shape == (H, W, 3)
    assert np.array_equal(image, lenslet_frame(read_frame(path, FMT, 1), 10, "bt601", "full"))
    assert not np.array_equal(image, extract_frame(video_shot_from_params(
        path, {**shot.params(), "frame": 0})))


@pytest.mark.parametrize("names, video, needles", [
    # a recording, and no frame to calibrate on
    (["x00_y00.yuv"], None, ["lenslet/x00_y00.yuv is a video recording",
                             "datasets.d.video: {frame: K}"]),
    # a video block, and no recording
    (["x00_y00.png"], {"frame": 0}, ["datasets.d.video is set", "no .yuv recording",
                                     "remove datasets.d.video"]),
    # both files of one shot
    (["x00_y00.png", f"x00_y00_{W}x{H}_10bit.yuv"], {"frame": 0},
     [f"x00_y00.png and x00_y00_{W}x{H}_10bit.yuv", "the shot x00_y00: keep one"]),
    (["x00_y00.yuv", f"x00_y00_{W}x{H}_10bit.yuv"], {"frame": 0, "size": f"{W}x{H}"},
     ["are both the shot x00_y00: keep one"]),
    # the frame index beyond the recording
    ([f"x00_y00_{W}x{H}_10bit.yuv"], {"frame": 3},
     [f"datasets.d.video.frame = 3: <dir>/x00_y00_{W}x{H}_10bit.yuv holds 3 frames "
      "(0..2): give an index below 3"]),
    (["x00_y00.yuv", "x01_y00.yuv"], {"frame": {"x00_y00": 0, "x01_y00": 5},
                                     "size": f"{W}x{H}", "bit_depth": 10},
     ["datasets.d.video.frame.x01_y00 = 5", "holds 3 frames"]),
    # a per-shot mapping missing a recording, or naming a shot that has none
    (["x00_y00.yuv", "x01_y00.yuv"], {"frame": {"x00_y00": 0}, "size": f"{W}x{H}",
                                     "bit_depth": 10},
     ["datasets.d.video.frame names no frame for x01_y00 (x01_y00.yuv)"]),
    (["x00_y00.yuv"], {"frame": {"x00_y00": 0, "hand03": 1}, "size": f"{W}x{H}",
                       "bit_depth": 10},
     ["datasets.d.video.frame names hand03", "remove or rename the key"]),
    # the format: nowhere, or the name and the config disagreeing
    (["x00_y00.yuv"], {"frame": 0}, ["x00_y00.yuv: the frame size (datasets.d.video.size",
                                     "and the bit depth (datasets.d.video.bit_depth",
                                     "x00_y00_3976x2956_30fps_10bit.yuv"]),
    ([f"x00_y00_{W}x{H}_10bit.yuv"], {"frame": 0, "size": "32x8"},
     [f"its name gives the size {W}x{H}, but datasets.d.video.size = '32x8'"]),
    ([f"x00_y00_{W}x{H}_10bit.yuv"], {"frame": 0, "bit_depth": 8},
     ["its name gives the bit depth 10 bits, but datasets.d.video.bit_depth = 8"]),
    # not a whole number of frames of the format
    ([f"x00_y00_{W}x18_8bit.yuv"], {"frame": 0},
     ["is not a whole number of 24x18 8-bit YUV 4:2:0 frames", "datasets.d.video.size"]),
    ([f"x00_y00_{W}x{2 * H}_10bit.yuv"], {"frame": 0},
     ["3456 bytes is not a whole number of 24x32 10-bit", "1.500 frames"]),
    # names
    (["x00_y00.YUV", "x00_y00-24x16.yuv", "cam1.yuv", "x00_y00.png.yuv"], {"frame": 0},
     ["x00_y00.YUV (rename it to .yuv)", "x00_y00-24x16.yuv", "cam1.yuv",
      "x00_y00.png.yuv", "x00_y00_3976x2956_10bit.yuv"]),
])
def test_errors_name_the_file_the_key_and_the_remedy(tmp_path, names, video, needles):
    d = folder(tmp_path, *names)
    with pytest.raises(CaptureError) as err:
        scan(d, None if video is None else video_block(**video))
    for needle in needles:
        assert needle.replace("<dir>", str(d)) in str(err.value), str(err.value)


def test_frames_of_another_size_than_the_sensor(tmp_path: Path):
    d = folder(tmp_path, f"x00_y00_{W}x{H}_10bit.yuv")
    assert scan(d, video_block(frame=0), sensor=(W, H))
    with pytest.raises(CaptureError, match=r"frames are 24x16 pixels but camera.yaml says "
                                           r"the sensor is 2048x1536"):
        scan(d, video_block(frame=0), sensor=(2048, 1536))


def test_a_cut_recording(tmp_path: Path):
    d = tmp_path / "lenslet"
    d.mkdir()
    recording(d / f"x00_y00_{W}x{H}_10bit.yuv", extra=10)
    with pytest.raises(CaptureError, match="a recording cut short"):
        scan(d, video_block(frame=0))
    (d / f"x00_y00_{W}x{H}_10bit.yuv").write_bytes(b"")
    with pytest.raises(CaptureError, match="0 bytes is not a whole number"):
        scan(d, video_block(frame=0))


def test_a_recording_of_another_bit_depth_than_its_name(tmp_path: Path):
    """Three 10-bit frames are six 8-bit ones to the byte, and four 8-bit frames two
    10-bit ones: the size check passes, and the workflow stopped a job later with a message
    about the command line's --bit-depth. The start-up check reads the named frame's middle
    and names the dataset's key."""
    d = tmp_path / "lenslet"
    d.mkdir()
    recording(d / f"x00_y00_{W}x{H}_8bit.yuv")  # 10-bit words, named 8-bit
    with pytest.raises(CaptureError, match=r"x00_y00_24x16_8bit.yuv: frame 1 reads as 16-bit "
                                           r"little-endian words.*Check the bit depth in its "
                                           r"name or datasets.d.video.bit_depth"):
        scan(d, video_block(frame=1))
    (d / f"x00_y00_{W}x{H}_8bit.yuv").unlink()
    eight = YuvFormat(W, H, 8)
    rng = np.random.default_rng(1)
    (d / f"x00_y00_{W}x{H}_10bit.yuv").write_bytes(
        rng.integers(16, 236, size=4 * eight.frame_samples).astype(np.uint8).tobytes())
    with pytest.raises(CaptureError, match=r"frame 0 holds samples up to \d+, which do not fit "
                                           r"10 bits: is the file 8-bit"):
        scan(d, video_block(frame=0))
    (d / f"x00_y00_{W}x{H}_10bit.yuv").unlink()
    recording(d / f"x00_y00_{W}x{H}_10bit.yuv")  # named as it is
    assert scan(d, video_block(frame=1))


@pytest.mark.parametrize("video, needle", [
    ({"frame": -1}, "datasets.d.video.frame = -1: must be >= 0"),
    ({"frame": 1.5}, "datasets.d.video.frame = 1.5: must be a whole number >= 0, or a mapping"),
    ({"frame": {"cam1": 2}}, "datasets.d.video.frame"),
    ({"frame": {"x00_y00": -2}}, "datasets.d.video.frame.x00_y00 = -2: must be >= 0"),
    ({}, "'frame' is a required property"),
    ({"frame": 0, "size": "1280"}, "datasets.d.video.size = '1280'"),
    ({"frame": 0, "bit_depth": 7}, "datasets.d.video.bit_depth = 7: must be >= 8"),
    ({"frame": 0, "matrix": "rec709"}, "must be one of bt709, bt601, bt2020"),
    ({"frame": 0, "frames": 2}, "unknown key(s) frames (allowed: bit_depth, frame, matrix"),
])
def test_schema_of_the_video_block(video, needle):
    with pytest.raises(ConfigError) as err:
        validate_config({"datasets": {"d": {"views": 3, "video": video}}})
    assert needle in str(err.value), str(err.value)


def test_no_video_block_for_a_synthetic_dataset():
    with pytest.raises(ConfigError, match=r"datasets.s.video = '\{...\}': only a real "
                                          r"capture's shots are given as videos"):
        validate_config({"datasets": {"s": {"simulate": {}, "video": {"frame": 0}}}})


def test_colour_defaults_are_the_command_lines():
    video = video_block(frame=0)
    assert (video["matrix"], video["range"]) == (DEFAULT_MATRIX, DEFAULT_RANGE)


def _pngs(d: Path, names: list[str], size=(W, H)) -> dict:
    """Real PNGs (flat grey images of ``size``, each shot its own level: two shots of one
    file's bytes are refused) for ``names``: {shot: path}."""
    from plenocal.io.files import write_image  # noqa: PLC0415

    d.mkdir(exist_ok=True)
    for k, n in enumerate(names):
        write_image(d / f"{n}.png", np.full((size[1], size[0]), 10 + k, np.uint8))
    return {n: d / f"{n}.png" for n in names}


def test_a_capture_needs_the_whole_grid_and_hand_held_shots(tmp_path: Path):
    """The array's layout is read from the shots' numbers: a grid with a hole, or one
    numbered from 1, would make the synthesis experiments name shots that do not exist
    (Snakemake's MissingInputException, naming none of them); no array shot gave an
    IndexError, no hand-held shot was refused only by registration A after every
    conversion. Each is now refused before any job, naming what is missing."""
    d = tmp_path / "lenslet"
    grid = ["x00_y00", "x01_y00", "x00_y01", "x01_y01"]
    check_capture(_pngs(d, [*grid, "hand00"]), "d", d, (W, H))
    cases = [
        (["x01_y01", "x02_y01", "x01_y02", "x02_y02", "hand00"],
         r"do not fill a 3 x 3 grid from x00_y00: x00_y00, x01_y00, x02_y00, x00_y01, "
         r"x00_y02 missing\. Number the columns and rows from 00"),
        (["x00_y00", "x01_y00", "x00_y01", "hand00"], r"2 x 2 grid from x00_y00: x01_y01 missing"),
        (["hand00", "hand01"], r"holds no array shot"),
        (grid, r"holds no hand-held shot \(hand00\.png, \.\.\.\): registration A"),
    ]
    for k, (names, why) in enumerate(cases):
        dk = tmp_path / f"case{k}"
        with pytest.raises(CaptureError, match=rf"dataset 'd': .*{why}"):
            check_capture(_pngs(dk, names), "d", dk, (W, H))


def test_each_png_is_read_as_far_as_its_header(tmp_path: Path):
    """An empty or mislabelled PNG, and a PNG of another size than camera.yaml's sensor,
    are named before any job (the conversion found them, one job later, after other
    shots' work)."""
    d = tmp_path / "lenslet"
    shots = _pngs(d, ["x00_y00", "hand00"])
    assert png_size(shots["x00_y00"]) == (W, H)
    check_capture(shots, "d", d, (W, H))
    with pytest.raises(CaptureError, match=r"x00_y00\.png: the image is 24x16 pixels but "
                                           r"camera\.yaml says the sensor is 30x16.*crop"):
        check_capture(shots, "d", d, (30, H))
    shots["hand00"].write_bytes(b"")
    with pytest.raises(CaptureError, match=r"hand00\.png: not a PNG image"):
        check_capture(shots, "d", d, (W, H))
    shots["hand00"].write_bytes(b"\xff\xd8\xff\xe0" + bytes(40))  # a JPEG renamed
    with pytest.raises(CaptureError, match=r"hand00\.png: not a PNG image"):
        check_capture(shots, "d", d, (W, H))


def test_a_simulated_dataset_never_writes_over_a_capture(tmp_path: Path):
    """check_simulated_folder: a capture's calib.xml, camera.yaml or lenslet images with
    no truth/scene.json beside them stop a simulated dataset; the simulator's own files
    (truth/scene.json there), an empty lenslet folder or no folder at all do not."""
    from plenocal.io.lenslet import check_simulated_folder

    d = tmp_path / "data" / "cap"
    check_simulated_folder(d, "cap")  # nothing there yet
    (d / "lenslet").mkdir(parents=True)
    check_simulated_folder(d, "cap")  # an empty folder holds nothing to lose
    (d / "lenslet" / "x00_y00.png").write_bytes(b"png")
    (d / "calib.xml").write_text("<RayCalibData/>")
    with pytest.raises(CaptureError, match=r"already holds calib\.xml, lenslet that the "
                       r"simulator did not write .*datasets\.cap"):
        check_simulated_folder(d, "cap")
    # the workflow's record says the simulator wrote calib.xml: its truth/ was deleted,
    # and is made again
    check_simulated_folder(d, "cap", lambda path: path == d / "calib.xml")
    with pytest.raises(CaptureError):
        check_simulated_folder(d, "cap", lambda path: False)
    (d / "truth").mkdir()
    (d / "truth" / "scene.json").write_text("{}")
    check_simulated_folder(d, "cap")  # the simulator's own run


def test_a_link_to_no_file(tmp_path: Path):
    """A shot linked to a file that is not there (an unmounted disk) is named with its
    target, not met as a bare FileNotFoundError in a job."""
    lenslet = tmp_path / "lenslet"
    lenslet.mkdir()
    (lenslet / "hand01.png").symlink_to("/nonexistent/disk/hand01.png")
    with pytest.raises(CaptureError, match=r"hand01\.png in .*lenslet/ is a link to no file "
                       r"\(/nonexistent/disk/hand01\.png\): mount or copy"):
        scan_lenslet_folder(lenslet, "cap", None)


def test_shots_that_are_not_one_cameras_readouts(tmp_path: Path):
    """A review found these converting without a word, or failing one job later: a PNG
    cut short (its conversion job failed, the console naming only the rule), a palette or
    1-bit image (read as quantised levels), one grey shot among colour ones (its views grey,
    the synthesis 4-11 dB down), and a shot that is a copy of another (registration A put
    both on one spot; the warnings blamed the scale). Each is now named before any job."""
    from plenocal.io.files import write_image  # noqa: PLC0415

    names = ["x00_y00", "x01_y00", "hand00", "hand01"]
    rng = np.random.default_rng(1)
    d = tmp_path / "ok"
    shots = _pngs(d, names)
    for n in names:  # colour shots, all different
        write_image(shots[n], rng.integers(0, 255, (H, W, 3), dtype=np.uint8))
    check_capture(shots, "d", d, (W, H))
    # a copy cut short
    data = shots["x01_y00"].read_bytes()
    shots["x01_y00"].write_bytes(data[:len(data) // 2])
    with pytest.raises(CaptureError, match=r"x01_y00\.png: a truncated PNG, cut short .*copy "
                                           r"it again"):
        check_capture(shots, "d", d, (W, H))
    shots["x01_y00"].write_bytes(data)
    # one grey shot among colour ones, and the reverse
    grey = rng.integers(0, 255, (H, W), dtype=np.uint8)
    write_image(shots["hand01"], grey)
    with pytest.raises(CaptureError, match=r"ok/: hand01 is grey, the other 3 shots colour: "
                                           r"one camera gives every shot alike"):
        check_capture(shots, "d", d, (W, H))
    for n in ("x00_y00", "x01_y00", "hand00"):
        write_image(shots[n], rng.integers(0, 255, (H, W), dtype=np.uint8))
    write_image(shots["hand01"], rng.integers(0, 255, (H, W, 3), dtype=np.uint8))
    with pytest.raises(CaptureError, match=r"hand01 is colour \(RGB\), the other 3 shots grey"):
        check_capture(shots, "d", d, (W, H))
    write_image(shots["hand01"], grey)
    check_capture(shots, "d", d, (W, H))  # all grey: a monochrome or raw Bayer capture
    # a palette image and a 1-bit one
    from PIL import Image  # noqa: PLC0415

    keep = shots["hand00"].read_bytes()
    Image.fromarray(grey).convert("P").save(shots["hand00"])
    with pytest.raises(CaptureError, match=r"hand00\.png: a palette image, not the camera's"):
        check_capture(shots, "d", d, (W, H))
    Image.fromarray(grey).convert("1").save(shots["hand00"])
    with pytest.raises(CaptureError, match=r"hand00\.png: 1-bit samples"):
        check_capture(shots, "d", d, (W, H))
    shots["hand00"].write_bytes(keep)
    # a copy under a second name
    shots["x01_y00"].write_bytes(shots["x00_y00"].read_bytes())
    with pytest.raises(CaptureError, match=r"x01_y00\.png holds the same bytes as "
                                           r"x00_y00\.png: a copy.*put x01_y00's own"):
        check_capture(shots, "d", d, (W, H))


def test_frames_of_one_recording_are_not_copies(tmp_path: Path):
    """Hand-held shots taken as other frames of one recording (links to one file) are
    not copies; the same frame of it under two shots is (a review found the first refused
    as a copy)."""
    from plenocal.io.lenslet import check_no_copies  # noqa: PLC0415

    d = tmp_path / "lenslet"
    d.mkdir()
    rec = recording(tmp_path / "hand.yuv")
    for shot in ("hand00", "hand01"):
        (d / f"{shot}_{W}x{H}_10bit.yuv").symlink_to(rec)
    files = {s: d / f"{s}_{W}x{H}_10bit.yuv" for s in ("hand00", "hand01")}
    check_no_copies(files, d, {"hand00": 0, "hand01": 2})
    with pytest.raises(CaptureError, match=r"holds the same bytes as"):
        check_no_copies(files, d, {"hand00": 1, "hand01": 1})


def test_grey_with_alpha_counts_as_colour(tmp_path: Path):
    """OpenCV reads a grey PNG with alpha as three channels: among grey shots it is the odd
    one (it passed as grey and failed its conversion under convert.bayer)."""
    from PIL import Image  # noqa: PLC0415

    d = tmp_path / "lenslet"
    shots = _pngs(d, ["x00_y00", "x01_y00", "hand00"])
    Image.new("LA", (W, H), (40, 255)).save(shots["hand00"])
    with pytest.raises(CaptureError, match=r"hand00 is colour \(RGB\), the other 2 shots grey"):
        check_capture(shots, "d", d, (W, H))
