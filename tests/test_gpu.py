"""Where COLMAP's CUDA code runs (plenocal.gpu, config sfm.device and depth.backend):
the probe, the resolution of ``auto``, the clear error for an explicit ``cuda`` on a
machine without a GPU, and - only where a CUDA pycolmap and a GPU are present - SIFT
and matching on the GPU against the CPU on the same views."""

from __future__ import annotations

import subprocess

import cv2  # noqa: F401  (before pycolmap)
import pytest
from synth.scenes import default_scene, render, rig_cameras, view_sets

import plenocal.gpu as gpu
from plenocal.calib.reg_a import colmap as cm
from plenocal.calib.reg_a import viewdb
from plenocal.io.files import write_image


@pytest.fixture
def probe(monkeypatch):
    """Set what the probe finds: ``probe(which, returncode, stdout)``; the cached
    answer is forgotten before and after."""
    calls = []

    def set_probe(which: str | None, returncode: int = 0, stdout: str = "ok\n"):
        monkeypatch.setattr(gpu.shutil, "which", lambda name: which)

        def fake_run(cmd, **kwargs):
            calls.append(cmd)
            return subprocess.CompletedProcess(cmd, returncode, stdout, "")

        monkeypatch.setattr(gpu.subprocess, "run", fake_run)
        gpu.cuda_available.cache_clear()
        return calls

    yield set_probe
    gpu.cuda_available.cache_clear()


def test_auto_is_the_cpu_without_a_gpu(probe):
    calls = probe(None)
    assert gpu.cuda_available() == (False, "nvidia-smi not found: no GPU visible")
    assert gpu.resolve_device("auto") == "cpu"
    assert gpu.resolve_device("cpu") == "cpu"
    assert calls == []  # no nvidia-smi: no child process


def test_explicit_cuda_without_a_gpu_names_key_reason_and_remedy(probe):
    probe("/usr/bin/nvidia-smi", 3, "pycolmap is built without CUDA\n")
    with pytest.raises(gpu.GpuUnavailableError) as err:
        gpu.resolve_device("cuda", "sfm.device")
    msg = str(err.value)
    assert "sfm.device = cuda" in msg and "built without CUDA" in msg
    assert "pycolmap-cuda12" in msg and "sfm.device: auto or cpu" in msg
    with pytest.raises(ValueError, match="sfm.device = 'gpu': must be auto, cpu or cuda"):
        gpu.resolve_device("gpu", "sfm.device")


def test_auto_takes_the_gpu_where_the_probe_says_so_and_asks_once(probe):
    calls = probe("/usr/bin/nvidia-smi", 0, "ok\n")
    assert gpu.resolve_device("auto") == "cuda"
    assert gpu.resolve_device("cuda") == "cuda"
    assert cm.resolve_sfm_device({"device": "auto", "sift": "auto"}) == (True, "colmap")
    assert len(calls) == 1  # the answer is kept for the process


def test_sift_auto_follows_the_device():
    assert cm.resolve_extractor("auto", True) == "colmap"
    assert cm.resolve_extractor("auto", False) == "opencv"
    assert cm.resolve_extractor("opencv", True) == "opencv"
    assert cm.resolve_extractor("colmap", False) == "colmap"
    with pytest.raises(ValueError, match="sfm.sift"):
        cm.resolve_extractor("surf", False)


def test_cpu_config_resolves_without_probing(probe):
    calls = probe("/usr/bin/nvidia-smi", 0, "ok\n")
    assert cm.resolve_sfm_device({"device": "cpu", "sift": "auto"}) == (False, "opencv")
    assert calls == []


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("gpu_views")
    shots = rig_cameras(f=300.0, width=240, height=180, cols=2, rows=1, handheld=1)
    paths = {}
    for name, cam in view_sets(shots, 3, 0.003).items():
        paths[name] = root / f"{name}.png"
        write_image(paths[name], render(cam, default_scene(), ss=1))
    return paths, {k: c.cam_to_world[:3, 3] for k, c in shots.items()}


def test_sift_and_matching_on_the_gpu_match_the_cpu(views, tmp_path):
    """SiftGPU and the GPU matcher against COLMAP's CPU SIFT and matcher on the same 27
    views and pairs: about as many keypoints, every pair the CPU verifies within 10 %
    of its count. Runs only where COLMAP's CUDA code can (skipped with the reason)."""
    ok, why = gpu.cuda_available()
    if not ok:
        pytest.skip(f"COLMAP's CUDA code cannot run here: {why}")
    paths, centres = views
    infos = {}
    for device in ("cpu", "cuda"):
        infos[device] = viewdb.build_view_database(
            paths, tmp_path / f"{device}.db", tmp_path / device, shot_centres=centres,
            shot_neighbours=1, max_num_features=1000, extractor="colmap",
            use_gpu=device == "cuda")
    cpu, cuda = infos["cpu"], infos["cuda"]
    assert cuda["device"] == "cuda" and cuda["matching_device"] == "cuda"
    assert cuda["num_pairs"] == cpu["num_pairs"]
    assert cuda["keypoints_mean"] == pytest.approx(cpu["keypoints_mean"], rel=0.25)
    assert cuda["num_verified_pairs"] >= 0.9 * cpu["num_verified_pairs"] > 0
