"""Converter on real lenslet frames (issue 12): crops of the MPEG lenslet sequences in
shared/real/frames (Raytrix and TSPC cameras), with their RayCalibData files.

Skipped, with the reason, where the shared folder is absent. Crops keep the tests fast:
the calibration's grid offset is moved with the crop (:func:`crop`)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from plenocal.convert import ConvertSettings, ShotConversion
from plenocal.convert.compare import compare_to_reference, fine_detail, sensor_aspect
from plenocal.convert.errors import ConvertError
from plenocal.convert.patchsize import detect_mla_kind
from plenocal.convert.render import blend_disagreement
from plenocal.grid import MicrolensGrid
from plenocal.io.raytrix import RayCalib, read_calib

_CANDIDATES = [Path("/work/shared/real"), Path(__file__).resolve().parents[2] / "shared/real"]
REAL = next((p for p in _CANDIDATES if (p / "frames").is_dir()), None)
pytestmark = pytest.mark.skipif(REAL is None, reason="shared/real (real lenslet frames) is "
                                "not beside the repository")


def crop(name: str, x0: int, y0: int, w: int, h: int) -> tuple[np.ndarray, RayCalib]:
    """RGB crop [y0:y0+h, x0:x0+w] of a frame and its calibration with the grid moved
    into the crop's coordinates (the origin is given from the image centre, y up)."""
    assert REAL is not None
    img = cv2.imread(str(REAL / "frames" / f"{name}.png"), cv2.IMREAD_UNCHANGED)
    calib = read_calib(REAL / "frames" / f"{name}.xml")
    H, W = img.shape[:2]
    origin = np.array([(W - 1) / 2 + calib.offset[0], (H - 1) / 2 - calib.offset[1]])
    # move the origin into the crop by whole steps of 3 lenses along both lattice axes
    # (a lattice point of the same lens type: the types repeat every 3 lenses)
    A3 = 3 * MicrolensGrid(calib, W, H).A
    target = np.array([x0 + (w - 1) / 2, y0 + (h - 1) / 2])
    k = np.rint(np.linalg.solve(A3, target - origin))
    ox, oy = origin + A3 @ k
    offset = (ox - x0 - (w - 1) / 2, -(oy - y0 - (h - 1) / 2))
    part = np.ascontiguousarray(img[y0:y0 + h, x0:x0 + w, ::-1])
    return part, RayCalib(**{**calib.__dict__, "offset": offset})


