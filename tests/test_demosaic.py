"""Raw Bayer lenslet frames (plenocal.convert.demosaic): Malvar-He-Cutler's Eqs. M1-M4
checked on hand-computable frames, the mosaic detector on grey and mosaicked frames, and
``convert.bayer`` through the converter and the command line."""

from __future__ import annotations

import logging
import subprocess
import sys

import numpy as np
import pytest
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture

from plenocal.config import ConfigError, validate_config
from plenocal.convert import ConvertError, ConvertSettings, convert_files
from plenocal.convert.demosaic import (
    BAYER_PATTERNS,
    MOSAIC_LIKENESS,
    colour_sites,
    demosaic,
    mosaic,
    mosaic_likeness,
    mosaic_warning,
)
from plenocal.convert.shot import load_lenslet
from plenocal.grid import MicrolensGrid
from plenocal.io.files import write_image
from plenocal.io.raytrix import write_calib
from plenocal.optics import PlenopticOptics


def small_optics() -> PlenopticOptics:
    """The default simulated camera (config.yaml) on a 400 x 300 sensor."""
    return PlenopticOptics(focal_length=0.035, focus_distance=0.6, mla_pitch=130e-6,
                           mla_f_number=2.8, k=5.0, pixel_size=5.5e-6, width=400, height=300)


def affine_frame(h: int = 40, w: int = 52) -> np.ndarray:
    """uint16 RGB whose channels are each affine in (x, y), on even values so that the
    interpolations' eighths are whole: Eqs. M1-M4 must give them back exactly."""
    y, x = np.mgrid[0:h, 0:w].astype(np.int64)
    channels = (1000 + 24 * x + 40 * y, 30000 - 16 * x + 8 * y, 5000 + 64 * y)
    return np.stack(channels, axis=2).astype(np.uint16)


def test_the_mosaic_keeps_each_pixels_filtered_colour():
    rgb = np.arange(4 * 6 * 3, dtype=np.uint16).reshape(4, 6, 3)
    m = mosaic(rgb, "GRBG")  # G R / B G
    assert m[0, 0] == rgb[0, 0, 1] and m[0, 1] == rgb[0, 1, 0]
    assert m[1, 0] == rgb[1, 0, 2] and m[3, 5] == rgb[3, 5, 1] and m.dtype == np.uint16
    with pytest.raises(ValueError, match="RGB frame"):
        mosaic(rgb[:, :, 0], "GRBG")


def test_colour_sites_by_pattern():
    assert colour_sites("RGGB") == {"R": (0, 0), "B": (1, 1)}
    assert colour_sites("grbg") == {"R": (0, 1), "B": (1, 0)}
    assert colour_sites("GBRG") == {"R": (1, 0), "B": (0, 1)}
    assert colour_sites("BGGR") == {"R": (1, 1), "B": (0, 0)}
    with pytest.raises(ValueError, match="RGBG"):
        colour_sites("RGBG")


@pytest.mark.parametrize("pattern", BAYER_PATTERNS)
def test_an_affine_frame_comes_back_exactly(pattern):
    """The kernels sum to one and their Laplacian terms cancel on an affine image, so
    every channel comes back to the bit away from the border (where the reflected
    frame is not affine); the known samples are kept as they are everywhere."""
    rgb = affine_frame()
    out = demosaic(mosaic(rgb, pattern), pattern)
    assert out.dtype == np.uint16 and out.shape == rgb.shape
    assert np.array_equal(out[2:-2, 2:-2], rgb[2:-2, 2:-2])
    assert np.array_equal(mosaic(out, pattern), mosaic(rgb, pattern))


def test_the_wrong_pattern_does_not_come_back():
    rgb = affine_frame()
    out = demosaic(mosaic(rgb, "RGGB"), "BGGR")
    assert not np.array_equal(out[2:-2, 2:-2], rgb[2:-2, 2:-2])


def test_one_hand_computed_sample():
    """Green at a red site (Eq. M1) on a 5 x 5 RGGB mosaic: (4 R + 2 (four greens) - (four
    reds two away)) / 8 at the centre, which is a red site."""
    m = np.zeros((5, 5), np.uint8)
    m[2, 2] = 100  # the centre, red
    m[1, 2] = m[3, 2] = m[2, 1] = m[2, 3] = 40  # its four greens
    m[0, 2] = m[4, 2] = m[2, 0] = m[2, 4] = 20  # the reds two away
    out = demosaic(m, "RGGB")
    assert out[2, 2, 1] == round((4 * 100 + 2 * 4 * 40 - 4 * 20) / 8)  # 80
    assert out[2, 2, 0] == 100


def test_bands_give_the_whole_frames_values_and_stay_within_the_mosaics_range():
    rng = np.random.default_rng(3)
    m = rng.integers(0, 4096, (37, 30)).astype(np.uint16)  # 12 bits in 16, odd height
    whole = demosaic(m, "GBRG", band_rows=10_000)
    for rows in (2, 6, 7, 16):
        assert np.array_equal(demosaic(m, "GBRG", band_rows=rows), whole)
    assert whole.max() <= m.max() and whole.min() >= 0
    with pytest.raises(ValueError, match="one channel"):
        demosaic(np.zeros((4, 4, 3), np.uint8), "RGGB")


