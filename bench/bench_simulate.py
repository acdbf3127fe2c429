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
``--psnr-shots`` of the scenes of ``--psnr-seeds``, with the converter's set-up decided per
count as rule convert_setup does: the fewest rays per pixel whose PSNR stays within
``--psnr-tolerance`` dB of the most rays' on every seed (issue 15: 0.2 dB).

Usage: python bench/bench_simulate.py [--config config.yaml] [--dataset synthetic]
       [--simulate FILE] [--psnr-samples 4,8,12,32] [--psnr-seeds 0,1,2]
       [--psnr-shots x03_y01,x00_y00,x06_y02,hand03]
"""

from __future__ import annotations

import argparse
import copy
import os
import resource
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
                    samples: list[int], seed: int) -> dict[int, float]:
    """Converted views against ideal renders, per number of rays per pixel, on the
    scene and shots of ``seed``; returns the central views' mean PSNR per count.

    As the workflow does it: the converter's set-up (rule convert_setup: tile, grid) is
    decided on the full-set shot's lenslet image of each count, the views' ground-truth
    cameras (rule ground_truth) follow that set-up, and the ideal renders (rule
    ground_truth_render) are the references; the views are scored by
    plenocal.convert.quality (rule convert_quality)."""
    import cv2  # noqa: F401, PLC0415  (before anything that may load pycolmap)

    from plenocal.artifacts.cameras import read_cameras  # noqa: PLC0415
    from plenocal.convert import ConvertSettings, convert_files  # noqa: PLC0415
    from plenocal.convert.quality import dataset_quality  # noqa: PLC0415
    from plenocal.convert.setup import decide_setup, read_setup, write_setup  # noqa: PLC0415
    from plenocal.convert.shot import load_calib, load_lenslet, read_sensor_size  # noqa: PLC0415
    from plenocal.io.files import read_json, to_uint8, write_image  # noqa: PLC0415
    from plenocal.simulate.groundtruth import ground_truth_cameras  # noqa: PLC0415
    from plenocal.simulate.raytrace import render_pinhole  # noqa: PLC0415
    from plenocal.simulate.scene import scene_arrays  # noqa: PLC0415
    from plenocal.viewgeom import central_view  # noqa: PLC0415

    ds, conv = cfg["datasets"][dataset], cfg["convert"]
    n = ds["views"]
    sim = copy.deepcopy(ds["simulate"])
    sim["seed"] = seed
    data = out / f"seed{seed}"
    setup_dataset(sim, data)
    scene = scene_arrays(read_json(data / "truth" / "scene.json"))
    a = sim["array"]
    full = f"x{(a['cols'] - 1) // 2:02d}_y{(a['rows'] - 1) // 2:02d}"
    settings = ConvertSettings.from_config(conv)
    means = {}
    for k in samples:
        s2 = copy.deepcopy(sim)
        s2["render"]["samples"] = k
        run = data / f"s{k}"
        t0 = time.perf_counter()
        for cam in dict.fromkeys([full, *shots]):
            render_shot(s2, data, cam, run / f"{cam}.png", log=lambda m: None)
        setup, _ = decide_setup(load_lenslet(run / f"{full}.png",
                                             read_sensor_size(data / "camera.yaml")),
                                load_calib(data / "calib.xml"), n, settings, source=full)
        write_setup(run / "convert_setup.json", setup)
        setup = read_setup(run / "convert_setup.json")
        tile = setup.tile
        pairs = []
        for cam in shots:
            gt = run / "gt" / f"{cam}.json"
            ground_truth_cameras(data, [cam], n, tile, setup.q_px, gt,
                              log=lambda m: None, even=bool(conv["even_size"]))
            shot = convert_files(run / f"{cam}.png", data / "calib.xml", data / "camera.yaml",
                                 n, settings, setup_json=run / "convert_setup.json")
            for name, img in shot.views():
                c = read_cameras(gt)[f"{cam}/{name}"]
                ideal, _ = render_pinhole(scene, c.K, c.cam_to_world, c.width, c.height,
                                          sim["render"]["ideal_supersample"])
                write_image(run / "gt" / cam / f"{name}.png", to_uint8(ideal))
                write_image(run / cam / f"{name}.png", img)
                pairs.append((cam, name, run / cam / f"{name}.png",
                              run / "gt" / cam / f"{name}.png"))
        q = dataset_quality(pairs, border=tile, central=central_view(n))
        means[k] = q["mean_psnr_central_db"]
        print(f"seed {seed}, render.samples {k:3d}: PSNR central views "
              f"{q['mean_psnr_central_db']:.3f} dB, all views {q['mean_psnr_db']:.3f} dB, "
              f"worst {q['min_psnr_db']:.2f} dB ({q['worst_view']}); "
              f"{time.perf_counter() - t0:.0f} s for {len(shots)} shots", flush=True)
    return means


def job_peak(cmd: list[str], work: Path) -> tuple[float, float]:
    """The simulate job ``cmd`` as a process of its own: its wall seconds and peak RSS (MB),
    measured as ``bench_real.py`` measures a converter (``/usr/bin/time -f %M``).
    RUSAGE_CHILDREN counted this script's own memory, which a forked child starts with
    (in one measurement 501 MB reported for a job whose own peak was 490 MB). Imported
    here, after the warm measure, so that bench_real's imports do not add to this
    process's peak."""
    from bench_real import TIME, measure  # noqa: PLC0415

    if not TIME.is_file():
        print(f"note: no {TIME}: the job's peak RSS is its launcher's child's ru_maxrss "
              "(bench_real.measure's fallback)", file=sys.stderr)
    # this checkout's package first, as the job ran from the repository's folder before
    pypath = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    wall, peak = measure(cmd, {**os.environ, "PYTHONPATH": pypath}, work)
    return wall, peak / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--dataset", default="synthetic")
    ap.add_argument("--simulate", help="YAML file with a `simulate:` block to use instead")
    ap.add_argument("--psnr-samples", help="comma-separated render.samples to compare")
    ap.add_argument("--psnr-shots", default="x03_y01,x00_y00,x06_y02,hand03")
    ap.add_argument("--psnr-seeds", default="0,1,2",
                    help="simulate.seed values (scenes and hand-held poses) to measure on")
    ap.add_argument("--psnr-tolerance", type=float, default=0.2,
                    help="dB below the most rays' PSNR that a count may lose")
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
        cold, rss_job = job_peak([sys.executable, "-c", JOB, str(config_file), args.dataset,
                                  tmp, "hand00", str(Path(tmp) / "b.png")], Path(tmp))
        if args.psnr_samples:
            counts = sorted(int(k) for k in args.psnr_samples.split(","))
            per_seed = {seed: psnr_by_samples(cfg, args.dataset, Path(tmp) / "psnr",
                                              args.psnr_shots.split(","), counts, seed)
                        for seed in (int(x) for x in args.psnr_seeds.split(","))}
            ok = [k for k in counts if all(m[k] >= m[counts[-1]] - args.psnr_tolerance
                                           for m in per_seed.values())]
            print(f"fewest rays per pixel within {args.psnr_tolerance} dB of {counts[-1]} on "
                  f"every seed: {ok[0] if ok else 'none'}")
    n = len(shot_names(sim))
    w, h, k = sim["sensor"]["width"], sim["sensor"]["height"], sim["render"]["samples"]
    print(f"tracing one shot {w}x{h}, {k} rays/px (warm process): {warm:.2f} s "
          f"({w * h * k / warm / 1e6:.1f} Mrays/s), peak RSS {rss_warm:.0f} MB")
    print(f"one simulate job (fresh process, cached JIT): {cold:.2f} s, peak RSS "
          f"{rss_job:.0f} MB (target < 4096 MB)")
    print(f"{n} shots on 2 cores: about {cold * n / 2:.0f} s (target <= 180 s)")


if __name__ == "__main__":
    main()
