"""Depth: the plane sweep recovers textured planes from synthetic pinhole renders;
the colmap backend fails clearly without a GPU; the workspace it would run on is
well formed; 16-bit disparity round trip; SGBM baseline runs; the vectorised pieces of
the sweep (best-k of the seen sources, winner-take-all) against their plain definitions."""

import cv2  # (before pycolmap)
import numpy as np
import pytest
from synth.costs import random_costs
from synth.planes import camera_at, fronto_plane, photo_texture, render_plane

from plenocal.depth import DepthBackendError, estimate_depth, resolve_backend
from plenocal.depth.colmap_mvs import (
    MvsProblem,
    colmap_available,
    colmap_depths,
    prepare_workspace,
    prepare_workspace_many,
    read_colmap_array,
)
from plenocal.depth.costkernels import mean_of_seen_best
from plenocal.depth.inputs import nearest_sources
from plenocal.depth.planesweep import (
    PlaneSweepOptions,
    plane_homographies,
    plane_homography,
    plane_sweep_depth,
    winner_take_all,
)
from plenocal.depth.quality import depth_quality
from plenocal.depth.sgbm import sgbm_depth
from plenocal.depth.sgm import SgmOptions, _wta, fill_background, sgm_depth

W, H, F = 320, 240, 500.0


@pytest.fixture(scope="module")
def texture():
    return photo_texture(512)