def test_the_detector_tells_a_mosaic_from_a_grey_frame():
    rgb = (random_texture(256, 1.5, 7) * 255).astype(np.uint8)
    grey = rgb.mean(axis=2).astype(np.uint8)
    assert mosaic_likeness(grey) > 1.0 and mosaic_warning(grey) is None
    noise = np.random.default_rng(1).integers(0, 256, (256, 256)).astype(np.uint8)
    assert mosaic_likeness(noise) == pytest.approx(1.0, abs=0.05)
    assert mosaic_warning(noise) is None
    for pattern in BAYER_PATTERNS:
        assert mosaic_likeness(mosaic(rgb, pattern)) < MOSAIC_LIKENESS
        assert "--bayer PATTERN" in mosaic_warning(mosaic(rgb, pattern))
    assert mosaic_warning(rgb) is None  # three channels: not a mosaic
    assert mosaic_likeness(np.full((8, 8), 9, np.uint8)) == float("inf")


@pytest.fixture
def bayer_shot(tmp_path):
    """A coloured lenslet frame (RGB), its RGGB mosaic and the calib.xml."""
    calib = calib_for_optics(small_optics())
    rgb = lenslet_from_patch_size(MicrolensGrid(calib, 400, 300), 5.0,
                                  random_texture(256, 1.5, 5))
    rgb = (rgb * np.array([0.55, 1.0, 0.7])).astype(np.uint8)  # a raw sensor's channel gains
    write_image(tmp_path / "rgb.png", rgb)
    write_image(tmp_path / "raw.png", mosaic(rgb, "RGGB"))
    write_calib(calib, tmp_path / "calib.xml")
    return tmp_path


def test_load_lenslet_demosaics_and_refuses(bayer_shot):
    assert load_lenslet(bayer_shot / "raw.png").ndim == 2
    rgb = load_lenslet(bayer_shot / "raw.png", bayer="RGGB")
    assert rgb.shape == (300, 400, 3)
    assert np.array_equal(rgb, load_lenslet(bayer_shot / "raw.png", None, "RGGB"))
    with pytest.raises(ConvertError, match=r"rgb.png: convert.bayer is RGGB, but the frame "
                                            r"has 3 channels.*convert.bayer: none"):
        load_lenslet(bayer_shot / "rgb.png", bayer="RGGB")


def test_a_mosaic_converted_with_its_pattern_gives_the_colour_frames_views(bayer_shot,
                                                                          caplog):
    """convert.bayer through convert_files: the views of the demosaiced mosaic are those of
    the colour frame within the demosaicing's error; the grey mosaic's are not."""
    settings = ConvertSettings.from_config({"tile_size": 5, "patch_size": {"step_px": 0.25}})
    ref = convert_files(bayer_shot / "rgb.png", bayer_shot / "calib.xml", None, 3, settings)
    raw = convert_files(bayer_shot / "raw.png", bayer_shot / "calib.xml", None, 3,
                        ConvertSettings.from_config({"tile_size": 5, "bayer": "RGGB",
                                                     "patch_size": {"step_px": 0.25}}))
    assert abs(np.median(raw.used_patch) - 5.0) < 0.05
    assert not any("Bayer" in w for w in raw.warnings + ref.warnings)
    a, b = ref.view(1, 1).astype(np.float64), raw.view(1, 1).astype(np.float64)
    assert 10 * np.log10(255.0 ** 2 / np.mean((a - b) ** 2)) > 30.0
    with caplog.at_level(logging.WARNING, logger="plenocal.convert"):
        grey = convert_files(bayer_shot / "raw.png", bayer_shot / "calib.xml", None, 3,
                             settings)
    # the warning is logged and kept with the shot's (convert_setup.json, the report)
    assert "looks like a raw Bayer mosaic" in caplog.text
    assert [w for w in grey.warnings if "looks like a raw Bayer mosaic" in w]
    g = grey.view(1, 1).astype(np.float64)
    assert g.shape != a.shape or 10 * np.log10(255.0 ** 2 / np.mean((a - g) ** 2)) < 25.0


def test_the_schema_and_the_command_line_take_only_the_four_patterns(bayer_shot, tmp_path):
    with pytest.raises(ConfigError, match="bayer"):
        validate_config({"datasets": {"d": {}}, "convert": {"bayer": "RGBG"}})
    assert ConvertSettings.from_config({"bayer": "BGGR"}).bayer == "BGGR"
    with pytest.raises(ConvertError, match="convert.bayer"):
        ConvertSettings(bayer="rggb")
    clip = tmp_path / "clip_400x300_8bit.yuv"
    clip.write_bytes(bytes(400 * 300 * 3 // 2))
    r = subprocess.run([sys.executable, "-m", "plenocal.cli", "convert", str(clip),
                        str(bayer_shot / "calib.xml"), "-o", str(tmp_path / "o"),
                        "--bayer", "RGGB"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "convert.bayer RGGB: for a raw one-channel PNG frame" in r.stderr
    assert "YUV recording, in colour already" in r.stderr and not (tmp_path / "o").exists()
