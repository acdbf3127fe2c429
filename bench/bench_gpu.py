"""GPU benchmark (issue 15): COLMAP's CUDA paths against the CPU ones, side by side in one
work folder on one machine.

Runs, in a scratch copy of the workflow, the calibration with its ground-truth check
(``results/<d>/eval/gt_errors.json``) and the view database (``results/<d>/matches/
matches.json``) once per setting of :data:`RUNS` named by ``--runs`` (default: all, the
CPU first): the CPU paths, COLMAP's patch-match stereo alone, the GPU matcher on
OpenCV's SIFT, SiftGPU and the GPU matcher, everything on the GPU. Later runs reuse the
lenslet images and views and rerun only what the settings change. Prints, per run:
the wall time, the job seconds of the rules that changed, the ground-truth errors
(gt_errors.json: focal length, centres, B, alpha, the scale of Eq. 5) and the depth
maps against the simulator's true depth (registration A's after one scale for all its
maps, B's in metres).

Needs a CUDA build of pycolmap and a GPU (README, GPU); refuses to run otherwise.

Usage::

    python bench/bench_gpu.py [--config config.yaml] [--jobs 8] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import copy
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_workflow import ROOT, make_copy, rule_benchmarks, snakemake  # noqa: E402

from plenocal.io.files import read_json, read_npy  # noqa: E402

#: the rules whose device or backend the two runs change
CHANGED = ("features_a", "match_a", "view_features", "view_matches", "depth_a", "depth_b")
RUNS = {
    "cpu": {"sfm": {"device": "cpu", "sift": "auto"}, "depth": {"backend": "planesweep"}},
    "colmap_depth": {"sfm": {"device": "cpu", "sift": "auto"}, "depth": {"backend": "colmap"}},
    "gpu_match": {"sfm": {"device": "cuda", "sift": "opencv"},
                  "depth": {"backend": "planesweep"}},
    "gpu_sift": {"sfm": {"device": "cuda", "sift": "auto"}, "depth": {"backend": "planesweep"}},
    "gpu": {"sfm": {"device": "cuda", "sift": "auto"}, "depth": {"backend": "colmap"}},
}


def depth_scores(results: Path, reg: str) -> dict:
    """Registration ``reg``'s depth maps of the array shots against the true depth of
    their reference views: valid share, share within 1 % of the truth and median
    relative error over the valid pixels. Registration A's maps are in SfM units: one
    scale (the median ratio over all its maps' valid pixels) brings them to metres."""
    pairs = []
    for info_path in sorted((results / "depth" / reg).glob("x*.json")):
        info = read_json(info_path)
        cam, view = info["reference"].split("/")
        truth = results / "ground_truth" / "depth" / cam / f"{view}.npy"
        if truth.is_file():
            pairs.append((read_npy(info_path.with_suffix(".npy")), read_npy(truth), info))
    if not pairs:
        return {}
    ratios = np.concatenate([gt[(d > 0) & (gt > 0)] / d[(d > 0) & (gt > 0)]
                             for d, gt, _ in pairs])
    scale = float(np.median(ratios)) if reg == "a" else 1.0
    have = valid = within = 0
    rel_all = []
    for d, gt, _ in pairs:
        h = gt > 0
        v = h & (d > 0)
        rel = np.abs(d[v] * scale - gt[v]) / gt[v]
        have += int(h.sum())
        valid += int(v.sum())
        within += int((rel <= 0.01).sum())
        rel_all.append(rel)
    return {"maps": len(pairs), "backend": pairs[0][2]["backend"],
            "valid_share": valid / max(have, 1), "within_1pct_share": within / max(have, 1),
            "median_rel_error": float(np.median(np.concatenate(rel_all))), "scale": scale}


def one_run(work: Path, config: dict, label: str, jobs: int, ds: str) -> dict:
    cfg = copy.deepcopy(config)
    for section, values in RUNS[label].items():
        cfg.setdefault(section, {}).update(values)
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    targets = [f"results/{ds}/eval/gt_errors.json", f"results/{ds}/matches/matches.json"]
    wall, _ = snakemake(work, *targets, jobs=jobs, log=work / f"snakemake_{label}.log")
    results = work / "results" / ds
    # the true depth of the depth maps' reference views (the ideal renders' rule)
    truth = []
    for info_path in sorted((results / "depth").glob("?/x*.json")):
        cam, view = read_json(info_path)["reference"].split("/")
        truth.append(f"results/{ds}/ground_truth/depth/{cam}/{view}.npy")
    if truth:
        snakemake(work, *sorted(set(truth)), jobs=jobs,
                  log=work / f"snakemake_{label}_truth.log")
    shutil.copytree(results / "logs", work / f"logs_{label}", dirs_exist_ok=True)
    checks = read_json(results / "eval" / "gt_errors.json")["checks"]
    rules = rule_benchmarks(work)
    return {"wall": wall, "rules": {r: rules[r] for r in CHANGED if r in rules},
            "checks": {c["name"]: c for c in checks},
            "depth": {reg: depth_scores(results, reg) for reg in ("a", "b")},
            "matches": read_json(results / "matches" / "matches.json")}


def report(runs: dict[str, dict], jobs: int) -> list[str]:
    labels = list(runs)
    out = [f"Same machine, same work folder, `snakemake -j{jobs}`, one run after the other: "
           f"{labels[0]} from scratch (simulation and conversion included), each later one "
           "reruns only what its settings change (" + "; ".join(
               f"{k}: sfm.device {RUNS[k]['sfm']['device']}, sfm.sift {RUNS[k]['sfm']['sift']}"
               f", depth.backend {RUNS[k]['depth']['backend']}" for k in labels) + ").", "",
           "| | " + " | ".join(labels) + " |", "|---|" + "---:|" * len(labels),
           "| wall s | " + " | ".join(f"{runs[k]['wall']:.1f}" for k in labels) + " |"]
    for rule in CHANGED:
        out.append(f"| {rule} job s | " + " | ".join(
            f"{runs[k]['rules'].get(rule, {'s': float('nan')})['s']:.1f}" for k in labels) + " |")
    out.append("| view pairs verified | " + " | ".join(
        f"{runs[k]['matches']['num_verified_pairs']} of {runs[k]['matches']['num_pairs']}"
        for k in labels) + " |")
    names = [n for n in runs[labels[0]]["checks"] if all(n in runs[k]["checks"] for k in labels)]
    for n in names:
        c = runs[labels[0]]["checks"][n]
        out.append(f"| {c['what']} ({c['unit']}, target {c['target']}) | " + " | ".join(
            f"{runs[k]['checks'][n]['value']:.4g}" + ("" if runs[k]['checks'][n]["pass"]
                                                       else " FAIL") for k in labels) + " |")
    for reg in ("a", "b"):
        for key, what in (("backend", "backend"), ("valid_share", "valid share"),
                          ("within_1pct_share", "within 1 % of the truth"),
                          ("median_rel_error", "median relative error")):
            vals = [runs[k]["depth"][reg].get(key, float("nan")) for k in labels]
            out.append(f"| depth {reg.upper()}: {what} | " + " | ".join(
                v if isinstance(v, str) else f"{v:.4f}" for v in vals) + " |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", help="also write the figures (markdown) to this file")
    ap.add_argument("--work", help="work folder (default: a new temporary one, removed at "
                                   "the end)")
    ap.add_argument("--runs", default=",".join(RUNS),
                    help=f"settings to run, in order (default: {','.join(RUNS)})")
    args = ap.parse_args()
    labels = args.runs.split(",")
    unknown = [label for label in labels if label not in RUNS]
    if unknown:  # before the copy of the workflow and the CUDA check
        ap.error(f"--runs {','.join(unknown)}: use some of {', '.join(RUNS)}")
    import cv2  # noqa: F401, PLC0415  (before pycolmap)

    from plenocal.gpu import cuda_available  # noqa: PLC0415

    ok, why = cuda_available()
    if not ok:
        sys.exit(f"bench_gpu: COLMAP's CUDA code cannot run here ({why}); see README, GPU")
    config = yaml.safe_load(Path(args.config).read_text())
    ds = next(iter(config["datasets"]))
    scratch = None if args.work else Path(tempfile.mkdtemp(prefix="plenocal-gpu-"))
    runs = {}
    try:
        work = make_copy(Path(args.work) if args.work else scratch, config)
        for label in labels:
            try:
                runs[label] = one_run(work, config, label, args.jobs, ds)
            except RuntimeError as err:  # a failed run is reported; the next ones still run
                print(f"{label}: FAILED\n{err}", flush=True)
                continue
            print(f"{label}: {runs[label]['wall']:.1f} s", flush=True)
            lines = report(runs, args.jobs)
            if args.out:
                Path(args.out).write_text("\n".join(lines) + "\n")
    finally:
        if scratch is not None:  # a full run's gigabytes, not kept where no --work asked
            shutil.rmtree(scratch, ignore_errors=True)
    print("\n".join(report(runs, args.jobs)) if runs else "bench_gpu: no run finished")


if __name__ == "__main__":
    main()
