"""Simulator benchmark (issue 2): seconds and peak memory to trace one default shot,
extrapolated to the default dataset on 2 cores (target: <= 3 min, < 4 GB per job).

Two figures: the tracing of one shot in a warm process (numba code loaded), and one
shot as a ``simulate`` job sees it: a fresh Python process that imports the package,
loads the compiled ray tracer from numba's cache, loads the textures, builds the
microlens map, traces and writes the PNG. The extrapolation uses the second.

``--simulate FILE`` replaces the dataset's ``simulate`` block by the one in FILE (e.g.
the Raytrix-like camera). ``--psnr-samples 12,8,6`` then measures, for each number of
rays per pixel (``render.samples``), the PSNR of the converted views (convert settings
of the config) against the ideal renders of their ground-truth cameras, on
``--psnr-shots``: how few rays keep the views as good as the default's.

Usage: python bench/bench_simulate.py [--config config.yaml] [--dataset synthetic]
       [--simulate FILE] [--psnr-samples 12,8,6,4] [--psnr-shots x03_y01,hand02]
"""

from __future__ import annotations

import argparse
import copy
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


def psnr_by_samples(cfg: dict, dataset: str, out: Path, shots: list[str],
                    samples: list[int]) -> None:
    """Converted views against ideal renders, per number of rays per pixel."""
    import cv2  # noqa: F401, PLC0415  (before anything that may load pycolmap)

    from plenocal.camera import PinholeCamera  # noqa: PLC0415
    from plenocal.convert import ConvertSettings, convert_files  # noqa: PLC0415
    from plenocal.convert.quality import dataset_quality  # noqa: PLC0415
    from plenocal.groundtruth import ground_truth_shot  # noqa: PLC0415
    from plenocal.io import read_json, to_uint8, write_image  # noqa: PLC0415
    from plenocal.simulate.raytrace import render_pinhole  # noqa: PLC0415
    from plenocal.simulate.scene import scene_arrays  # noqa: PLC0415
    from plenocal.viewgeom import central_view  # noqa: PLC0415

    sim, conv = cfg["datasets"][dataset]["simulate"], cfg["convert"]
    n = cfg["datasets"][dataset]["views"]
    scene = scene_arrays(read_json(out / "truth" / "scene.json"))
    for cam in shots:
        gt = out / "gt" / f"{cam}.json"
        ground_truth_shot(out, cam, n, conv["tile_size"], conv.get("view_spacing_px"), gt,
                          log=lambda m: None)
        for key, d in read_json(gt)["cameras"].items():
            c = PinholeCamera.from_dict(d)
            img, _ = render_pinhole(scene, c.K, c.cam_to_world, c.width, c.height,
                                    sim["render"]["ideal_supersample"])
            write_image(out / "gt" / f"{key}.png", to_uint8(img))
    settings = ConvertSettings.from_config(conv)
    for k in samples:
        s2 = copy.deepcopy(sim)
        s2["render"]["samples"] = k
        pairs = []
        t0 = time.perf_counter()
        for cam in shots:
            png = out / f"s{k}" / f"{cam}.png"
            render_shot(s2, out, cam, png, log=lambda m: None)
            shot = convert_files(png, out / "calib.xml", out / "camera.yaml", n, settings)
            for name, img in shot.views():
                write_image(out / f"s{k}" / cam / f"{name}.png", img)
                pairs.append((cam, name, out / f"s{k}" / cam / f"{name}.png",
                              out / "gt" / cam / f"{name}.png"))
        q = dataset_quality(pairs, border=int(conv["tile_size"]), central=central_view(n))
        print(f"render.samples {k:3d}: PSNR central views {q['mean_psnr_central_db']:.2f} dB, "
              f"all views {q['mean_psnr_db']:.2f} dB, worst {q['min_psnr_db']:.2f} dB "
              f"({q['worst_view']}); {time.perf_counter() - t0:.0f} s for {len(shots)} shots")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--dataset", default="synthetic")
    ap.add_argument("--simulate", help="YAML file with a `simulate:` block to use instead")
    ap.add_argument("--psnr-samples", help="comma-separated render.samples to compare")
    ap.add_argument("--psnr-shots", default="x03_y01,hand02")
    args = ap.parse_args()
    raw = yaml.safe_load(Path(args.config).read_text())
    if args.simulate:
        raw["datasets"][args.dataset]["simulate"] = yaml.safe_load(
            Path(args.simulate).read_text())["simulate"]
    cfg = validate_config(copy.deepcopy(raw))
    sim = cfg["datasets"][args.dataset]["simulate"]
    with tempfile.TemporaryDirectory() as tmp:
        config_file = Path(tmp) / "config.yaml"
        config_file.write_text(yaml.safe_dump(raw))
        setup_dataset(sim, tmp)
        render_shot(sim, tmp, "x00_y00", Path(tmp) / "warm.png", log=lambda m: None)  # JIT
        t0 = time.perf_counter()
        render_shot(sim, tmp, "x01_y00", Path(tmp) / "a.png", log=lambda m: None)
        warm = time.perf_counter() - t0
        rss_warm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", JOB, str(config_file), args.dataset, tmp, "hand00",
                        str(Path(tmp) / "b.png")], check=True, cwd=ROOT)
        cold = time.perf_counter() - t0
        rss_job = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        if args.psnr_samples:
            psnr_by_samples(cfg, args.dataset, Path(tmp), args.psnr_shots.split(","),
                            [int(k) for k in args.psnr_samples.split(",")])
    n = len(shot_names(sim))
    w, h, k = sim["sensor"]["width"], sim["sensor"]["height"], sim["render"]["samples"]
    print(f"tracing one shot {w}x{h}, {k} rays/px (warm process): {warm:.2f} s "
          f"({w * h * k / warm / 1e6:.1f} Mrays/s), peak RSS {rss_warm:.0f} MB")
    print(f"one simulate job (fresh process, cached JIT): {cold:.2f} s, peak RSS "
          f"{rss_job:.0f} MB (target < 4096 MB)")
    print(f"{n} shots on 2 cores: about {cold * n / 2:.0f} s (target <= 180 s)")


if __name__ == "__main__":
    main()
