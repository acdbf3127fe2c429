"""bench/bench_depth_noise.py: the true cameras moved by exactly the amounts asked for,
the same draw for the same seed, and the run's own figures read as the report reads them."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import bench_depth_noise as dn  # noqa: E402

from plenocal.artifacts.results import (  # noqa: E402
    PsnrTable,
    SynthesisResult,
    SynthesisSetup,
    write_synthesis,
)
from plenocal.camera import PinholeCamera, rotation_angle_deg  # noqa: E402


def _cams() -> dict[str, PinholeCamera]:
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    out = {}
    for i, key in enumerate(("x00_y00/2_2", "x01_y00/2_2", "x00_y00/0_0")):
        pose = np.eye(4)
        pose[:3, 3] = [0.01 * i, 0.002 * i, 0.0]
        out[key] = PinholeCamera(K, pose, 640, 480)
    return out


def test_every_camera_moves_by_the_amounts_given_and_a_seed_is_one_draw():
    cams = _cams()
    a, b, c = (dn.moved(cams, s, 1e-6, 1e-4) for s in (1, 1, 2))
    for key, cam in cams.items():
        assert np.linalg.norm(a[key].centre - cam.centre) == pytest.approx(1e-6, rel=1e-9)
        assert rotation_angle_deg(a[key].R, cam.R) == pytest.approx(1e-4, rel=1e-4)
        assert np.array_equal(a[key].cam_to_world, b[key].cam_to_world)
        assert not np.array_equal(a[key].cam_to_world, c[key].cam_to_world)
        assert np.array_equal(a[key].K, cam.K)  # the intrinsics stay


def test_the_runs_figures_are_the_dibr_tables_means(tmp_path: Path):
    def table(cameras, depth, whole, surface, renderer="dibr"):
        return PsnrTable(renderer, depth, cameras, "", ("c/1_1",), {"a": whole, "b": whole + 1.0},
                         {"a": surface, "b": surface + 2.0})

    path = tmp_path / "synthesis_exp1.json"
    write_synthesis(path, SynthesisResult(1, "dibr", (
        table("complete", "estimated", 30.0, 40.0),
        table("complete", "estimated", 1.0, 1.0, "rvs"),
        table("ground_truth", "true", 33.0, 44.0)), SynthesisSetup(0.4, 0.8, 8, "sgm", {})))
    assert dn.run_figures(path) == {("complete", "estimated"): (30.5, 41.0),
                                    ("ground_truth", "true"): (33.5, 45.0)}
