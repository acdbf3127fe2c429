"""Surface pixels of a synthesis target (issue 32, item 4): the dB lost to calibration
without the renderer's per-pixel choices at occlusion edges."""

import numpy as np
import pytest
from synth.planes import camera_at, fronto_plane, photo_texture, render_plane

from plenocal.artifacts.results import (
    SynthesisResult,
    SynthesisSetup,
    read_synthesis,
    write_synthesis,
)
from plenocal.camera import PinholeCamera
from plenocal.io.files import to_uint8, write_image
from plenocal.verify.experiments import layout_from_cams
from plenocal.verify.surface import masked_error, psnr_of_error, surface_mask
from plenocal.verify.synthesis import psnr_tables, run_experiment, surface_masks
from plenocal.viewgeom import view_names

W, H, F, N = 200, 150, 300.0, 3
COLS, ROWS, STEP, B = 3, 2, 0.01, 0.002


def scene(cam: PinholeCamera, far, near) -> tuple[np.ndarray, np.ndarray]:
    """A textured plane at 0.7 m and a nearer textured square at 0.5 m in front of it."""
    img_f, z_f = render_plane(cam, far)
    img_n, z_n = render_plane(cam, near)
    front = z_n > 0
    return np.where(front[..., None], img_n, img_f), np.where(front, z_n, z_f)


@pytest.fixture(scope="module")
def planes():
    tex = photo_texture(256, noise=0.005)
    return fronto_plane(0.7, 1.2, tex), fronto_plane(0.5, 0.06, tex[::-1, ::-1].copy())


