"""Lenslet video (issue 35): raw YUV 4:2:0 in, per-view YUV or per-frame PNGs out.

The clips are built here from crops of the real frames in shared/real/frames (frame 0 and
frame 150 of the MPEG sequences; skipped where the folder is absent): each crop's RGB made
into YUV 4:2:0 (:func:`plenocal.io.yuv.rgb_to_yuv`), with the crop's calibration
(:func:`test_convert_real.crop`)."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from test_convert_real import REAL, crop

from plenocal.convert import ConvertSettings
from plenocal.convert.setup import read_setup
from plenocal.convert.video import VideoConverter, VideoSettings, lenslet_frame, parse_frames
from plenocal.io.files import read_image, write_image
from plenocal.io.raytrix import write_calib
from plenocal.io.yuv import (
    YuvError,
    YuvFormat,
    parse_name,
    read_frame,
    resolve_format,
    rgb_to_yuv,
    write_frame,
    yuv_to_rgb,
)
from plenocal.names import view_names

needs_real = pytest.mark.skipif(REAL is None, reason="shared/real (real lenslet frames) is "
                                "not beside the repository")
BOX = (300, 300, 420, 320)  # Fujita2: books and the kangaroo's edge, ~200 lenses


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "plenocal.cli", *args], capture_output=True,
                          text=True, timeout=300)


def _frames(box=BOX) -> tuple[np.ndarray, np.ndarray, object]:
    a, calib = crop("Fujita2", *box)
    x0, y0, w, h = box
    b = cv2.imread(str(REAL / "frames" / "Fujita2_f150.png"))[y0:y0 + h, x0:x0 + w, ::-1]
    return a, np.ascontiguousarray(b), calib


def _clip(folder: Path, images: list[np.ndarray], bits: int, name: str | None = None) -> Path:
    h, w = images[0].shape[:2]
    fmt = YuvFormat(w, h, bits)
    path = folder / (name or f"clip_{w}x{h}_{bits}bit.yuv")
    with open(path, "wb") as fh:
        for img in images:
            write_frame(fh, rgb_to_yuv(img.astype(np.float32) / 255.0, bits), fmt)
    return path


def _video_of(folder: Path, images: list[np.ndarray], bits: int, calib):
    """``images`` as a ``bits``-bit clip with ``calib`` written as calib.xml, converted to
    per-view YUV videos (``--temporal off``): (clip, xml, out folder, stderr, video.json)."""
    clip = _clip(folder, images, bits)
    xml = folder / "calib.xml"
    write_calib(calib, xml)
    out = folder / "video"
    r = _cli("convert", str(clip), str(xml), "-o", str(out), "--format", "yuv",
             "--temporal", "off")
    assert r.returncode == 0, r.stderr
    return clip, xml, out, r.stderr, json.loads((out / "video.json").read_text())


def _rvs_read(path: Path, w: int, h: int, bits: int, frame: int) -> np.ndarray:
    """RVS 4.0's read_color_YUV (image_loading.cpp): seek ``area x elemSize x 3 / 2 x
    frame``, read Y (h x w), then U and V (h/2 x w/2, cv::Size / 2), native-endian samples
    of cvdepth_from_bit_depth (8 bits: uchar, else ushort); chroma resized to full size."""
    elem = 1 if bits <= 8 else 2
    dt = np.uint8 if elem == 1 else np.dtype("<u2")
    with open(path, "rb") as fh:
        fh.seek(w * h * elem * 3 // 2 * frame)
        y = np.frombuffer(fh.read(w * h * elem), dtype=dt).reshape(h, w)
        u = np.frombuffer(fh.read((w // 2) * (h // 2) * elem), dtype=dt).reshape(h // 2, w // 2)
        v = np.frombuffer(fh.read((w // 2) * (h // 2) * elem), dtype=dt).reshape(h // 2, w // 2)
    return np.stack([y, cv2.resize(u, (w, h)), cv2.resize(v, (w, h))], axis=-1)


# --------------------------------------------------------------------------- I/O


def test_names_give_size_and_depth():
    assert parse_name("Boys2_3976x2956_30fps_8bit.yuv") == ((3976, 2956), 8)
    assert parse_name("v_2_2_1440x1064_10bit_yuv420p10le.yuv") == ((1440, 1064), 10)
    assert parse_name("a_1920x1080_yuv420p.yuv") == ((1920, 1080), 8)
    assert parse_name("b_1920x1080_yuv420p10le.yuv") == ((1920, 1080), 10)
    assert parse_name("recording.yuv") == (None, None)
    # two different sizes state neither
    assert parse_name("c_10x20_8bit_30x40.yuv") == (None, 8)


@pytest.mark.parametrize("name", ["seq_64x64_8bit_yuv444p.yuv", "seq_64x64_yuv422p10le.yuv",
                                  "seq_64x64_10bit_444p.yuv", "seq_64x64_nv12.yuv",
                                  "seq_64x64_yuv420p10be.yuv", "seq_64x64_p010le.yuv"])
def test_a_name_of_another_pixel_format_is_refused(tmp_path, name):
    """A 4:4:4 file of two frames is as many bytes as a 4:2:0 file of four: read as 4:2:0
    it was four frames of noise, without a word (a review's finding). The name says it."""
    raw = tmp_path / name
    raw.write_bytes(bytes(64 * 64 * 3 * 2))
    with pytest.raises(YuvError, match=rf"{name}: its name states the pixel format .*"
                                       r"planar YUV 4:2:0.*ffmpeg"):
        resolve_format(raw)
    # the 4:2:0 names, and other words beside them, stay readable
    for ok in ("seq_64x64_8bit_yuv420p.yuv", "seq_64x64_yuv420p10le.yuv",
               "take422_64x64_8bit.yuv"):
        (tmp_path / ok).write_bytes(bytes(64 * 64 * 3 // 2 * (2 if "10" in ok else 1)))
        resolve_format(tmp_path / ok)


def test_odd_sizes_sample_chroma_as_the_even_frame_one_smaller():
    """An odd width or height's chroma planes (this reader's, as RVS's: rounded down) are
    upsampled by exactly 2, as an even frame's: the first W - 1 columns and H - 1 rows of
    a 65 x 49 frame are the 64 x 48 frame's with the same planes, bit for bit (resized to
    the frame's size instead, the chroma drifted up to a pixel by the far edges: -1.7
    levels on a ramp)."""
    rng = np.random.default_rng(5)
    y = rng.integers(0, 1024, (49, 65)).astype(np.uint16)
    cb, cr = (rng.integers(0, 1024, (24, 32)).astype(np.uint16) for _ in range(2))
    odd = yuv_to_rgb((y, cb, cr), 10)
    even = yuv_to_rgb((np.ascontiguousarray(y[:48, :64]), cb, cr), 10)
    assert odd.shape == (49, 65, 3)
    assert np.array_equal(odd[:48, :64], even)


def test_yuv_views_of_odd_size_are_refused(tmp_path):
    """--format yuv with convert.even_size false wrote odd-sized 4:2:0 videos that FFmpeg
    and this reader lay out differently: refused before any work, saying why."""
    clip, xml = tmp_path / "c_64x64_8bit.yuv", tmp_path / "calib.xml"
    clip.write_bytes(bytes(64 * 64 * 3 // 2))
    xml.write_text("<RayCalibData/>")
    r = _cli("convert", str(clip), str(xml), "-o", str(tmp_path / "o"), "--format", "yuv",
             "--set", "even_size=false")
    assert r.returncode == 2 and "even_size false" in r.stderr and "even width" in r.stderr
    assert not (tmp_path / "o").exists()


def test_format_errors_name_the_file_and_the_remedy(tmp_path):
    raw = tmp_path / "recording.yuv"
    raw.write_bytes(bytes(64 * 48 * 3 // 2 * 3))  # three 8-bit frames
    with pytest.raises(YuvError, match=r"recording\.yuv.*size \(--size WxH\).*bit depth"):
        resolve_format(raw)
    assert resolve_format(raw, (64, 48), 8) == YuvFormat(64, 48, 8)
    with pytest.raises(YuvError, match=r"recording\.yuv: 13824 bytes is not a whole number of "
                                       r"64x48 10-bit.*--size and --bit-depth"):
        resolve_format(raw, (64, 48), 10)
    named = tmp_path / "x_64x48_10bit.yuv"
    named.write_bytes(bytes(64 * 48 * 3))
    assert resolve_format(named) == YuvFormat(64, 48, 10)
    # a name that states two sizes or two depths says so, and --size / --bit-depth settle it
    two = tmp_path / "x_64x48_32x24_8bit_10bit.yuv"
    two.write_bytes(bytes(64 * 48 * 3 // 2 * 3))
    with pytest.raises(YuvError, match=r"x_64x48_32x24_8bit_10bit\.yuv: its name states two "
                                       r"sizes \(32x24 and 64x48\) and two bit depths \(8 and "
                                       r"10\): pass the right one"):
        resolve_format(two)
    with pytest.raises(YuvError, match=r"states two bit depths \(8 and 10\)"):
        resolve_format(two, (64, 48))
    assert resolve_format(two, (64, 48), 8) == YuvFormat(64, 48, 8)
    # the command line says it as one line with status 2
    r = _cli("convert", str(raw), str(raw), "-o", str(tmp_path / "o"))
    assert r.returncode == 2 and "recording.yuv" in r.stderr and "--size" in r.stderr


def test_a_name_and_options_that_disagree_are_refused(tmp_path):
    """``--size`` or ``--bit-depth`` against what the file's name states: an error naming
    both, not a silent choice (a 10-bit file read as 8-bit gave views of noise)."""
    named = tmp_path / "x_64x48_10bit.yuv"
    named.write_bytes(bytes(64 * 48 * 3 * 2))
    assert resolve_format(named, (64, 48), 10) == YuvFormat(64, 48, 10)  # agreeing: fine
    with pytest.raises(YuvError, match=r"x_64x48_10bit\.yuv: its name states 64x48, --size "
                                       r"says 48x64: leave --size out"):
        resolve_format(named, (48, 64))
    with pytest.raises(YuvError, match=r"its name states 10 bits, --bit-depth says 8"):
        resolve_format(named, None, 8)
    r = _cli("convert", str(named), str(named), "-o", str(tmp_path / "o"), "--bit-depth", "8")
    assert r.returncode == 2 and "states 10 bits" in r.stderr, r.stderr


def test_samples_that_cannot_be_of_the_depth_are_refused(tmp_path):
    """A frame whose samples do not fit the bit depth it is read with: 8-bit bytes read as
    10-bit words (values up to 65535), 10-bit words read as 8-bit bytes (every second luma
    byte 0..3). A dark 8-bit frame and a true 10-bit one read as they are."""
    rng = np.random.default_rng(0)
    w, h = 64, 48
    f10, f8 = YuvFormat(w, h, 10), YuvFormat(w, h, 8)
    planes10 = (rng.integers(64, 940, (h, w)), rng.integers(64, 960, (h // 2, w // 2)),
                rng.integers(64, 960, (h // 2, w // 2)))
    ten = tmp_path / "ten.yuv"
    with open(ten, "wb") as fh:
        write_frame(fh, planes10, f10)
    assert np.array_equal(read_frame(ten, f10, 0)[0], planes10[0])
    with pytest.raises(YuvError, match=r"ten\.yuv: frame 1 reads as 16-bit little-endian "
                                       r"words.*--bit-depth"):
        read_frame(ten, f8, 1)
    eight = tmp_path / "eight.yuv"
    planes8 = tuple(rng.integers(16, 236, p.shape) for p in planes10)
    with open(eight, "wb") as fh:
        for _ in range(2):
            write_frame(fh, planes8, f8)
    assert np.array_equal(read_frame(eight, f8, 1)[0], planes8[0])
    with pytest.raises(YuvError, match=r"eight\.yuv: frame 0 holds samples up to \d+, which "
                                       r"do not fit 10 bits"):
        read_frame(eight, f10, 0)
    black = tmp_path / "black.yuv"  # full-range black: every byte 0, no 16-bit pattern
    black.write_bytes(bytes(f8.frame_bytes))
    assert read_frame(black, f8, 0)[0].max() == 0


def test_odd_sizes_written_by_ffmpeg_are_named(tmp_path):
    """FFmpeg rounds an odd size's chroma planes up, RVS (and this reader) down: such a
    file is refused with what it is and how to crop it, not 'wrong size or bit depth'
    alone."""
    w, h = 63, 47
    ff = tmp_path / f"odd_{w}x{h}_8bit.yuv"
    ff.write_bytes(bytes((w * h + 2 * 32 * 24) * 3))  # three frames, chroma 32 x 24
    with pytest.raises(YuvError, match=r"a whole number \(3\) of frames whose chroma planes "
                                       r"are rounded up.*crop"):
        resolve_format(ff)
    rvs = tmp_path / f"rvs_{w}x{h}_8bit.yuv"
    rvs.write_bytes(bytes((w * h + 2 * 31 * 23) * 3))
    assert resolve_format(rvs) == YuvFormat(w, h, 8)


def test_frames_are_python_slices():
    assert list(parse_frames("2:5", 10)) == [2, 3, 4]
    assert list(parse_frames(":2", 10)) == [0, 1]
    assert list(parse_frames("-2:", 10)) == [8, 9]
    assert list(parse_frames("0:10:4", 10)) == [0, 4, 8]
    assert list(parse_frames("7", 10)) == [7]
    assert list(parse_frames(None, 3)) == [0, 1, 2]
    for bad in ("a:b", "12:20", "1:2:3:4"):
        with pytest.raises(Exception, match="--frames"):
            parse_frames(bad, 10)
    with pytest.raises(Exception, match=r"'5:2': selects none of the file's 10 frames "
                                        r"\(0\.\.9; A:B is A up to B, B excluded"):
        parse_frames("5:2", 10)


def test_frames_past_the_file_are_refused_not_clamped():
    assert list(parse_frames("0:3", 3)) == [0, 1, 2]  # the end may be the frame count
    assert list(parse_frames("-3:", 3)) == [0, 1, 2]
    assert list(parse_frames("2", 3)) == [2]
    # backwards: the end one past the first frame is -4 (-count - 1), the mirror of 0:3
    assert list(parse_frames("2:-4:-1", 3)) == [2, 1, 0]
    assert list(parse_frames("::-1", 3)) == [2, 1, 0]
    for bad, word in (("0:300", "end 300"), ("3", "frame 3"), ("5:", "frame 5"),
                      ("-4:", "frame -4"), ("0:-4", "end -4"), ("2:-5:-1", "end -5"),
                      ("2:3:-1", "end 3"), ("3::-1", "frame 3")):
        with pytest.raises(Exception, match=rf"'{bad}': {word} is past the file's 3 frames "
                                            r"\(0\.\.2\); leave the bound open"):
            parse_frames(bad, 3)
    with pytest.raises(Exception, match=r"'0:2:-1': selects none.*with a negative STEP, B "
                                        "must come before A"):
        parse_frames("0:2:-1", 3)


def test_yuv_round_trip_and_rvs_layout(tmp_path):
    """Flat colours survive RGB -> YUV -> RGB to the 10-bit step; the bytes are where
    RVS's reader looks for them (frame 1's planes at 1.5 x 2 x W x H bytes)."""
    rng = np.random.default_rng(0)
    blocks = rng.random((6, 5, 3)).astype(np.float32)
    rgb = np.repeat(np.repeat(blocks, 8, axis=0), 8, axis=1)  # 48 x 40, flat 8x8 blocks
    fmt = YuvFormat(40, 48, 10)
    planes = [rgb_to_yuv(rgb, 10), rgb_to_yuv(rgb[::-1].copy(), 10)]
    path = tmp_path / "t.yuv"
    with open(path, "wb") as fh:
        for p in planes:
            write_frame(fh, p, fmt)
    assert path.stat().st_size == 2 * 40 * 48 * 3
    for k in range(2):
        y, u, v = read_frame(path, fmt, k)
        rvs = _rvs_read(path, 40, 48, 10, k)
        assert np.array_equal(rvs[..., 0], planes[k][0]) and np.array_equal(y, planes[k][0])
        assert np.array_equal(u, planes[k][1]) and np.array_equal(v, planes[k][2])
    back = yuv_to_rgb(read_frame(path, fmt, 0), 10)
    inner = (slice(None), slice(None))
    err = np.abs(back - rgb)
    # away from the blocks' borders (chroma is interpolated across them)
    mask = np.zeros(rgb.shape[:2], bool)
    mask[2:-2, 2:-2] = True
    edge = np.zeros(rgb.shape[:2], bool)
    edge[::8] = edge[7::8] = edge[:, ::8] = edge[:, 7::8] = True
    edge[1::8] |= True
    edge[6::8] |= True
    edge[:, 1::8] |= True
    edge[:, 6::8] |= True
    assert err[inner][mask & ~edge].max() < 2.0 / 876
    assert planes[0][0].dtype == np.uint16 and planes[0][0].max() <= 940  # limited range


# --------------------------------------------------------------------------- conversion


@needs_real
def test_10bit_clip_to_10bit_view_videos_matching_the_frames_pngs(tmp_path):
    """A 10-bit clip (frames 0, 150, 0 of a Fujita2 crop) converts to one 10-bit YUV 4:2:0
    video per view, readable as RVS reads it, one view size for all frames; each frame's
    views match, to the rounding of the outputs, those converted from the frame's PNG (the
    same YUV frame as a 16-bit RGB PNG) with the video's set-up."""
    a, b, calib = _frames()
    clip, xml, out, stderr, doc = _video_of(tmp_path, [a, b, a], 10, calib)
    for k in range(3):
        assert f"frame {k} ({k + 1}/3)" in stderr  # progress per frame
    # the recording's bit depth said once, not a 16-bit image's bits per frame
    assert stderr.count("10-bit recording, its frames read as 16-bit words") == 1
    assert stderr.count("significant bits (max") <= 1  # the set-up's decision only
    W, H = doc["views"]["width"], doc["views"]["height"]
    assert W % 2 == 0 and H % 2 == 0
    files = doc["views"]["files"]
    assert files["2_2"] == f"v_2_2_{W}x{H}_10bit_yuv420p10le.yuv"
    vfmt = YuvFormat(W, H, 10)
    fmt = resolve_format(clip)
    for k in range(3):
        png = tmp_path / f"f{k}.png"
        write_image(png, lenslet_frame(read_frame(clip, fmt, k), 10))
        ref = tmp_path / f"png{k}"
        r = _cli("convert", str(png), str(xml), "-o", str(ref), "--bit-depth", "16",
                 "--setup", str(out / "convert_setup.json"))
        assert r.returncode == 0, r.stderr
        worst, over, count = 0, 0, 0
        for name in ("2_2", "0_0", "4_4", "1_3"):
            path = out / files[name]
            assert path.stat().st_size == 3 * vfmt.frame_bytes
            got = read_frame(path, vfmt, k)
            assert np.array_equal(_rvs_read(path, W, H, 10, k)[..., 0], got[0])
            view = read_image(ref / f"{name}.png")
            assert view.shape == (H, W, 3)
            want = rgb_to_yuv(view.astype(np.float32) / 255.0, 10)
            for g, w in zip(got, want, strict=True):
                d = np.abs(g.astype(int) - w.astype(int))
                worst = max(worst, int(d.max()))
                over += int((d > 2).sum())
                count += d.size
        # the PNG views are 8-bit RGB: half an 8-bit step is 1.7 10-bit luma levels, and
        # where filled lenses are softened the 8-bit view is rounded twice (before and
        # after the blend with its blur: up to one 8-bit step, 3.4 levels), each output
        # rounded once more: at most 4 levels, and more than 2 on few pixels
        assert worst <= 4, (k, worst)
        assert over <= 0.01 * count, (k, over, count)


@needs_real
def test_16bit_png_views_keep_a_10bit_clips_levels(tmp_path):
    """``--png-bits 16``: a 10-bit clip's PNG views keep its levels. The frame's PNG
    converted to 16-bit views with the video's set-up matches the 10-bit view videos to a
    level (the 8-bit views above: 4), and the recording converted to PNG frames with
    ``--png-bits 16`` gives those same views, sample for sample. The option is refused
    with ``--format yuv``, whose videos are of the input's depth already."""
    a, _, calib = _frames()
    clip, xml, out, _, doc = _video_of(tmp_path, [a], 10, calib)
    W, H = doc["views"]["width"], doc["views"]["height"]
    assert doc["views"]["bits"] == 10
    vfmt, fmt = YuvFormat(W, H, 10), resolve_format(clip)
    png = tmp_path / "f0.png"
    write_image(png, lenslet_frame(read_frame(clip, fmt, 0), 10))
    single = tmp_path / "single"
    r = _cli("convert", str(png), str(xml), "-o", str(single), "--bit-depth", "16",
             "--setup", str(out / "convert_setup.json"), "--png-bits", "16")
    assert r.returncode == 0, r.stderr
    frames = tmp_path / "frames"
    r = _cli("convert", str(clip), str(xml), "-o", str(frames), "--format", "png",
             "--temporal", "off", "--setup", str(out / "convert_setup.json"),
             "--png-bits", "16")
    assert r.returncode == 0, r.stderr
    assert json.loads((frames / "video.json").read_text())["views"]["bits"] == 16
    for name in ("2_2", "0_0", "4_4", "1_3"):
        view = read_image(single / f"{name}.png")
        assert view.dtype == np.uint16 and view.shape == (H, W, 3)
        assert np.array_equal(read_image(frames / "frame_00000" / f"{name}.png"), view)
        # more than an 8-bit view's 256 levels in a channel: the 10 bits are kept
        assert len(np.unique(view[..., 1])) > 256
        got = read_frame(out / doc["views"]["files"][name], vfmt, 0)
        want = rgb_to_yuv(view.astype(np.float32) / 65535.0, 10)
        for g, w in zip(got, want, strict=True):
            assert np.abs(g.astype(int) - w.astype(int)).max() <= 1, name
    r = _cli("convert", str(clip), str(xml), "-o", str(tmp_path / "no"), "--format", "yuv",
             "--png-bits", "16")
    assert r.returncode == 2 and "--png-bits 16 with --format yuv" in r.stderr, r.stderr
    assert not (tmp_path / "no").exists()


@needs_real
def test_8bit_clip_to_8bit_view_videos_are_the_frames_png_views(tmp_path):
    """An 8-bit clip (frames 0, 150 of a Fujita2 crop) is held as 8-bit RGB frames, as their
    PNGs: each frame's view videos are exactly rgb_to_yuv of the 8-bit views converted from
    the frame's PNG (lenslet_frame written out) with the video's set-up."""
    a, b, calib = _frames()
    clip, xml, out, _, doc = _video_of(tmp_path, [a, b], 8, calib)
    W, H = doc["views"]["width"], doc["views"]["height"]
    vfmt = YuvFormat(W, H, 8)
    fmt = resolve_format(clip)
    for k in range(2):
        frame = lenslet_frame(read_frame(clip, fmt, k), 8)
        assert frame.dtype == np.uint8
        png = tmp_path / f"f{k}.png"
        write_image(png, frame)
        ref = tmp_path / f"png{k}"
        r = _cli("convert", str(png), str(xml), "-o", str(ref),
                 "--setup", str(out / "convert_setup.json"))
        assert r.returncode == 0, r.stderr
        for name in ("2_2", "0_0", "4_4"):
            got = read_frame(out / doc["views"]["files"][name], vfmt, k)
            want = rgb_to_yuv(read_image(ref / f"{name}.png").astype(np.float32) / 255.0, 8)
            for g, w in zip(got, want, strict=True):
                assert np.array_equal(g, w), (k, name)


def test_view_videos_hold_no_file_open(tmp_path):
    """33 x 33 views (1,089 files) under a limit of 256 open files: each frame is appended
    by opening its view's file for that write alone (every view's file held open at once
    failed past the system's limit, 1,024 on Linux by default)."""
    import resource  # noqa: PLC0415

    from plenocal.convert.video import ViewVideos  # noqa: PLC0415

    fmt = YuvFormat(4, 2, 8)
    names = view_names(33)
    planes = (np.full((2, 4), 7, np.uint8), np.full((1, 2), 8, np.uint8),
              np.full((1, 2), 9, np.uint8))
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(256, soft), hard))
    try:
        videos = ViewVideos(tmp_path, names, fmt)
        for _ in range(2):
            for name in names:
                videos.write(name, planes)
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    files = sorted(tmp_path.iterdir())
    assert len(files) == 33 * 33
    assert {f.read_bytes() for f in files} == {(bytes([7] * 8) + bytes([8, 8, 9, 9])) * 2}


def test_a_setup_frame_beside_a_setup_file_is_refused(tmp_path):
    """``--setup-frame`` with ``--setup``: the set-up is read, not decided, so the frame
    would be ignored; refused before any frame is read."""
    from plenocal.convert.errors import ConvertError  # noqa: PLC0415
    from plenocal.convert.setup import ConverterSetup  # noqa: PLC0415
    from plenocal.convert.video import convert_recording  # noqa: PLC0415
    from plenocal.io.raytrix import LensType, RayCalib  # noqa: PLC0415

    clip = tmp_path / "c_64x48_8bit.yuv"
    clip.write_bytes(bytes(YuvFormat(64, 48, 8).frame_bytes * 2))
    calib = RayCalib(diameter=10.0, offset=(0.0, 0.0), rotation=0.0, lens_border=1.0,
                     lens_base_x=(1.0, 0.0), lens_base_y=(0.5, 0.866),
                     lens_types=(LensType(0, (0.0, 0.0), 1.0, 100.0),), source="c.xml")
    setup = ConverterSetup(mla="keplerian", tile=6, grid_mode="file", refined=False,
                           lattice=None, decided_on="x", mla_source="setting",
                           tile_source="setting", mla_match_scores=None, grid_check={},
                           warnings=())
    with pytest.raises(ConvertError, match=r"--setup-frame 1 with --setup: .*give one"):
        convert_recording(clip, calib, tmp_path / "o", 5, ConvertSettings(), setup=setup,
                          setup_frame=1)
    assert not (tmp_path / "o").exists()


@needs_real
def test_a_recording_that_fails_leaves_the_previous_run_as_it_was(tmp_path, monkeypatch):
    """A rerun into the same folder that stops at its second frame (here: made to fail)
    leaves every file of the first run as it was, the set-up included, and no staging
    folder; the same with per-view videos. A negative --setup-frame counts from the end."""
    import plenocal.convert.video as video_mod  # noqa: PLC0415

    a, b, calib = _frames()
    clip = _clip(tmp_path, [a, b, a], 8)
    xml = tmp_path / "calib.xml"
    write_calib(calib, xml)
    for fmt in ("png", "yuv"):
        out = tmp_path / fmt
        video_mod.convert_recording(clip, calib, out, 3, ConvertSettings(mla="galilean"),
                                    out_format=fmt, setup_frame=-1)
        before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
        assert json.loads((out / "convert_setup.json").read_text())["decided_on"].endswith(
            "[2]")
        calls = []
        convert = video_mod.VideoConverter.convert

        def failing(self, image, source, _convert=convert, _calls=calls):
            _calls.append(source)
            if len(_calls) == 2:
                raise RuntimeError("stopped")
            return _convert(self, image, source)

        monkeypatch.setattr(video_mod.VideoConverter, "convert", failing)
        with pytest.raises(RuntimeError, match="stopped"):
            video_mod.convert_recording(clip, calib, out, 3,
                                        ConvertSettings(mla="keplerian"), out_format=fmt)
        monkeypatch.undo()
        after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
        assert after == before, fmt
        assert not [p for p in out.iterdir() if p.name.startswith(".")], fmt


@needs_real
def test_identical_frames_give_identical_views(tmp_path):
    """Frames A A B B: frame 1 equals frame 0 and frame 3 frame 2 byte for byte, with the
    temporal hold (the default) and per-frame PNG output; every run the same bytes, in
    every file (video.json and convert_setup.json too: no times in them)."""
    a, b, calib = _frames()
    clip = _clip(tmp_path, [a, a, b, b], 8)
    xml = tmp_path / "calib.xml"
    write_calib(calib, xml)
    runs = []
    for k in range(2):
        out = tmp_path / f"o{k}"
        r = _cli("convert", str(clip), str(xml), "-o", str(out), "--format", "yuv")
        assert r.returncode == 0, r.stderr
        runs.append(out)
    doc = json.loads((runs[0] / "video.json").read_text())
    vfmt = YuvFormat(doc["views"]["width"], doc["views"]["height"], 8)
    assert [f["held_share"] for f in doc["frames"]][1] == 1.0
    for name in view_names(5):
        path = runs[0] / doc["views"]["files"][name]
        data = path.read_bytes()
        frames = [data[k * vfmt.frame_bytes:(k + 1) * vfmt.frame_bytes] for k in range(4)]
        assert frames[0] == frames[1] and frames[2] == frames[3] and frames[0] != frames[2]
    files = sorted(p.name for p in runs[0].iterdir())
    assert "video.json" in files and files == sorted(p.name for p in runs[1].iterdir())
    for name in files:
        assert (runs[0] / name).read_bytes() == (runs[1] / name).read_bytes(), name
    r = _cli("convert", str(clip), str(xml), "-o", str(tmp_path / "png"), "--frames", "2:4")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "png").glob("frame_*")) == ["frame_00002",
                                                                       "frame_00003"]
    for name in ("2_2", "0_4"):
        assert ((tmp_path / "png/frame_00002" / f"{name}.png").read_bytes()
                == (tmp_path / "png/frame_00003" / f"{name}.png").read_bytes())


def test_a_warning_is_said_once_per_recording(tmp_path):
    """Every frame of a clip whose calibration file cuts the patch-size search (a plane at
    4.5 px, the file's sizes 6-9 px) gets the range warning; the recording says it once,
    then how many more frames had it."""
    from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture

    from plenocal.grid import MicrolensGrid
    from plenocal.optics import PlenopticOptics

    opt = PlenopticOptics(focal_length=0.035, focus_distance=0.6, mla_pitch=130e-6,
                          mla_f_number=2.8, k=5.0, pixel_size=5.5e-6, width=480, height=300)
    D = opt.micro_image_pitch_px
    calib = calib_for_optics(opt, depth_range=(D / 9.0, D / 6.0))
    img = lenslet_from_patch_size(MicrolensGrid(calib, 480, 300), 4.5,
                                  random_texture(512, 1.5, 4))
    clip = _clip(tmp_path, [img] * 3, 8)
    xml = tmp_path / "calib.xml"
    write_calib(calib, xml)
    r = _cli("convert", str(clip), str(xml), "-o", str(tmp_path / "o"), "--format", "yuv",
             "--mla", "keplerian")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    said = [ln for ln in lines if "Widen the lens_type depth_range" in ln]
    assert len(said) == 1, said
    assert [ln for ln in lines if "came again on 2 more frame(s)" in ln], r.stderr


@needs_real
@pytest.mark.parametrize("frames", ["0:2", "1:2"])
def test_the_decided_frame_is_read_once(tmp_path, monkeypatch, frames):
    """The frame the set-up is decided on (the first converted) is read from the file and
    turned into RGB once, not again for its views: two frames, two reads; one frame, one;
    the views the bytes of a conversion whose set-up was given."""
    import plenocal.convert.video as video_mod
    from plenocal.convert.setup import read_setup
    from plenocal.io.raytrix import read_calib

    a, b, calib = _frames()
    clip = _clip(tmp_path, [a, b], 8)
    xml = tmp_path / "calib.xml"
    write_calib(calib, xml)
    reads = []
    read = video_mod.read_frame
    monkeypatch.setattr(video_mod, "read_frame", lambda *x: reads.append(x[2]) or read(*x))
    video_mod.convert_recording(clip, read_calib(xml), tmp_path / "o", 5, ConvertSettings(),
                                VideoSettings(temporal="off"), frames=frames,
                                out_format="png")
    chosen = parse_frames(frames, 2)
    assert reads == list(chosen)
    video_mod.convert_recording(clip, read_calib(xml), tmp_path / "g", 5, ConvertSettings(),
                                VideoSettings(temporal="off"), frames=frames,
                                out_format="png",
                                setup=read_setup(tmp_path / "o" / "convert_setup.json"))
    assert reads == list(chosen) * 2
    for k in chosen:
        for name in ("2_2", "0_4"):
            assert ((tmp_path / f"o/frame_{k:05d}/{name}.png").read_bytes()
                    == (tmp_path / f"g/frame_{k:05d}/{name}.png").read_bytes())


@needs_real
@pytest.mark.parametrize("temporal", ["off", "hold"])
def test_the_decided_frame_is_not_measured_again(temporal, monkeypatch):
    """The frame the set-up is decided on takes the decision's measurements (one patch-size
    analysis of the first frame, not two): its views are those of a converter given the
    same set-up, which measures the frame itself."""
    import plenocal.convert.shot as shot_mod
    import plenocal.convert.video as video_mod

    a, _, calib = _frames()
    frame = lenslet_frame(rgb_to_yuv(a.astype(np.float32) / 255.0, 10), 10)
    st, vs = ConvertSettings(), VideoSettings(temporal=temporal)
    deciding = VideoConverter(calib, 5, st, vs)
    deciding.decide(frame, "clip[0]")
    given = VideoConverter(calib, 5, st, vs, setup=deciding.setup)
    want = given.convert(frame, "clip[0]")
    calls = []
    for mod in (video_mod, shot_mod):
        monkeypatch.setattr(mod, "estimate_patch_size", lambda *a, **k: calls.append(1))
    got = deciding.convert(frame, "clip[0]")
    assert not calls
    for r, c in ((2, 2), (0, 4)):
        assert np.array_equal(got.view(r, c), want.view(r, c))
    np.testing.assert_array_equal(got.used_patch, want.used_patch)


@needs_real
def test_hold_steadies_patch_sizes_on_static_content():
    """Frames 0 and 150 of Fujita2's top left (books, shelf: static but for coding noise;
    bench/bench_video_flicker.py measures the same on larger crops): fewer static lenses
    change their patch size between the frames with the pairs weighted by their texture
    than without (the flat pairs' chance peaks move with the noise), fewer again with the
    hold, and the set-up (so the view size) is the same for both frames."""
    box = (0, 0, 700, 560)
    a, b, calib = _frames(box)
    frames = [lenslet_frame(rgb_to_yuv(x.astype(np.float32) / 255.0, 10), 10) for x in (a, b)]
    g = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY).astype(np.float32) / 257.0 for f in frames]
    plain = ConvertSettings()
    plain = replace(plain, patch=replace(plain.patch, pair_weights=False))
    changed = {}
    for mode, st in (("off", ConvertSettings()), ("hold", ConvertSettings()),
                     ("off, every pair alike", plain)):
        conv = VideoConverter(calib, 5, st, VideoSettings(temporal=mode.split(",")[0]))
        s0, s1 = (conv.convert(f, str(k)) for k, f in enumerate(frames))
        assert (s0.layout.width, s0.layout.height) == (s1.layout.width, s1.layout.height)
        D = int(round(s0.grid.diameter))
        box_diff = cv2.blur(np.abs(g[0] - g[1]), (D, D))
        c = np.clip(np.rint(s0.grid.centres).astype(int), 0, [box_diff.shape[1] - 1,
                                                              box_diff.shape[0] - 1])
        static = (box_diff[c[:, 1], c[:, 0]] < 4.0)[s0.layout.lens_index]
        assert static.sum() > 200
        dP = np.abs(s1.used_patch - s0.used_patch)[static]
        changed[mode] = float((dP > 0.25).mean())
    # measured: 0.277 every pair alike, 0.062 weighted, 0.026 weighted and held
    assert changed["off, every pair alike"] > 0.1, changed
    assert changed["off"] < 0.5 * changed["off, every pair alike"], changed
    assert 0 < changed["off"]
    assert changed["hold"] < 0.75 * changed["off"], changed


@needs_real
@pytest.mark.parametrize("bits", [8, 10])
def test_held_frames_measure_what_the_frame_alone_measures(bits):
    """With the hold, a later frame's lenses that are not held take the sizes and
    confidences the frame measures alone (``temporal: off``, where the frame's own
    conversion measures it): the same grey image, an 8-bit recording's 8 bits included
    (read as 16 bits it was 257 times too dark, no lens was confident, and every lens that
    moved was filled from its neighbours instead of measured)."""
    a, b, calib = _frames()
    frames = [lenslet_frame(rgb_to_yuv(x.astype(np.float32) / 255.0, bits), bits)
              for x in (a, b)]
    assert frames[0].dtype == (np.uint8 if bits == 8 else np.uint16)
    got = {}
    for mode in ("hold", "off"):
        conv = VideoConverter(calib, 5, ConvertSettings(), VideoSettings(temporal=mode))
        first = conv.convert(frames[0], "clip[0]")
        got[mode] = (first, conv.convert(frames[1], "clip[1]"))
    first, held = got["hold"]
    alone = got["off"][1]
    moved = held.patch.raw != first.patch.raw
    assert 5 <= moved.sum() < len(moved)
    np.testing.assert_array_equal(held.patch.raw[moved], alone.patch.raw[moved])
    np.testing.assert_array_equal(held.patch.confidence[moved], alone.patch.confidence[moved])
    assert alone.patch.confident.mean() > 0.3
    assert not any("no lens matched with confidence" in w for w in held.warnings)


def test_yuv_to_rgb_by_rows_is_the_whole_frame():
    """lenslet_frame turns a frame into RGB in bands of rows (memory on 31-MP frames):
    every band is the same numbers as those rows of the whole frame, for even and odd
    sizes and bands that start on odd rows."""
    from plenocal.io.yuv import yuv_to_rgb

    rng = np.random.default_rng(0)
    for H, W in [(100, 120), (101, 121), (64, 66)]:
        ch, cw = (H + 1) // 2, (W + 1) // 2
        planes = (rng.integers(0, 1024, (H, W)).astype(np.uint16),
                  *(rng.integers(0, 1024, (ch, cw)).astype(np.uint16) for _ in range(2)))
        whole = yuv_to_rgb(planes, 10)
        for a, b in [(0, 10), (10, 32), (32, H), (3, 7), (0, H), (H - 2, H)]:
            assert np.array_equal(yuv_to_rgb(planes, 10, rows=slice(a, b)), whole[a:b]), (
                H, W, a, b)


@pytest.mark.parametrize("bits", [8, 10, 16])
def test_view_to_yuv_is_rgb_to_yuv_of_the_view_bit_for_bit(bits):
    """The views' YUV planes (one compiled pass over the integer view) are rgb_to_yuv's of
    the view over its type's range, bit for bit: 8- and 16-bit views, both matrices and
    ranges, even and odd sizes (an odd last row or column left out of the chroma), values
    at both ends."""
    from plenocal.convert import video
    from plenocal.io.yuv import MATRICES, RANGES, rgb_to_yuv

    rng = np.random.default_rng(bits)
    for dtype in (np.uint8, np.uint16):
        top = np.iinfo(dtype).max
        for H, W in [(40, 30), (41, 31), (2, 3)]:
            view = rng.integers(0, top + 1, (H, W, 3)).astype(dtype)
            view[0, 0] = 0
            view[-1, -1] = top
            for matrix in MATRICES:
                for span in RANGES:
                    want = rgb_to_yuv(np.multiply(view, np.float32(1.0 / top),
                                                  dtype=np.float32), bits, matrix, span)
                    got = video.view_to_yuv(view, bits, matrix, span)
                    for a, b in zip(want, got, strict=True):
                        assert a.dtype == b.dtype and a.shape == b.shape
                        assert np.array_equal(a, b), (dtype, H, W, matrix, span)


@needs_real
def test_a_rerun_replaces_its_views_videos_and_chunks_share_a_folder(tmp_path):
    """One folder, one conversion (plenocal.convert.outfolder): per-view videos of another
    view size (another tile) are replaced by the rerun's, not left beside them; PNG frames
    converted in chunks of frames share a folder, and a chunk of another view set stops
    before its work."""
    import plenocal.convert.video as video_mod  # noqa: PLC0415

    a, b, calib = _frames()
    clip = _clip(tmp_path, [a, b], 8)
    out = tmp_path / "yuv"
    sizes = []
    for tile in (5, 6):
        doc = video_mod.convert_recording(clip, calib, out, 3,
                                          ConvertSettings(mla="galilean", tile_size=tile),
                                          out_format="yuv")
        sizes.append((doc["views"]["width"], doc["views"]["height"]))
        assert sorted(p.name for p in out.glob("*.yuv")) == sorted(
            doc["views"]["files"].values())
    assert sizes[0] != sizes[1]
    out = tmp_path / "png"
    video_mod.convert_recording(clip, calib, out, 3, ConvertSettings(mla="galilean"),
                                frames="0:1")
    first = (out / "convert_setup.json").read_text()
    # the next chunk decides its own set-up on frame 1 (another safe diameter here): two
    # set-ups in one folder, the first no longer recorded, so it is refused and says how
    with pytest.raises(video_mod.ConvertError, match=r"frame_00000 were converted with .*"
                                                     r"convert_setup.json.*pass --setup"):
        video_mod.convert_recording(clip, calib, out, 3, ConvertSettings(mla="galilean"),
                                    frames="1:2")
    assert (out / "convert_setup.json").read_text() == first
    assert sorted(p.name for p in out.glob("frame_*")) == ["frame_00000"]
    video_mod.convert_recording(clip, calib, out, 3, ConvertSettings(mla="galilean"),
                                frames="1:2", setup=read_setup(out / "convert_setup.json"))
    assert sorted(p.name for p in out.glob("frame_*")) == ["frame_00000", "frame_00001"]
    assert (out / "convert_setup.json").read_text() == first
    with pytest.raises(video_mod.ConvertError, match=r"frame_00000 \(3 x 3 views\)"):
        video_mod.convert_recording(clip, calib, out, 5, ConvertSettings(mla="galilean"),
                                    frames="1:2")
