"""Simulator benchmark (issue 2): seconds and peak memory to trace one default shot,
extrapolated to the default dataset on 2 cores (target: <= 3 min, < 4 GB per job).

Two figures: the tracing of one shot in a warm process (numba code loaded), and one
shot as a ``simulate`` job sees it: a fresh Python process that imports the package,
loads the compiled ray tracer from numba's cache, loads the textures, builds the
microlens map, traces and writes the PNG. The extrapolation uses the second.

Usage: python bench/bench_simulate.py [--config config.yaml] [--dataset synthetic]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from plenocal.config import validate_config
from plenocal.simulate.dataset import render_shot, setup_dataset, shot_names

ROOT = Path(__file__).resolve().parents[1]

JOB = """
import sys, yaml
import cv2
from plenocal.config import validate_config
from plenocal.simulate.dataset import render_shot
cfg = validate_config(yaml.safe_load(open(sys.argv[1])))
render_shot(cfg["datasets"][sys.argv[2]]["simulate"], sys.argv[3], sys.argv[4], sys.argv[5],
            log=lambda m: None)
"""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--dataset", default="synthetic")
    args = ap.parse_args()
    cfg = validate_config(yaml.safe_load(Path(args.config).read_text()))
    sim = cfg["datasets"][args.dataset]["simulate"]
    with tempfile.TemporaryDirectory() as tmp:
        setup_dataset(sim, tmp)
        render_shot(sim, tmp, "x00_y00", Path(tmp) / "warm.png", log=lambda m: None)  # JIT
        t0 = time.perf_counter()
        render_shot(sim, tmp, "x01_y00", Path(tmp) / "a.png", log=lambda m: None)
        warm = time.perf_counter() - t0
        rss_warm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", JOB, args.config, args.dataset, tmp, "hand00",
                        str(Path(tmp) / "b.png")], check=True, cwd=ROOT)
        cold = time.perf_counter() - t0
        rss_job = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    n = len(shot_names(sim))
    w, h, k = sim["sensor"]["width"], sim["sensor"]["height"], sim["render"]["samples"]
    print(f"tracing one shot {w}x{h}, {k} rays/px (warm process): {warm:.2f} s "
          f"({w * h * k / warm / 1e6:.1f} Mrays/s), peak RSS {rss_warm:.0f} MB")
    print(f"one simulate job (fresh process, cached JIT): {cold:.2f} s, peak RSS "
          f"{rss_job:.0f} MB (target < 4096 MB)")
    print(f"{n} shots on 2 cores: about {cold * n / 2:.0f} s (target <= 180 s)")


if __name__ == "__main__":
    main()
