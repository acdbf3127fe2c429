"""Border micro images cut by the main lens (issue 33: Boys2's flat band): measured on a
synthetic frame with a painted cut, left out of the views, decided once per camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture
from test_convert import small_optics

from plenocal.config import ConfigError, validate_config
from plenocal.convert import ConvertError, ConvertSettings, ShotConversion
from plenocal.convert.bordercut import BorderCut, band_spacing, measure_border_cut
from plenocal.convert.setup import ConverterSetup, decide_setup
from plenocal.convert.shot import frame_gray
from plenocal.grid import SENSOR_BORDERS as BORDERS
from plenocal.grid import MicrolensGrid
from plenocal.viewgeom import make_layout

ROOT = Path(__file__).resolve().parents[1]
W, H = 480, 360
CAP = (235, 250, 250)  # a flat-fielded cut: clipped, light cyan (Boys2's)
EDGES = (-2.0, 2.0, 5.0)  # the cut's edge below each cut band's micro-image centre (px)


def frame(seed: int = 4):
    calib = calib_for_optics(small_optics(W, H))
    grid = MicrolensGrid(calib, W, H)
    return calib, grid, lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, seed))


def paint(img: np.ndarray, grid: MicrolensGrid, value, edges=EDGES, whole: bool = False,
          border: str = "top") -> np.ndarray:
    """``img`` with the part of each micro image of ``border``'s first bands beyond
    ``edges[k]`` from its centre towards the sensor's middle (all of it where ``whole``)
    set to ``value``: band ``k`` counted from the border as the measure counts it."""
    out = img.copy()
    dist = grid.border_distance(border)
    inside = grid.inside(0.0)
    s = band_spacing(grid, border)
    first = dist[inside].min()
    yy, xx = np.mgrid[0:H, 0:W]
    for i in np.flatnonzero(inside):
        k = int(np.floor((dist[i] - first) / s + 0.5))
        if k >= len(edges):
            continue
        mx, my = grid.centres[i]
        disc = (xx - mx) ** 2 + (yy - my) ** 2 <= (grid.diameter / 2) ** 2
        inward = {"top": yy - my, "bottom": my - yy, "left": xx - mx, "right": mx - xx}[border]
        part = disc if whole else disc & (inward > edges[k])
        out[part] = value
    return out


def cut_of(img: np.ndarray, grid: MicrolensGrid, calib) -> BorderCut:
    return measure_border_cut(frame_gray(img, 8), grid, calib.safe_diameter)


def test_a_painted_cut_is_found_band_by_band():
    calib, grid, img = frame()
    assert not cut_of(img, grid, calib).any
    cut = cut_of(paint(img, grid, CAP), grid, calib)
    assert cut.bands == {"top": 3, "bottom": 0, "left": 0, "right": 0}, cut
    assert cut.level["top"] == pytest.approx(np.mean(CAP) / 255, abs=0.02)
    d = grid.border_distance("top")
    s = band_spacing(grid, "top")
    first = d[grid.inside(0.0)].min()
    assert cut.insets_px["top"] == pytest.approx(first + 2.5 * s)
    # unlit (a frame that is not flat-fielded) is a cut too
    assert cut_of(paint(img, grid, (0, 0, 0)), grid, calib).bands["top"] == 3


@pytest.mark.parametrize("border", ["bottom", "left", "right"])
def test_a_cut_is_found_on_any_border(border):
    calib, grid, img = frame()
    cut = cut_of(paint(img, grid, CAP, border=border), grid, calib)
    assert cut.bands == {b: 3 if b == border else 0 for b in BORDERS}, cut
    axis = 0 if border in ("left", "right") else 1
    shot = ShotConversion(paint(img, grid, CAP, border=border), calib, 5,
                          ConvertSettings(tile_size=6, even_size=False))
    full = ShotConversion(img, calib, 5, ConvertSettings(tile_size=6, even_size=False))
    assert (shot.layout.width, shot.layout.height)[axis] < (full.layout.width,
                                                            full.layout.height)[axis]
    assert (shot.layout.width, shot.layout.height)[1 - axis] == (full.layout.width,
                                                                 full.layout.height)[1 - axis]


def test_a_cut_beside_a_black_scene_is_found():
    """A figure on black (a TSPC test sequence): the outermost lens rows see only the
    black backdrop, flat on both halves of their micro images; the clipped cap over one
    half is a cut all the same."""
    calib, grid, img = frame()
    black = paint(img, grid, (3, 3, 3), whole=True)
    assert not cut_of(black, grid, calib).any
    cut = cut_of(paint(black, grid, CAP), grid, calib)
    assert cut.bands["top"] == 3, cut


@pytest.mark.parametrize(("value", "whole", "why"), [
    ((5, 5, 5), True, "a flat dark scene along the border fills both halves"),
    ((250, 250, 250), True, "an overexposed sky fills both halves"),
    ((128, 128, 128), False, "a one-sided flat part at a middle grey is the scene's"),
])
def test_flat_scenes_along_a_border_are_not_a_cut(value, whole, why):
    calib, grid, img = frame()
    assert not cut_of(paint(img, grid, value, whole=whole), grid, calib).any, why


def _in_some_lenses(painted: np.ndarray, img: np.ndarray, grid: MicrolensGrid,
                    share: float, seed: int = 1) -> np.ndarray:
    """``painted`` in a random ``share`` of the lenses, ``img`` in the others."""
    out = img.copy()
    yy, xx = np.mgrid[0:H, 0:W]
    keep = np.random.default_rng(seed).random(len(grid.centres)) < share
    for (mx, my), k in zip(grid.centres, keep, strict=True):
        if k:
            disc = (xx - mx) ** 2 + (yy - my) ** 2 <= (grid.diameter / 2 + 1) ** 2
            out[disc] = painted[disc]
    return out


def test_a_part_clipped_in_most_lenses_but_not_all_is_the_scene():
    """An overexposed floor along a border (HandTools made 2.5x brighter) saturates the
    same side of most of a band's micro images, not all (0.52-0.67 of them): their median
    reads clipped and flat, one-sided, yet the main lens would have cut every one."""
    calib, grid, img = frame()
    for share, want in ((0.8, 0), (1.0, 3)):
        cut = cut_of(_in_some_lenses(paint(img, grid, CAP), img, grid, share), grid, calib)
        assert cut.bands["top"] == want, (share, cut)


def test_a_cut_stays_on_the_side_its_first_band_has_it():
    """The main lens cuts one side of a border's micro images, band after band: a band
    flat on the other half (a scene's clipped edge) ends the cut."""
    calib, grid, img = frame()
    # bands 0 and 1 cut on their inward half as Boys2's, band 2 flat on its outward half
    dist = grid.border_distance("top")
    first, s = dist[grid.inside(0.0)].min(), band_spacing(grid, "top")
    yy, xx = np.mgrid[0:H, 0:W]
    out = paint(img, grid, CAP, edges=(-2.0, 2.0))
    for i in np.flatnonzero(grid.inside(0.0)):
        if int(np.floor((dist[i] - first) / s + 0.5)) == 2:
            mx, my = grid.centres[i]
            disc = (xx - mx) ** 2 + (yy - my) ** 2 <= (grid.diameter / 2) ** 2
            out[disc & (yy - my < 2.0)] = CAP
    assert cut_of(paint(img, grid, CAP), grid, calib).bands["top"] == 3
    cut = cut_of(out, grid, calib)
    assert cut.bands["top"] == 2, cut
    assert cut.excess["top"][2] < 0, cut  # one-sided, on the other half


def test_views_leave_the_cut_lenses_out_symmetrically_and_show_no_cap():
    calib, grid, img = frame()
    img = paint(img, grid, CAP)
    st = ConvertSettings(tile_size=6, even_size=False)
    off = ShotConversion(img, calib, 5, ConvertSettings(tile_size=6, even_size=False,
                                                        border_cut="off"))
    on = ShotConversion(img, calib, 5, st)
    assert on.border_cut.bands["top"] == 3 and not off.border_cut.any
    assert on.layout.width == off.layout.width
    assert on.layout.height < off.layout.height
    # the views stay centred on the axis: the used lenses' tile centres span the view
    # symmetrically (both borders lose rows)
    for L in (on.layout, off.layout):
        y = L.tile_centres[:, 1]
        assert y.min() <= 0.5 and y.max() >= L.height - 1.5

    def cap_share(view: np.ndarray) -> float:
        return float((np.abs(view.astype(int) - CAP).max(axis=-1) <= 3).mean())

    # the lower views sample the cut (below the micro images' centres) without it
    assert cap_share(off.view(4, 4)) > 0.01
    for r, c in ((4, 4), (4, 0), (2, 2), (0, 0)):
        assert cap_share(on.view(r, c)) == 0.0, (r, c)


def test_the_camera_setup_decides_the_cut_once():
    """Decided on the shot the set-up is made on (the central array shot), and applied
    to a shot that shows no cut (a hand-held shot of a flat wall): one view size."""
    calib, grid, img = frame()
    st = ConvertSettings(tile_size=6, even_size=False)
    setup, shot = decide_setup(paint(img, grid, CAP), calib, 5, st, "centre.png")
    assert setup.border_cut.bands["top"] == 3
    assert any("top 3 lens rows" in w and "views" in w for w in setup.warnings)
    again = ConverterSetup.from_dict(setup.to_dict())
    assert again.border_cut == setup.border_cut
    other = frame(seed=7)[2]
    plain = ShotConversion(other, calib, 5, again.settings(st), grid=again.grid(calib, W, H),
                           border_cut=again.border_cut,
                           safe_diameter=again.safe_diameter_px)
    assert (plain.layout.width, plain.layout.height) == (shot.layout.width,
                                                         shot.layout.height)
    assert ShotConversion(other, calib, 5, st).layout.height > plain.layout.height
    assert plain.disparity()["border_cut"]["bands"]["top"] == 3


def test_layout_insets_and_settings():
    calib, grid, _ = frame()
    full = make_layout(grid, 5, 6)
    d = grid.border_distance("left")
    inset = float(np.sort(np.unique(np.round(d[grid.inside(0.0)])))[2]) - 0.5
    cut = make_layout(grid, 5, 6, insets_px={"left": inset})
    assert cut.height == full.height and cut.width < full.width
    assert (grid.border_distance("left")[cut.lens_index] >= inset).all()
    assert set(BORDERS) == {"top", "bottom", "left", "right"}
    with pytest.raises(ValueError, match="border must be one of"):
        grid.border_distance("up")
    with pytest.raises(ConvertError, match="convert.border_cut"):
        ConvertSettings(border_cut="maybe")
    # YAML reads a bare off as false
    assert ConvertSettings.from_config({"border_cut": False}).border_cut == "off"
    cfg = yaml.safe_load((ROOT / "config.yaml").read_text())
    cfg["convert"] = {**(cfg.get("convert") or {}), **yaml.safe_load("border_cut: off")}
    assert validate_config(cfg)["convert"]["border_cut"] is False
    cfg["convert"]["border_cut"] = "sometimes"
    with pytest.raises(ConfigError, match="border_cut"):
        validate_config(cfg)


def test_a_recording_decides_the_cut_once(tmp_path):
    """A clip whose first frame shows the cut: the set-up holds it, every frame's views
    leave the cut lenses out (one size), and the log says so."""
    import json  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415

    from plenocal.io.raytrix import write_calib  # noqa: PLC0415
    from plenocal.io.yuv import YuvFormat, rgb_to_yuv, write_frame  # noqa: PLC0415

    calib, grid, a = frame()
    b = frame(seed=7)[2]
    clip = tmp_path / f"clip_{W}x{H}_8bit.yuv"
    with open(clip, "wb") as fh:
        for img in (paint(a, grid, CAP), paint(b, grid, CAP)):
            write_frame(fh, rgb_to_yuv(img.astype(np.float32) / 255.0, 8), YuvFormat(W, H, 8))
    xml = tmp_path / "calib.xml"
    write_calib(calib, xml)
    out = tmp_path / "video"
    r = subprocess.run([sys.executable, "-m", "plenocal.cli", "convert", str(clip), str(xml),
                        "-o", str(out), "--format", "yuv", "--tile-size", "6"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "top 3 lens rows" in r.stderr
    setup = json.loads((out / "convert_setup.json").read_text())
    assert setup["border_cut"]["bands"]["top"] == 3
    plain = ShotConversion(a, calib, 5, ConvertSettings(tile_size=6, even_size=True,
                                                        border_cut="off"))
    views = json.loads((out / "video.json").read_text())["views"]
    assert views["height"] < plain.layout.height and views["width"] == plain.layout.width