def _scene(texture, tilt, step=0.02):
    plane = fronto_plane(0.6, 0.8, texture, tilt)
    ref = camera_at([0, 0, 0], F, W, H)
    srcs = [camera_at([dx * step, dy * step, 0], F, W, H)
            for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    ri, rd = render_plane(ref, plane)
    return ref, ri, rd, srcs, [render_plane(s, plane)[0] for s in srcs]


@pytest.mark.parametrize("tilt", [0.0, 30.0])
def test_plane_sweep_recovers_plane(texture, tilt):
    ref, ri, rd, srcs, sims = _scene(texture, tilt)
    d = plane_sweep_depth(ref, ri, srcs, sims, 0.4, 0.9, PlaneSweepOptions())
    q = depth_quality(d, rd, 0.01)
    assert q["valid_share"] > 0.85, q
    assert q["within_of_valid"] > 0.9, q
    assert q["median_rel_error"] < 0.004, q


def test_plane_homography_maps_plane_points(texture):
    ref = camera_at([0, 0, 0], F, W, H)
    src = camera_at([0.03, -0.01, 0.005], F, W, H)
    uv = np.array([[10.0, 20.0], [300.0, 200.0]])
    X = ref.unproject(uv, np.array([0.55, 0.55]))
    expect, _ = src.project(X)
    Hm = plane_homography(ref, src, 0.55)
    q = np.c_[uv, np.ones(2)] @ Hm.T
    np.testing.assert_allclose(q[:, :2] / q[:, 2:], expect, atol=1e-9)


def test_plane_sweep_rejects_bad_input(texture):
    ref, ri, rd, srcs, sims = _scene(texture, 0.0)
    with pytest.raises(ValueError, match="near < far"):
        plane_sweep_depth(ref, ri, srcs, sims, 0.9, 0.4)
    with pytest.raises(ValueError, match="reference image"):
        plane_sweep_depth(ref, ri[:100], srcs, sims, 0.4, 0.9)


def test_colmap_backend_clear_error_without_gpu(texture):
    ok, why = colmap_available()
    if ok:
        pytest.skip("a CUDA pycolmap and a GPU are present here")
    with pytest.raises(DepthBackendError, match="pycolmap-cuda12.*planesweep"):
        resolve_backend("colmap")
    assert resolve_backend("auto") == "planesweep"
    ref, ri, rd, srcs, sims = _scene(texture, 0.0)
    with pytest.raises(DepthBackendError, match="GPU"):
        estimate_depth(ref, ri, srcs[:2], sims[:2], 0.4, 0.9, {"backend": "colmap"})


@pytest.mark.parametrize("tilt", [0.0, 30.0])
def test_colmap_backend_recovers_plane_on_a_gpu(texture, tilt, tmp_path):
    """COLMAP's patch-match stereo (depth.backend colmap) on the plane that the plane
    sweep recovers above: within 1 % of the true depth where valid, about as complete.
    Runs only where a CUDA pycolmap and a GPU are present (skipped with the reason
    elsewhere: CI has no GPU; BENCHMARKS.md "GPU" has a run)."""
    ok, why = colmap_available()
    if not ok:
        pytest.skip(f"COLMAP's CUDA code cannot run here: {why}")
    ref, ri, rd, srcs, sims = _scene(texture, tilt)
    d = estimate_depth(ref, ri, srcs, sims, 0.4, 0.9, {"backend": "colmap"},
                       workspace=tmp_path)
    q = depth_quality(d, rd, 0.01, border=8)
    assert q["valid_share"] > 0.8, q
    assert q["within_of_valid"] > 0.9, q
    assert q["median_rel_error"] < 0.004, q


def test_colmap_probe_skipped_without_nvidia_smi(monkeypatch):
    import plenocal.depth.colmap_mvs as mvs
    import plenocal.gpu as gpu

    def no_subprocess(*a, **k):
        raise AssertionError("the pycolmap probe ran although nvidia-smi is missing")

    monkeypatch.setattr(gpu.shutil, "which", lambda name: None)
    monkeypatch.setattr(gpu.subprocess, "run", no_subprocess)
    gpu.cuda_available.cache_clear()
    try:
        ok, why = mvs.colmap_available()
        assert not ok and "no GPU" in why
        assert resolve_backend("auto") == "planesweep"
    finally:
        gpu.cuda_available.cache_clear()


def test_colmap_workspace_is_readable(tmp_path, texture):
    import pycolmap

    ref, ri, rd, srcs, sims = _scene(texture, 0.0)
    names = prepare_workspace(tmp_path, ref, ri, srcs[:3], sims[:3])
    rec = pycolmap.Reconstruction(str(tmp_path / "sparse"))
    assert rec.num_images() == 4
    im = next(i for i in rec.images.values() if i.name == names[1])
    # the COLMAP pose and intrinsics reproduce our projection (+0.5 px pixel convention)
    X = np.array([[0.05, -0.02, 0.6]])
    uv, _ = srcs[0].project(X)
    cam = rec.cameras[im.camera_id]
    xc = im.cam_from_world() * X[0] if callable(im.cam_from_world) else im.cam_from_world * X[0]
    px = cam.img_from_cam(np.asarray(xc)[None])[0]
    np.testing.assert_allclose(px - 0.5, uv[0], atol=1e-6)
    cfg = (tmp_path / "stereo" / "patch-match.cfg").read_text().splitlines()
    assert cfg == [names[0], ", ".join(names[1:])]


def _two_problems(texture):
    """The plane seen from the reference with three sources, and from the first source
    with the reference and the second source: four distinct views."""
    ref, ri, rd, srcs, sims = _scene(texture, 0.0)
    return [MvsProblem(ref, ri, srcs[:3], sims[:3], 0.4, 0.9),
            MvsProblem(srcs[0], sims[0], [ref, srcs[1]], [ri, sims[1]], 0.45, 0.85)], rd


def test_colmap_workspace_holds_each_view_once_for_many_references(tmp_path, texture):
    """One COLMAP run for several maps (a depth job's): every distinct view written once,
    patch-match.cfg lists each reference with its own sources, fusion.cfg the
    references."""
    import pycolmap

    problems, _ = _two_problems(texture)
    names = prepare_workspace_many(tmp_path, problems)
    v = [f"view{i:03d}.png" for i in range(4)]
    assert names == [[v[0], v[1], v[2], v[3]], [v[1], v[0], v[2]]]
    assert sorted(p.name for p in (tmp_path / "images").iterdir()) == v
    assert pycolmap.Reconstruction(str(tmp_path / "sparse")).num_images() == 4
    cfg = (tmp_path / "stereo" / "patch-match.cfg").read_text().splitlines()
    assert cfg == [v[0], ", ".join(v[1:]), v[1], f"{v[0]}, {v[2]}"]
    assert (tmp_path / "stereo" / "fusion.cfg").read_text().splitlines() == [v[0], v[1]]
    with pytest.raises(ValueError, match="twice"):
        prepare_workspace_many(tmp_path / "again", [problems[0], problems[0]])


def test_colmap_depths_in_one_run_on_a_gpu(tmp_path, texture):
    """Two maps in one COLMAP run, each within its own bounds and about as good as the
    single map above. Runs only where a CUDA pycolmap and a GPU are present."""
    ok, why = colmap_available()
    if not ok:
        pytest.skip(f"COLMAP's CUDA code cannot run here: {why}")
    problems, rd = _two_problems(texture)
    d0, d1 = colmap_depths(problems, tmp_path)
    q = depth_quality(d0, rd, 0.01, border=8)
    assert q["valid_share"] > 0.8 and q["within_of_valid"] > 0.9, q
    assert d1[d1 > 0].min() >= 0.45 and d1.max() <= 0.85
    assert (d1 > 0).mean() > 0.5


def test_colmap_array_reader(tmp_path):
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    p = tmp_path / "d.bin"
    p.write_bytes(b"4&3&1&" + a.tobytes())  # per channel, row after row (COLMAP Mat)
    np.testing.assert_array_equal(read_colmap_array(p), a)


def test_nearest_sources_order():
    cams = {k: camera_at([x, 0, 0], F, W, H) for k, x in
            (("a", 0.0), ("b", 0.02), ("c", -0.01), ("d", 0.05))}
    assert nearest_sources("a", cams, 2) == ["c", "b"]


def test_sgbm_baseline_runs(texture):
    plane = fronto_plane(0.6, 0.8, texture, 0.0)
    a, b = camera_at([0, 0, 0], F, W, H), camera_at([0.02, 0, 0], F, W, H)
    ia, da = render_plane(a, plane)
    ib, _ = render_plane(b, plane)
    d, info = sgbm_depth(a, ia, b, ib, 0.4, 0.9)
    q = depth_quality(d, da, 0.02)
    assert q["valid_share"] > 0.7 and q["within_of_valid"] > 0.8, q


def _two_planes(texture, cam):
    """A far tilted plane and a near fronto square in front of it (z-buffered)."""
    far = fronto_plane(0.7, 0.9, texture, 20.0)
    near_tex = np.ascontiguousarray(texture[::-1, ::-1][:200, :200])
    near = fronto_plane(0.5, 0.1, near_tex)
    i1, d1 = render_plane(cam, far)
    i2, d2 = render_plane(cam, near)
    front = (d2 > 0) & ((d1 <= 0) | (d2 < d1))
    return np.where(front[..., None], i2, i1), np.where(front, d2, d1)


def test_sgm_dense_sharp_and_consistent(texture):
    """SGM over the multi-view cost volume: every pixel has a depth, nearly all within
    1 % of the truth, also next to the occluding edge of the near square (occluded in
    some sources), where the sparse plane sweep leaves holes."""
    ref = camera_at([0, 0, 0], F, W, H)
    srcs = [camera_at([dx * 0.015, dy * 0.015, 0], F, W, H)
            for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    ri, rd = _two_planes(texture, ref)
    sims = [_two_planes(texture, s)[0] for s in srcs]
    d = sgm_depth(ref, ri, srcs, sims, 0.4, 0.9, SgmOptions())
    q = depth_quality(d, rd, 0.01, border=4)
    assert q["valid_share"] == 1.0, q
    assert q["within_share"] > 0.93, q
    edge = cv2.dilate((cv2.Canny((rd * 100).astype(np.uint8), 1, 1) > 0).astype(np.uint8),
                      np.ones((5, 5), np.uint8)) > 0
    near_edge = depth_quality(np.where(edge, d, 0), np.where(edge, rd, 0), 0.01)
    assert near_edge["within_share"] > 0.75, near_edge
    ps = plane_sweep_depth(ref, ri, srcs, sims, 0.4, 0.9, PlaneSweepOptions())
    assert depth_quality(ps, rd, 0.01, border=4)["valid_share"] < q["valid_share"]


def test_background_fill_takes_the_far_side():
    z = np.array([[0.5, 0.0, 0.0, 0.8, 0.8]], dtype=np.float32)
    np.testing.assert_allclose(fill_background(z), [[0.5, 0.8, 0.8, 0.8, 0.8]])
    z = np.array([[0.0, 0.6, 0.0]], dtype=np.float32)
    np.testing.assert_allclose(fill_background(z), [[0.6, 0.6, 0.6]])


def test_sgm_source_mean_is_the_mean_of_the_best_seen():
    per = random_costs((8, 9, 11), 1)
    S, fraction = per.shape[0], 0.5
    k_of = np.maximum(1, np.ceil(np.arange(S + 1) * fraction)).astype(np.int64)
    out = np.empty(per.shape[1:], np.float32)
    mean_of_seen_best(per.copy(), k_of, int(k_of[-1]), out)
    for y, x in np.ndindex(out.shape):
        seen = np.sort(per[:, y, x][np.isfinite(per[:, y, x])])
        if len(seen) == 0:
            assert out[y, x] == 1.0
            continue
        k = int(k_of[len(seen)])
        assert out[y, x] == np.cumsum(seen, dtype=np.float32)[k - 1] / np.float32(k)


def test_winner_take_all_is_the_first_minimum_and_the_second_outside_its_neighbours():
    vol = random_costs((6, 9, 11), 2)
    v = np.where(np.isfinite(vol), vol, np.float32(1e6))
    best, depth, c0, second = winner_take_all(vol.copy(), np.linspace(1.0, 2.0, 6))
    assert np.array_equal(best, np.argmin(v, axis=0))
    assert np.array_equal(c0, v.min(axis=0))
    labels = np.arange(6)[:, None, None]
    far = np.abs(labels - best[None]) > 1
    assert np.array_equal(second, np.where(far, v, np.float32(1e6)).min(axis=0))


def test_sgm_wta_matches_its_definition():
    agg = random_costs((9, 11, 7), 3).transpose(1, 2, 0).copy()
    agg[~np.isfinite(agg)] = 5.0
    near, far = 0.4, 0.9
    depth, cont, ratio = _wta(agg, near, far)
    D = agg.shape[2]
    best = np.argmin(agg, axis=2)
    for y, x in np.ndindex(best.shape):
        a, b = agg[y, x], int(best[y, x])
        off = np.float32(0.0)
        if 1 <= b <= D - 2:
            den = a[b - 1] - np.float32(2.0) * a[b] + a[b + 1]
            if den > np.float32(1e-9):
                off = np.clip(np.float32(0.5) * (a[b - 1] - a[b + 1]) / den, -0.5, 0.5)
        assert cont[y, x] == b + np.float64(off)
        inv = 1.0 / near + cont[y, x] * (1.0 / far - 1.0 / near) / (D - 1)
        assert depth[y, x] == np.float32(1.0 / inv)
        rest = [a[d] for d in range(D) if abs(d - b) > 1]
        assert ratio[y, x] == (a[b] / min(rest) if rest else 0.0)


def test_plane_homographies_match_the_single_plane_homography(texture):
    ref, _, _, srcs, _ = _scene(texture, 0.0)
    depths = np.array([0.4, 0.55, 0.9])
    hs = plane_homographies(ref, srcs[2], depths)
    for h, d in zip(hs, depths, strict=True):
        np.testing.assert_allclose(h, plane_homography(ref, srcs[2], float(d)), rtol=1e-12,
                                   atol=1e-12)


def test_depth_jobs_of_both_registrations():
    """depth_job_a refuses a shot SfM did not register (naming the file); depth_job_b takes
    the reference's own set as sources, in metres."""
    from plenocal.artifacts.disparity import Conversion
    from plenocal.artifacts.reg_a import RegistrationA
    from plenocal.artifacts.rig import RigB
    from plenocal.calib.reg_b import rig
    from plenocal.calib.reg_b.datasheet import Datasheet
    from plenocal.depth.inputs import depth_job_a, depth_job_b

    reg_a = RegistrationA(1799.5, 301, 225, "incremental", {})
    with pytest.raises(ValueError, match=r"shot x01_y00 is not registered in a\.json"):
        depth_job_a(reg_a, "a.json", "x01_y00", "2_2", "views", None, 2, 0.1)
    ds = Datasheet(0.0055, 2048, 1536, 600.0, 35.0, 0.13, (2.8,), 5.0, None, 10.0, 470.0,
                   740.0)
    conv = Conversion(-4.5, -3.0, 3.0971, 6.0, 23.92, 21.92, 301, 225, 5)
    job = depth_job_b(RigB(rig.build_rig(ds, [conv], 1799.5, 5, model="exact")), "x01_y00",
                      "2_2", "views", 4, 0.1)
    assert job.units == "m" and len(job.src_names) == 4 and "2_2" not in job.src_names
    assert all(p.parent.name == "x01_y00" for p in job.src_paths)
    assert str(job.ref_path) == "views/x01_y00/2_2.png" and 0 < job.near < job.far


def test_maps_swept_in_worker_processes_are_the_maps_swept_here(texture, tmp_path):
    """Registration A's maps (plenocal.depth.shot._sweep_all): in two worker processes the
    same bits as one after the other in this process, in the jobs' order."""
    from plenocal.depth.inputs import DepthJob
    from plenocal.depth.shot import _sweep_all
    from plenocal.io.files import write_image

    jobs = {}
    for k, tilt in enumerate((0.0, 20.0, 35.0)):
        ref, ri, _, srcs, sims = _scene(texture, tilt)
        paths = []
        for j, img in enumerate([ri, *sims[:4]]):
            paths.append(tmp_path / f"s{k}_{j}.png")
            write_image(paths[-1], (np.clip(img, 0, 1) * 255).astype(np.uint8))
        jobs[f"shot{k}"] = DepthJob(ref, paths[0], [f"v{j}" for j in range(4)], srcs[:4],
                                    paths[1:], 0.4, 0.9, "m")
    opt = PlaneSweepOptions(num_depths=24)
    here = list(_sweep_all(jobs, opt, 1))
    workers = list(_sweep_all(jobs, opt, 2))
    assert [c for c, _, _ in workers] == list(jobs) == [c for c, _, _ in here]
    for (_, a, _), (_, b, _) in zip(here, workers, strict=True):
        assert a.tobytes() == b.tobytes() and (a > 0).mean() > 0.5


def test_downsampled_camera_by_hand():
    """A camera reduced twice: f / 2 and c' = (c + 1/2) / 2 - 1/2 (pixel centres at
    integers), the size halved rounding down; a world point lands where the full-size
    pixel's block centre does."""
    from plenocal.camera import PinholeCamera, downsample_camera

    K = np.array([[100.0, 0.0, 49.5], [0.0, 100.0, 24.5], [0.0, 0.0, 1.0]])
    cam = PinholeCamera(K, np.eye(4), 101, 50)
    half = downsample_camera(cam, 2)
    np.testing.assert_allclose(half.K, [[50.0, 0.0, 24.5], [0.0, 50.0, 12.0], [0, 0, 1]])
    assert (half.width, half.height) == (50, 25)
    X = np.array([0.13, -0.07, 1.7])
    full_uv, _ = cam.project(X)
    half_uv, _ = half.project(X)
    np.testing.assert_allclose(half_uv, (full_uv + 0.5) / 2 - 0.5, atol=1e-12)
    assert downsample_camera(cam, 1) is cam


def test_downsampled_image_is_block_means():
    """Each reduced pixel is the mean of its 2 x 2 block; the odd last row and column
    are left out."""
    from plenocal.depth.inputs import downsample_image

    img = np.arange(35, dtype=np.float32).reshape(5, 7)
    out = downsample_image(img, 2)
    want = img[:4, :6].reshape(2, 2, 3, 2).mean(axis=(1, 3))
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out, want)
    with pytest.raises(ValueError, match="cannot be reduced"):
        downsample_image(img, 8)


def test_plane_swept_at_half_resolution(texture, tmp_path):
    """A registration's map at depth.registration_downsample 2: half the size, the same
    plane (the true depth at the reduced pixels' block centres)."""
    from plenocal.depth.inputs import DepthJob, downsampled
    from plenocal.depth.shot import _sweep_one
    from plenocal.io.files import write_image

    ref, ri, rd, srcs, sims = _scene(texture, 20.0)
    paths = []
    for j, img in enumerate([ri, *sims]):
        paths.append(tmp_path / f"v{j}.png")
        write_image(paths[-1], (np.clip(img, 0, 1) * 255).astype(np.uint8))
    job = downsampled(DepthJob(ref, paths[0], [f"v{j}" for j in range(len(srcs))], srcs,
                               paths[1:], 0.4, 0.9, "m"), 2)
    depth, _ = _sweep_one(job, PlaneSweepOptions())
    assert depth.shape == (H // 2, W // 2) and job.downsample == 2
    truth = rd.reshape(H // 2, 2, W // 2, 2).mean(axis=(1, 3))  # the plane: linear in 1/z
    q = depth_quality(depth, truth, 0.01)
    assert q["valid_share"] > 0.8, q
    assert q["median_rel_error"] < 0.006, q