def test_surface_mask_leaves_out_edges_and_what_no_input_sees(planes):
    tgt = camera_at([0.0, 0.0, 0.0], F, W, H)
    src = camera_at([0.02, 0.0, 0.0], F, W, H)
    views = {"t/0": tgt, "s/0": src}
    depth = {k: scene(c, *planes)[1] for k, c in views.items()}
    mask = surface_mask("t/0", ["s/0"], views, depth.__getitem__, border=4)
    zt = depth["t/0"]
    near = np.flatnonzero((zt < 0.6).any(axis=0))  # the square's columns in the target
    x0, x1 = near.min(), near.max()
    mid = H // 2
    # the square and the plane far from it: surface
    assert mask[mid, (x0 + x1) // 2] and mask[mid, 20] and mask[mid, W - 20]
    # its edges: not (2 px either side, the 5 x 5 window)
    assert not mask[mid, x0 - 2: x0 + 2].any() and not mask[mid, x1 - 1: x1 + 3].any()
    # the plane left of the square, hidden from the input on the right (disparity
    # 300 * 0.02 * (1 / 0.5 - 1 / 0.7) = 3.4 px): not; beyond, and right of it: surface
    assert not mask[mid, x0 - 5: x0 - 2].any()
    assert mask[mid, x0 - 6] and mask[mid, x1 + 3]
    assert not mask[:4].any() and not mask[:, -4:].any()
    assert 0.8 < mask.mean() < 0.98


def test_masked_error_and_psnr():
    a = np.zeros((4, 5, 3), np.float32)
    b = a.copy()
    b[1, 2] = 0.1
    m = np.zeros((4, 5), bool)
    m[1, 1:3] = True
    sse, n = masked_error(a, b, m)
    assert n == 6 and sse == pytest.approx(3 * 0.01)
    assert psnr_of_error(sse, n) == pytest.approx(10 * np.log10(1 / (0.03 / 6)))
    assert psnr_of_error(0.0, 0) is None


@pytest.fixture(scope="module")
def array(tmp_path_factory, planes):
    """A 3 x 2 array of 3 x 3 sets of the two-plane scene, exactly aligned cameras (as the
    ground truth's): the images, the cameras and the true depth."""
    root = tmp_path_factory.mktemp("surface")
    cams, depth = {}, {}
    for r in range(ROWS):
        for c in range(COLS):
            for v in view_names(N):
                vr, vc = map(int, v.split("_"))
                key = f"x{c:02d}_y{r:02d}/{v}"
                cam = camera_at([c * STEP + (vc - 1) * B - STEP, r * STEP + (vr - 1) * B, 0.0],
                                F, W, H)
                img, z = scene(cam, *planes)
                (root / key.split("/")[0]).mkdir(exist_ok=True)
                write_image(root / f"{key}.png", to_uint8(img))
                cams[key], depth[key] = cam, z
    return root, cams, depth


def test_surface_psnr_in_the_tables_and_the_file(array, tmp_path):
    """Exps. 1 and 2 score their targets over the surface pixels too, with the masks of the
    true cameras and depth: the exact cameras lose nothing there to a 1e-4 px jitter
    (where the whole-view PSNR may move), a camera off by 1 mm loses dB there, and the
    figures reach the result file."""
    root, cams, depth = array
    layout = layout_from_cams(sorted({k.split("/")[0] for k in cams}), N)
    cfg = {"psnr_border_px": 6}
    jittered = {}
    for i, (k, c) in enumerate(sorted(cams.items())):
        K = c.K.copy()
        K[:2, 2] += 1e-4 * np.array([(-1) ** i, (-1) ** (i // 2)])
        jittered[k] = PinholeCamera(K, c.cam_to_world, W, H)
    bad = dict(cams)
    M = cams["x01_y00/1_1"].cam_to_world.copy()
    M[0, 3] += 0.001
    bad["x01_y00/1_1"] = PinholeCamera(cams["x01_y00/1_1"].K, M, W, H)
    for exp in (1, 2):
        masks = surface_masks(exp, layout, cams, depth, cfg)
        assert masks and all(m.mean() > 0.5 for m in masks.values())
        runs = {}
        for name, cs in (("ground_truth", cams), ("complete", jittered)):
            res, _ = run_experiment(exp, cs, lambda c, v: str(root / c / f"{v}.png"),
                                    layout, 0.45, 0.8, cfg, depth, None, masks)
            runs[("dibr", "true", name)] = res
        tables = psnr_tables(exp, runs, ["dibr"], 6)
        gt, jit = (next(t for t in tables if t.cameras == c)
                   for c in ("ground_truth", "complete"))
        assert set(gt.surface_psnr_db) == set(masks) == set(gt.psnr_db)
        for t in masks:
            assert jit.surface_psnr_db[t] == pytest.approx(gt.surface_psnr_db[t], abs=0.02)
    masks = surface_masks(1, layout, cams, depth, cfg)
    runs = {}
    for name, cs in (("ground_truth", cams), ("complete", bad)):
        res, _ = run_experiment(1, cs, lambda c, v: str(root / c / f"{v}.png"), layout, 0.45,
                                0.8, cfg, depth, None, masks)
        runs[("dibr", "true", name)] = res
    result = SynthesisResult(experiment=1, renderer="dibr",
                             tables=tuple(psnr_tables(1, runs, ["dibr"], 6)),
                             setup=SynthesisSetup(near_m=0.45, far_m=0.8, psnr_border_px=6,
                                                  depth_method="given", depth_quality={}))
    (complete, truth, lost, n), = result.surface_db_lost()
    assert n == len(masks) and lost > 0.5
    assert truth.surface_psnr_db["x01_y00/1_1"] > complete.surface_psnr_db["x01_y00/1_1"] + 3
    write_synthesis(tmp_path / "s.json", result)
    back = read_synthesis(tmp_path / "s.json")
    for a, b in zip(back.tables, result.tables, strict=True):
        assert a.surface_psnr_db == pytest.approx(b.surface_psnr_db, abs=1e-8)
    # no masks (a real capture, Exp. 3): no surface figures, and none in the file
    assert surface_masks(3, layout, cams, depth, cfg) == {}
    assert surface_masks(1, layout, None, depth, cfg) == {}
    assert "surface_psnr_db" not in result.tables[0].__class__(
        "dibr", "true", "complete", "", (), {}).to_dict()
