"""Simulator benchmark (issue 2): seconds and peak memory to trace one default shot,
extrapolated to the default dataset on 2 cores.

Usage: python bench/bench_simulate.py [--config config.yaml] [--dataset synthetic]
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import yaml

from plenocal.config import validate_config
from plenocal.simulate.dataset import render_shot, setup_dataset, shot_names

ROOT = Path(__file__).resolve().parents[1]


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
        dt = time.perf_counter() - t0
    n = len(shot_names(sim))
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    w, h, k = sim["sensor"]["width"], sim["sensor"]["height"], sim["render"]["samples"]
    print(f"one shot {w}x{h}, {k} rays/px: {dt:.2f} s ({w * h * k / dt / 1e6:.1f} Mrays/s), "
          f"peak RSS {rss:.0f} MB")
    print(f"{n} shots on 2 cores: about {dt * n / 2:.0f} s of tracing (target <= 180 s)")


if __name__ == "__main__":
    main()