def content_shift(a: np.ndarray, b: np.ndarray, box: tuple[int, int, int, int]
                ) -> tuple[float, float]:
    """(dx, dy) of the content of box (x, y, w, h) from view ``a`` to view ``b``: the
    box's inner part (a tenth of its size in from each side) found in ``b`` by
    normalised cross-correlation (shifts of a third of the box are found; phase
    correlation of the windowed box lost a 25 px shift of the kangaroo's head)."""
    x, y, w, h = box
    ga = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY).astype(np.float32)
    gb = cv2.cvtColor(b, cv2.COLOR_RGB2GRAY).astype(np.float32)
    mx, my = max(w // 10, 1), max(h // 10, 1)
    tpl = ga[y + my:y + h - my, x + mx:x + w - mx]
    score = cv2.matchTemplate(gb, tpl, cv2.TM_CCOEFF_NORMED)
    _, best, _, (bx, by) = cv2.minMaxLoc(score)
    assert best > 0.8, f"box {box} not found in the other view (ZNCC {best:.2f})"
    return float(bx - (x + mx)), float(by - (y + my))


# Fujita2, sensor x 250..1330, y 250..830: the books on the left (far), the kangaroo's
# head and shoulders on the right (in front of the books)
FUJITA_CROP = (250, 250, 1080, 580)


@pytest.fixture(scope="module")
def fujita():
    img, calib = crop("Fujita2", *FUJITA_CROP)
    return ShotConversion(img, calib, 5, ConvertSettings(tile_size=8)), img, calib


@pytest.mark.parametrize(("name", "box", "kind"), [
    ("Fujita2", (700, 700, 560, 480), "galilean"),
    ("Origami", (700, 700, 560, 480), "galilean"),
    ("Boxer-IrishMan-Gladiator2", (1500, 700, 700, 560), "galilean"),
    ("R42_klein_crop", (100, 100, 700, 450), "galilean"),
    ("Boys2", (1500, 1100, 900, 700), "keplerian"),
    ("HandTools", (1500, 1100, 900, 700), "keplerian"),
])
def test_mla_kind_is_read_from_the_frame(name, box, kind):
    """Raytrix micro images match only with points moving away from the neighbour,
    TSPC ones only towards it (by a wide margin: a wrong kind is never close)."""
    img, calib = crop(name, *box)
    shot = ShotConversion(img, calib, 3, ConvertSettings(tile_size=4))
    assert shot.mla == kind
    scores = shot.mla_scores
    other = "keplerian" if kind == "galilean" else "galilean"
    assert scores[kind] > 0.7 and scores[kind] - scores[other] > 0.4, scores
    # the two ways matched side by side on two threads: the same numbers
    two = detect_mla_kind(shot.gray, shot.grid, shot.settings.patch, threads=2)
    assert two == (kind, scores["keplerian"], scores["galilean"])


def test_views_upright_and_parallax_direction(fujita):
    """View (r, c): c grows as the viewpoint moves right, r as it moves down. From view
    (2, 0) to (2, 4) the kangaroo, in front of the books, moves LEFT against them; from
    (0, 2) to (4, 2) it moves UP against them. The books' and the kangaroo's boxes in
    the crop's view are where they lie on the sensor (views stand as the frame does)."""
    shot, _, _ = fujita
    L = shot.layout
    scale = L.tile / shot.calib.diameter

    def box(x, y, w, h):  # sensor box of the crop -> view box
        cx, cy = (shot.grid.width - 1) / 2, (shot.grid.height - 1) / 2
        return (int((x - cx) * scale + L.width / 2), int((y - cy) * scale + L.height / 2),
                int(w * scale), int(h * scale))

    books = box(40, 60, 300, 420)  # book spines, sensor x 290..590 of the frame
    kangaroo = box(620, 150, 250, 300)  # its head, sensor x 870..1120 of the frame
    left, right = shot.view(2, 0), shot.view(2, 4)
    up, down = shot.view(0, 2), shot.view(4, 2)
    bx, _ = content_shift(left, right, books)
    kx, _ = content_shift(left, right, kangaroo)
    assert kx - bx < -3.0, (kx, bx)
    _, by = content_shift(up, down, books)
    _, ky = content_shift(up, down, kangaroo)
    assert ky - by < -3.0, (ky, by)
    # the horizontal pair does not move vertically, nor the vertical pair horizontally
    assert abs(content_shift(left, right, kangaroo)[1]) < 1.0
    assert abs(content_shift(up, down, kangaroo)[0]) < 1.0


def test_views_have_the_sensors_square_pixels_and_tlcts_do_not():
    """The views are the sensor image scaled by T / D about its centre: square pixels.
    Against the lenslet frame they were made from, blurred until no micro image is left,
    Fujita2's central and corner views read its aspect to 0.5 % (measured 0.9994 and
    1.0005); TLCT's central view reads 7 % off it (1.074: the measure sees an aspect that
    is not the sensor's; BENCHMARKS.md, "Whose views have square pixels")."""
    from plenocal.convert import convert_files  # noqa: PLC0415

    assert REAL is not None
    frame = cv2.imread(str(REAL / "frames" / "Fujita2.png"))[..., ::-1]
    shot = convert_files(REAL / "frames" / "Fujita2.png", REAL / "frames" / "Fujita2.xml",
                         None, 5, ConvertSettings(), threads=2)
    for r, c in ((2, 2), (0, 0)):
        aspect, cc = sensor_aspect(shot.view(r, c), frame)
        assert cc > 0.95 and abs(aspect - 1.0) < 0.005, (r, c, aspect, cc)
    tlct = cv2.imread(str(REAL / "reference" / "Fujita2" / "centre.png"))[..., ::-1]
    aspect, cc = sensor_aspect(tlct, frame)
    assert cc > 0.95 and aspect > 1.05, (aspect, cc)


def test_mosaic_measure_fails_the_wrong_kind_and_passes_the_right_one(fujita):
    """The blend disagreement (lenses blended into one pixel that see different things)
    is ~1 for the mosaic that the HEAD converter made of Fujita2 (measured on HEAD's
    code: 1.24 central, 0.91 corner view) and for this crop converted as Keplerian;
    clean views stay well below."""
    shot, img, calib = fujita
    wrong = ShotConversion(img, calib, 5, ConvertSettings(tile_size=8, mla="keplerian"))
    for r, c in ((2, 2), (0, 0)):
        assert blend_disagreement(wrong.plan_for(r, c), wrong.source_float, r, c) > 0.6
        assert blend_disagreement(shot.plan_for(r, c), shot.source_float, r, c) < 0.4
    # and the conversion says so: the kind was set by hand, the image reads the other way
    assert any("convert.mla = keplerian, but the image matches as galilean" in w
               for w in wrong.warnings)
    assert not any("convert.mla" in w for w in shot.warnings)


def test_tspc_crop_converts_clean_and_upright():
    """Boys2 (TSPC, D = 70 px): the central view of a crop is clean (no mosaic) and
    the tile follows its patch sizes (~17 px) instead of a fixed 6."""
    img, calib = crop("Boys2", 1400, 900, 1120, 840)
    shot = ShotConversion(img, calib, 5)
    assert shot.mla == "keplerian"
    assert shot.layout.tile >= 20
    assert shot.disparity()["patch_size_px"]["confident_share"] > 0.3
    assert blend_disagreement(shot.plan, shot.source_float, 2, 2) < 0.4


def test_tspc_corner_views_need_the_refined_grid():
    """Boys2's RayCalibData grid drifts from the micro-image centres (8.7 px rms on this
    crop, up to 18 px on the frame). The central view hardly notices: it samples near
    the centre of a flat micro image. The corner views of the paper's q sample 27 px out
    in a 34 px radius, where the micro images fall off steeply and overlap their six
    neighbours, so a centre that is several pixels off puts their samples in a
    different part of the rim in every lens: a lattice. Measured (blend disagreement,
    corners 0_0 4_4 0_4 4_0, the wide blend of views that reach the rim): file grid
    0.49 0.23 0.20 0.48, refined grid (what ``convert_files`` and the workflow use)
    0.18 0.21 0.18 0.24; with the tight blend of the central views they were 0.66 0.36
    0.31 0.68 and 0.29 0.35 0.28 0.42."""
    from plenocal.convert.setup import check_and_grid  # noqa: PLC0415

    img, calib = crop("Boys2", 1400, 900, 1120, 840)
    corners = ((0, 0), (4, 4), (0, 4), (4, 0))
    found = {}
    for mode in ("file", "refine"):
        grid, _ = check_and_grid(img, calib, mode)
        # at the paper's q (the file's D'): the measured D' (0.71 of it) keeps the corner
        # samples nearer the centre, where a drifted centre matters less (issue 33: file
        # grid 0.12-0.18, refined 0.13-0.16)
        shot = ShotConversion(img, calib, 5, ConvertSettings(safe_diameter="file"), grid=grid)
        found[mode] = [blend_disagreement(shot.plan_for(r, c), shot.source_float, r, c)
                       for r, c in corners]
        assert blend_disagreement(shot.plan, shot.source_float, 2, 2) < 0.25, mode
    # 0.3 with the 1.5-2 tile fades of the wide blends; 0.34 with the one-tile fade that
    # has no seams at the tiles' borders; 0.37 with the corner views' 7-lens 1.6-tile
    # blend, which lowers their lattice trace (Boys2 4_4 7.3 -> 5.8 dB) but blends more
    # lenses that disagree (issue 33)
    assert max(found["refine"]) < 0.40, found
    assert max(found["file"]) > 1.5 * max(found["refine"]), found  # the drift's lattice


def test_compare_measures_by_construction():
    """compare_to_reference: a view against itself scaled, shifted and stretched (as
    TLCT's non-square pixels are) gives SSIM ~1 and sharpness ~1; a blurred one loses
    sharpness."""
    img, _ = crop("Fujita2", 200, 200, 1200, 1000)
    small = cv2.resize(img, (600, 500), interpolation=cv2.INTER_AREA)
    ref = cv2.resize(small, (372, 290), interpolation=cv2.INTER_AREA)[6:286, 4:364]
    same = compare_to_reference(small, ref)
    assert same["ssim"] > 0.9 and same["sharpness_ratio"] > 0.85, same
    assert same["scale_xy"][0] == pytest.approx(0.62, abs=0.01)
    blurred = compare_to_reference(cv2.GaussianBlur(small, (0, 0), 3.0), ref)
    assert blurred["sharpness_ratio"] < 0.6, blurred
    g = np.zeros((50, 50), np.float32)
    assert fine_detail(g, g > -1) == 0.0


def test_lens_types_vignette_differently_and_each_gets_its_profile():
    """Boxer's three lens types fall off differently towards the micro-image rim: the
    per-type profiles keep the spread (0.86 / 0.92 / 0.97 of the centre at 70 % of the
    safe radius); with the type labels shuffled over the lenses (no real difference left
    between the labels) the shrinkage brings every row back to the common profile; a
    single-type grid gets one row."""
    from plenocal.convert.vignetting import BIN_PX, lens_type_profiles

    assert REAL is not None
    name = "Boxer-IrishMan-Gladiator2"
    img = cv2.imread(str(REAL / "frames" / f"{name}.png"), cv2.IMREAD_GRAYSCALE)
    calib = read_calib(REAL / "frames" / f"{name}.xml")
    gray = img.astype(np.float32) / 255.0
    grid = MicrolensGrid(calib, img.shape[1], img.shape[0])
    profiles, row = lens_type_profiles(gray, grid)
    at = int(0.7 * calib.safe_diameter / 2 / BIN_PX)
    rims = sorted(profiles[:, at])
    assert profiles.shape[0] == 3 and len(row) == len(grid.types)
    assert rims[-1] - rims[0] > 0.06, rims
    shuffled = grid.types.copy()
    np.random.default_rng(0).shuffle(shuffled)
    grid.types = shuffled
    mixed, _ = lens_type_profiles(gray, grid)
    assert np.ptp(mixed[:, at]) < 0.01, mixed[:, at]
    grid.types = np.zeros_like(shuffled)
    single, row1 = lens_type_profiles(gray, grid)
    assert single.shape[0] == 1 and not row1.any()


@pytest.mark.parametrize(("name", "low", "high"), [
    ("Boys2", 0.65, 0.78),  # TSPC: micro images overlap their neighbours
    ("Fujita2", 0.65, 0.8),  # Raytrix: micro images touch along the lattice directions
    ("R42_klein_crop", 1.0, 1.0),  # its own light across the file's D - 2
])
def test_safe_diameter_is_measured_on_the_frame(name, low, high):
    """Issue 33: D' ends where the neighbours' light arrives (0.71 of the file's D - 2 on
    Boys2, 0.73 on Fujita2); never more than the file's."""
    from plenocal.convert.patchsize import to_gray  # noqa: PLC0415
    from plenocal.convert.safediameter import measure_safe_diameter  # noqa: PLC0415
    from plenocal.convert.setup import check_and_grid  # noqa: PLC0415

    assert REAL is not None
    img = cv2.imread(str(REAL / "frames" / f"{name}.png"), cv2.IMREAD_UNCHANGED)[..., ::-1]
    calib = read_calib(REAL / "frames" / f"{name}.xml")
    grid, _ = check_and_grid(img, calib, "auto")
    safe = measure_safe_diameter(to_gray(np.ascontiguousarray(img)), grid)
    assert low * safe.file_px - 1e-6 <= safe.diameter_px <= high * safe.file_px + 1e-6, safe


@pytest.fixture(scope="module")
def boys2_views():
    """Boys2's central and first corner view as ``plenocal convert`` makes them (defaults),
    and the corner view at the paper's spacing with the earlier wide blend (4 and 5 lenses,
    a 1.5 and 2 tile fade; 1.75 here, the widest the candidates hold; each lens weighed by
    its own trust): what the issue found the lattice in; TLCT's views beside."""
    from plenocal.cli import command_line_block  # noqa: PLC0415
    from plenocal.convert import convert_files  # noqa: PLC0415

    assert REAL is not None
    frame, xml = REAL / "frames" / "Boys2.png", REAL / "frames" / "Boys2.xml"
    now = convert_files(frame, xml, None, 5, ConvertSettings.from_config(
        command_line_block()))
    before = convert_files(frame, xml, None, 5, ConvertSettings.from_config(
        command_line_block({"safe_diameter": "file", "blend": {
            "wide_slots": 4, "wide_fade_radius": 1.5, "wider_slots": 5,
            "wider_fade_radius": 1.75, "trust_passes": 0}})))
    ref = {k: cv2.imread(str(REAL / "reference" / "Boys2" / f"{k}.png"))[..., ::-1]
           for k in ("centre", "v000")}
    return {"centre": (now.view(2, 2), now.layout.basis), "corner": (now.view(0, 0),
            now.layout.basis), "corner_before": (before.view(0, 0), before.layout.basis),
            "ref": ref, "q": (now.layout.q, before.layout.q), "shot": now}


def _row_detail(view: np.ndarray) -> np.ndarray:
    """Each row's band-pass detail (difference of Gaussian blurs of 2 and 6 px) over the
    view's median row: a flat band along an edge reads 0.1-0.2, the scene 0.8-1.1."""
    g = cv2.cvtColor(view, cv2.COLOR_RGB2GRAY).astype(np.float32)
    bp = np.abs(cv2.GaussianBlur(g, (0, 0), 2) - cv2.GaussianBlur(g, (0, 0), 6)).mean(axis=1)
    return bp / np.median(bp)


def test_boys2_cut_border_lenses_are_left_out(boys2_views):
    """Issue 33: Boys2's top lens rows carry a flat, clipped cap over the lower part of
    their micro images (the main lens cuts them). Kept, every view below row 0 shows a
    flat band along its top (38 px in row 4); left out (and as many rows at the bottom),
    the top rows of every view carry the scene."""
    import dataclasses  # noqa: PLC0415

    from plenocal.convert.shot import load_lenslet  # noqa: PLC0415

    now = boys2_views["shot"]
    assert now.border_cut.bands == {"top": 3, "bottom": 0, "left": 0, "right": 0}
    assert now.border_cut.level["top"] > 0.85
    kept = ShotConversion(load_lenslet(REAL / "frames" / "Boys2.png"), now.calib, 5,
                          dataclasses.replace(now.settings, border_cut="off"), grid=now.grid,
                          analysis=now.analysis, safe_diameter=now.safe.diameter_px)
    assert now.layout.height < kept.layout.height and now.layout.width == kept.layout.width
    assert _row_detail(kept.view(4, 4))[2:40].min() < 0.3
    for r, c in ((4, 4), (4, 0), (2, 2), (0, 0)):
        assert _row_detail(now.view(r, c))[2:40].min() > 0.5, (r, c)


def test_an_overexposed_floor_is_not_a_cut_border(tmp_path):
    """HandTools made 2.5x brighter (a third of it clipped): its bottom lens rows saturate
    on one side of most micro images, not all (0.52-0.67 of a band's lenses), and the
    views lost their bottom 112 rows to a cut that is not there. The main lens cuts every
    lens of a band alike (Boys2: 0.97-1.00)."""
    from plenocal.convert import convert_files  # noqa: PLC0415

    assert REAL is not None
    img = cv2.imread(str(REAL / "frames" / "HandTools.png"), cv2.IMREAD_UNCHANGED)
    bright = np.clip(img.astype(np.float32) * 2.5, 0, 255).astype(np.uint8)
    assert (bright == 255).any(axis=2).mean() > 0.3
    frame = tmp_path / "HandTools_x2.5.png"
    cv2.imwrite(str(frame), bright)
    shot = convert_files(frame, REAL / "frames" / "HandTools.xml", None, 5,
                         ConvertSettings(mla="keplerian"))
    assert not shot.border_cut.any, shot.border_cut
    assert shot.layout.height >= 1188


def test_lattice_trace_fails_the_paper_spacing_corner_view_and_passes_the_measured(boys2_views):
    """Issue 33: at the paper's q the TSPC corner views carry the lens lattice (their
    trace above TLCT's); at the q of the measured D' (0.71 of it) not."""
    from plenocal.convert.localcheck import local_compare  # noqa: PLC0415

    v = boys2_views
    assert v["q"][0] == pytest.approx(0.71 * v["q"][1], abs=0.02 * v["q"][1])
    before = local_compare(v["corner_before"][0], v["ref"]["v000"], v["corner_before"][1])
    now = local_compare(v["corner"][0], v["ref"]["v000"], v["corner"][1])
    assert before["lattice_db"] > before["ref_lattice_db"] + 0.5, before
    assert now["lattice_db"] <= now["ref_lattice_db"], now
    # against the measure's floor on the same view: the lattice stands above it at the
    # paper's q, and sinks into it at the measured D' (TLCT's view lies on its floor too)
    assert before["lattice_z"] > 2.0, before
    assert abs(now["lattice_z"]) < 1.0 and abs(now["ref_lattice_z"]) < 1.0, now


def test_central_view_worst_textured_tile_against_tlct(boys2_views):
    """Issue 33's floor: the central view's worst textured tile against TLCT's >= 0.85,
    and its lattice trace at most TLCT's."""
    from plenocal.convert.localcheck import local_compare  # noqa: PLC0415

    view, basis = boys2_views["centre"]
    found = local_compare(view, boys2_views["ref"]["centre"], basis)
    assert found["textured_tiles"] >= 20
    assert found["worst_tile_ssim"] >= 0.85, found
    assert found["lattice_db"] <= found["ref_lattice_db"], found


def test_central_view_fine_detail_at_least_tlcts(boys2_views):
    """Issue 33's detail target on the frame that missed it (0.98 with the frame read as it
    is): Boys2's central view, as plenocal convert makes it (the frame prefiltered), holds
    at least TLCT's fine detail, and more than the same view without the filter."""
    from plenocal.cli import command_line_block  # noqa: PLC0415
    from plenocal.convert import convert_files  # noqa: PLC0415

    ref = boys2_views["ref"]["centre"]
    found = compare_to_reference(boys2_views["centre"][0], ref)
    assert found["sharpness_ratio"] >= 1.0, found
    assert REAL is not None
    plain = convert_files(REAL / "frames" / "Boys2.png", REAL / "frames" / "Boys2.xml", None,
                          5, ConvertSettings.from_config(command_line_block(
                              {"blend": {"prefilter": 0}})))
    without = compare_to_reference(plain.view(2, 2), ref)
    assert without["sharpness_ratio"] < found["sharpness_ratio"] - 0.03, (without, found)


def test_origami_central_view_worst_textured_tile_against_tlct():
    """Issue 33's floor on the frame whose worst tile is an out-of-focus background (the
    top right, beyond the lens types' ranges, where the lenses' sizes are guessed): the
    guessed tiles softened by a quarter tile keep the background's edges as TLCT's view
    has them (0.861; half a tile smeared them into a blurred block, 0.800)."""
    from plenocal.cli import command_line_block  # noqa: PLC0415
    from plenocal.convert import convert_files  # noqa: PLC0415
    from plenocal.convert.localcheck import local_compare  # noqa: PLC0415

    assert REAL is not None
    shot = convert_files(REAL / "frames" / "Origami.png", REAL / "frames" / "Origami.xml",
                         None, 5, ConvertSettings.from_config(command_line_block()))
    ref = cv2.imread(str(REAL / "reference" / "Origami" / "centre.png"))[..., ::-1]
    found = local_compare(shot.view(2, 2), ref, shot.layout.basis)
    assert found["textured_tiles"] >= 20
    assert found["worst_tile_ssim"] >= 0.85, found


def _composition_change(shot, weights: np.ndarray, r: int, c: int) -> tuple[float, float]:
    """How sharply view (r, c)'s blend switches between lenses: for each pair of
    horizontally adjacent pixels, the sum over lenses of the change in each lens's
    normalised weight (a lens that leaves the blend counts its whole weight); the 99th
    percentile over the pixels whose support is under 0.1 (every lens samples near its
    rim), and the largest anywhere. An arc at a lens's rim is such a switch."""
    from plenocal.convert.render import make_plans, view_weights  # noqa: PLC0415
    from plenocal.viewgeom import candidates_within, nearest_slots  # noqa: PLC0415

    blends = shot._blends
    plan = make_plans(shot.layout, shot.used_patch, shot.safe.diameter_px, blends, weights,
                      shot.profile, shot._profile_row)[shot.blend_of(r, c)]
    ids, _ = nearest_slots(shot.layout, keep=max(b.slots for b in blends),
                           k=candidates_within(max(b.fade_radius for b in blends)))
    support = np.empty(plan.map_x.shape[1:], np.float32)
    w = view_weights(plan, r, c, support=support)
    ids = ids[:w.shape[0]]
    a, b = ids[:, :, :-1], ids[:, :, 1:]
    wa, wb = w[:, :, :-1], w[:, :, 1:]
    same = (a[:, None] == b[None, :]) & (a[:, None] >= 0)  # slot i at u is slot j at u + 1
    change = np.abs(wa - (same * wb[None]).sum(axis=1)).sum(axis=0)
    change += (wb * ~same.any(axis=0)).sum(axis=0)  # lenses that join the blend at u + 1
    low = support[:, :-1] < 0.1
    return float(np.percentile(change[low], 99)), float(change.max())


def test_corner_views_blend_does_not_switch_to_one_measured_lens():
    """Issue 33's arcs (HandTools_f150's corner view along the sleeve): a lens whose size
    was measured weighs ten times a filled one, and where every lens samples near its rim
    it took the blend over its whole disc, whose rim showed. The blend takes the trust
    averaged over the lattice: its composition changes from pixel to pixel by at most two
    thirds of what it did with each lens's own trust."""
    from plenocal.convert import convert_files  # noqa: PLC0415
    from plenocal.convert.patchsize import reliability  # noqa: PLC0415

    assert REAL is not None
    shot = convert_files(REAL / "frames" / "HandTools_f150.png",
                         REAL / "frames" / "HandTools.xml", None, 5)
    r, c = 4, 4
    assert shot.blend_of(r, c) == 2  # the wider blend
    p = shot.patch
    own = (p.focus * reliability(p.raw, p.patch, p.confident, shot.settings.patch.step_px)
           )[shot.layout.lens_index]
    before = _composition_change(shot, own, r, c)
    now = _composition_change(shot, shot._lens_weight, r, c)
    assert now[0] < 0.67 * before[0], (before, now)
    assert now[1] < 0.67 * before[1], (before, now)


def _one_lens_share(shot: ShotConversion, r: int, c: int) -> float:
    """Share of view (r, c)'s pixels that take more than 0.9 of their weight from one lens."""
    from plenocal.convert.render import view_weights  # noqa: PLC0415

    return float(np.mean(view_weights(shot.plan_for(r, c), r, c).max(axis=0) > 0.9))


def test_far_content_on_a_multi_focus_mla_takes_the_wider_blend():
    """R42_klein_crop (Raytrix R42) sees its scene at virtual depth 5.5, in one lens
    type's range only: the other two types weigh the focus floor, and at the blends of
    their reach half the corner view's pixels (0.49) and a quarter of the central view's
    (0.23) took more than 0.9 of their weight from one lens, each sharp lens painting a
    region about sqrt 3 tiles wide: specks and hexagon fragments along the rod and on the
    fabric (issue 33). Every view now takes the wider blend (render.focus_reach), and the
    shares fall to the other Raytrix frames' (0.14-0.19 in their corner views). Fujita2,
    whose scene two types see sharp, keeps each view's own blend."""
    from plenocal.convert import convert_files  # noqa: PLC0415

    assert REAL is not None
    shot = convert_files(REAL / "frames" / "R42_klein_crop.png",
                         REAL / "frames" / "R42_klein_crop.xml", None, 5,
                         ConvertSettings(mla="galilean"))
    assert shot.least_reach == 2
    assert all(shot.blend_of(r, c) == 2 for r in range(5) for c in range(5))
    now = _one_lens_share(shot, 0, 0), _one_lens_share(shot, 2, 2)
    shot._least_reach = 0  # the blends of the views' own reach, as before
    before = _one_lens_share(shot, 0, 0), _one_lens_share(shot, 2, 2)
    assert before[0] > 0.4 and before[1] > 0.15, before
    assert now[0] < 0.2 and now[1] < 0.05, now
    img, calib = crop("Fujita2", *FUJITA_CROP)
    fujita = ShotConversion(img, calib, 5, ConvertSettings(mla="galilean"))
    assert fujita.least_reach == 0 and fujita.blend_of(2, 2) == 0
    # decided once per camera, as D' and q are: the set-up carries it to every shot
    fujita = ShotConversion(img, calib, 5, ConvertSettings(mla="galilean"), least_reach=2)
    assert fujita.blend_of(2, 2) == 2


def test_the_camera_setup_decides_the_least_reach_once():
    """Rule convert_setup decides the least blend reach on its shot and writes it in
    convert_setup.json (version 4); a shot converted with the set-up takes it whatever its
    own lenses' focus says (a hand-held shot nearer the scene sees it in other types'
    ranges: the simulator's Raytrix-like shots read mean focus weights 0.67-0.88)."""
    from plenocal.convert.setup import ConverterSetup, decide_setup  # noqa: PLC0415
    from plenocal.convert.shot import load_lenslet  # noqa: PLC0415

    assert REAL is not None
    img = load_lenslet(REAL / "frames" / "R42_klein_crop.png")
    calib = read_calib(REAL / "frames" / "R42_klein_crop.xml")
    setup, shot = decide_setup(img, calib, 5, ConvertSettings(mla="galilean"), source="x")
    assert setup.least_reach == shot.least_reach == 2
    again = ConverterSetup.from_dict(setup.to_dict())
    assert again == setup and again.to_dict()["least_reach"] == 2
    doc = {**setup.to_dict(), "version": 4}
    with pytest.raises(ConvertError, match="version 5"):
        ConverterSetup.from_dict(doc)


def test_r42_lattice_is_centred_by_its_corner_views():
    """R42_klein_crop: the grid check cannot confirm its calib.xml grid (14 % of the lit
    lenses measured), and the file's grid was kept. Its corner view 0_0 showed a row of
    crescents under the rod that 4_4 did not: the views sampled one side of every micro
    image nearer its rim. The four corner views' blend disagreement is a quarter lower
    with the file's lattice moved by about (+3.25, +2.25) px (plenocal.convert.centring),
    and the views use that lattice; the camera's set-up carries it, so every shot
    converted with the set-up takes the same grid (issue 33)."""
    from plenocal.convert import convert_files  # noqa: PLC0415
    from plenocal.convert.setup import decide_setup  # noqa: PLC0415
    from plenocal.convert.shot import load_lenslet  # noqa: PLC0415

    assert REAL is not None
    png, xml = REAL / "frames" / "R42_klein_crop.png", REAL / "frames" / "R42_klein_crop.xml"
    settings = ConvertSettings(mla="galilean")
    shot = convert_files(png, xml, None, 5, settings)
    fit = shot.grid_check["centring"]
    assert fit["applied"] and not shot.grid_check["verified"], fit
    dx, dy = fit["offset_px"]
    assert 2.5 <= dx <= 4.0 and 1.5 <= dy <= 3.0, fit
    assert fit["disagreement_fit"] <= 0.85 * fit["disagreement_file"], fit
    file_grid = MicrolensGrid(read_calib(xml), shot.grid.width, shot.grid.height)
    assert np.allclose(shot.grid.origin - file_grid.origin, (dx, dy), atol=1e-4)
    img = load_lenslet(png)
    setup, _ = decide_setup(img, read_calib(xml), 5, settings, source="x")
    assert setup.refined and setup.grid_check["centring"]["applied"]
    again = setup.grid(read_calib(xml), img.shape[1], img.shape[0])
    assert np.allclose(again.origin, shot.grid.origin, atol=1e-4)
