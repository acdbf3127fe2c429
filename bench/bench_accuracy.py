"""Accuracy over captures (issue 32): the calibration against the simulator's ground truth
for several seeds and at least two geometries, side by side, with the median and the worst.

A user brings one capture we never saw, so one seed's figure is an anecdote: this script
runs the workflow on every capture of a set and reports, per capture,

* the complete calibration (the refined one where ``refine`` runs, and the paper's Eq. 6
  result beside it): focal length, centres (mm and % of the array step), rotations, the
  written calibration's scale (what the verdict judges), the merge's r, Eq. 5's r and the
  stage's step's r;
* Table I on the same matches: the complete calibration, the paper's Eq. 6 result, the
  naive A+SfM and the ground-truth cameras (mean px, and the ratio to the ground truth's);
* the Exp. 1 PSNR with our own depth (the complete calibration, and the ground-truth
  cameras on depth estimated with them: verify.ground_truth_own_depth, set here; until
  188156d on the complete calibration's maps);
* where the paper's Eq. 6 result's error comes from (gt_errors' ``sources``: registration
  A's focal length and shot poses, the hand-held shots, the merge's scale and the rig),

then the median and the worst case of every column, and per geometry. ``--collect-only
--kept`` reads every capture kept of the geometries, whatever its seed (the union of the
sets run so far: BENCHMARKS.md, "Every kept capture"). The captures are kept in
``bench/out/accuracy/<geometry>-s<seed>/`` (one Snakemake working folder each, running the
repository's own Snakefile): a second run reruns only what changed. Snakemake does not see
a change inside the ``plenocal`` package (only in the rules and scripts), so after such a
change name the stages to run again, e.g. ``--forcerun refine``. The rules' scripts import
the ``plenocal`` package of the checkout that holds this script and its Snakefile, not the
one installed: a copy of the repository used for a run of its own must be brought to the
code to measure first (a stale copy's views came out bit for bit those of its own commit).
A setting is compared on the same captures with ``--set KEY=VALUE``: each capture is
cloned to ``<capture>-<label>`` (its files' times kept) and only what the change reaches
runs there.

Usage::

    python bench/bench_accuracy.py [--seeds 1 2 3 4 5] [--geometries default wide]
        [--forcerun RULE ...] [--collect-only [--kept]] [--no-exp1] [--out BENCHMARKS.md]
        [--set refine.tracks=both [--label both]]
"""

from __future__ import annotations

import argparse
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchmd import Lines, update_sections  # noqa: E402

from plenocal.config import deep_update  # noqa: E402
from plenocal.io.files import read_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out" / "accuracy"
DATASET = "synthetic"

#: The geometries: the default dataset of config.yaml, and one that differs in array size,
#: step, hand-held count and focus distance (fewer, wider-spaced shots, nearer focus).
GEOMETRIES = {
    "default": {},
    "wide": {
        "array": {"cols": 5, "rows": 2, "step_m": 0.015},
        "handheld": {"count": 5},
        "main_lens": {"focus_distance_m": 0.55},
    },
    # a third, on request: a larger array at a smaller step, more hand-held shots, far focus
    "dense": {
        "array": {"cols": 9, "rows": 3, "step_m": 0.008},
        "handheld": {"count": 9, "max_rotation_deg": 6},
        "main_lens": {"focus_distance_m": 0.65},
    },
    # a fourth: the default array with a Galilean MLA (upright micro images), as the real
    # Raytrix frames of shared/real/ read (README, "Converting real lenslet images")
    "galilean": {"mla": {"kind": "galilean"}},
}
# and the wide array with it (the two set different keys)
GEOMETRIES["wide-galilean"] = {**GEOMETRIES["wide"], **GEOMETRIES["galilean"]}
# a Raytrix-like camera on the default array: Galilean, three interleaved lens types
# (multi-focus), the grid turned by pi/2 and a small angle, as the real Raytrix frames'
# calib.xml files give it (0.0007 rad beside pi/2: README, "Converting real lenslet images")
GEOMETRIES["raytrix"] = {"mla": {"kind": "galilean", "lens_types": 3,
                                 "rotation_rad": 1.5707963 + 0.0007}}
# and the wide array with it
GEOMETRIES["wide-raytrix"] = {**GEOMETRIES["wide"], **GEOMETRIES["raytrix"]}
# Three more, defined after the code they measure and tuned on nothing (BENCHMARKS.md,
# "Three geometries no run had seen"): a longer main lens focused farther, on a scene
# farther away (a narrower view: less of the turns' information); a 3 x 3 array with four
# hand-held shots turned less; a 4 x 4 array with a Galilean MLA focused between the two
GEOMETRIES["tele"] = {
    "array": {"cols": 5, "rows": 3, "step_m": 0.02},
    "handheld": {"count": 6, "max_offset_m": 0.05},
    "main_lens": {"focal_length_mm": 50.0, "focus_distance_m": 1.0},
    "scene": {"near_m": 0.8, "far_m": 1.3},
}
GEOMETRIES["small"] = {
    "array": {"cols": 3, "rows": 3, "step_m": 0.012},
    "handheld": {"count": 4, "max_rotation_deg": 8},
    "main_lens": {"focus_distance_m": 0.5},
    "scene": {"near_m": 0.4, "far_m": 0.62},
}
# the small capture with four more hand-held shots: the same scene, array and first four
# hand-held poses (the hand-held poses are drawn in order from their own generator) and
# the same first four hand-held images; the array shots' sensor noise is drawn anew (each
# shot's noise is seeded by its place among the sorted shot names). How much of the small
# geometry's focal error more turned shots take away: a capture guideline
_SMALL_HAND = GEOMETRIES["small"]["handheld"]
GEOMETRIES["small-8hand"] = {**GEOMETRIES["small"], "handheld": {**_SMALL_HAND, "count": 8}}
# and with two more (six): between the two
GEOMETRIES["small-6hand"] = {**GEOMETRIES["small"], "handheld": {**_SMALL_HAND, "count": 6}}
# and its four hand-held shots turned twice as far (the same axes, offsets and draws: a
# shot's turn is max_rotation_deg times a drawn factor), the array shots' images the same
GEOMETRIES["small-turned"] = {**GEOMETRIES["small"], "handheld": {
    **_SMALL_HAND, "max_rotation_deg": 2 * _SMALL_HAND["max_rotation_deg"]}}
GEOMETRIES["square-galilean"] = {
    "array": {"cols": 4, "rows": 4, "step_m": 0.01},
    "handheld": {"count": 5, "max_rotation_deg": 9},
    "main_lens": {"focus_distance_m": 0.7},
    "scene": {"near_m": 0.55, "far_m": 0.9},
    "mla": {"kind": "galilean"},
}
# One more, defined after every setting was chosen and tuned on nothing (BENCHMARKS.md,
# "An eleventh geometry no run had seen"): a 2 x 4 array (taller than wide, no middle
# column), six hand-held shots, and a sensor as real ones are: shot noise, 12-bit data in
# 16-bit PNGs, and the main lens's natural vignetting (cos^4)
GEOMETRIES["tall"] = {
    "array": {"cols": 2, "rows": 4, "step_m": 0.016},
    "handheld": {"count": 6, "max_rotation_deg": 7},
    "main_lens": {"focus_distance_m": 0.6, "vignetting": {"cos4": True}},
    "scene": {"near_m": 0.45, "far_m": 0.85},
    "sensor": {"full_well_e": 20000, "bit_depth": 12},
}
# and a twelfth, the same way: the tele camera with a Raytrix-like MLA (three lens types,
# the grid turned), on a 4 x 3 array, with the real sensor's effects of tall and a lens
# barrel that clips the oblique bundles (mechanical vignetting at the sensor's edges)
GEOMETRIES["tele-raytrix"] = {
    **GEOMETRIES["tele"], "array": {"cols": 4, "rows": 3, "step_m": 0.02},
    "mla": GEOMETRIES["raytrix"]["mla"], "sensor": GEOMETRIES["tall"]["sensor"],
    "main_lens": {**GEOMETRIES["tele"]["main_lens"], "vignetting": {
        "stop_distance_mm": 20.0, "stop_diameter_scale": 1.2}},
}
# and a thirteenth, the same way (BENCHMARKS.md, "Held-out captures: seed 90 of five
# geometries, and a thirteenth geometry no run had seen"):
# a TSPC-like camera: one lens type, micro images more than twice the others' (300 um
# lenses, about 57 px, against 24 px: fewer, larger lenses, as on the TSPC frames of
# shared/real/), behind a wider main lens (25 mm) focused nearer, on a 4 x 2 array
GEOMETRIES["tspc-like"] = {
    "array": {"cols": 4, "rows": 2, "step_m": 0.012},
    "handheld": {"count": 6, "max_rotation_deg": 8},
    "main_lens": {"focal_length_mm": 25.0, "focus_distance_m": 0.45},
    "scene": {"near_m": 0.35, "far_m": 0.6},
    "mla": {"pitch_um": 300.0, "k": 4.0, "lens_types": 1},
}
DEFAULT_SEEDS = (1, 2, 3, 4, 5)
TARGETS = ("eval/gt_errors.json", "eval/reprojection.json", "eval/synthesis_exp1.json")

#: The issue's targets on the worst capture: (column, limit).
#: The scale judged is the written calibration's own (``residual_scale_pct``: the similarity
#: that fits it to the truth), as the focal length, centres and rotations are the written
#: calibration's; the merge's r (``scale_pct``, the paper's Eq. 6 result in
#: ``calibration/eq6/``) is a column of its own and a line after the verdict.
LIMITS = {"focal_pct": 0.1, "centre_mm": 0.1, "rot_deg": 0.02, "residual_scale_pct": 0.3}


def capture_config(geometry: str, seed: int, changes: dict | None = None) -> dict:
    """config.yaml with the default dataset's simulate block set to the geometry and seed,
    and ``changes`` (nested, as :func:`parse_changes` gives them) over the rest."""
    cfg = yaml.safe_load((ROOT / "config.yaml").read_text())
    (name, ds), = cfg["datasets"].items()
    sim = deep_update(ds["simulate"], GEOMETRIES[geometry])
    sim["seed"] = seed
    cfg["datasets"] = {DATASET: {**ds, "simulate": sim}}
    # Exp. 1's true-cameras column: those cameras on depth estimated with them
    cfg.setdefault("verify", {})["ground_truth_own_depth"] = True
    return deep_update(cfg, changes or {})


def parse_changes(items: list[str]) -> dict:
    """``--set`` items ``a.b.c=VALUE`` (a dotted config key, a YAML value) as one nested
    dict; the simulated dataset (``datasets``) is the geometry's and the seed's, not
    changed here."""
    out: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        parts = key.strip().split(".")
        if not sep or not all(parts):
            raise ValueError(f"--set {item!r}: give KEY=VALUE with a dotted config key, "
                             "e.g. refine.tracks=both")
        if parts[0] == "datasets":
            raise ValueError(f"--set {item!r}: the dataset is the geometry's and the seed's "
                             "(--geometries, --seeds)")
        node = out
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ValueError(f"--set {item!r}: {p} is set to a value above")
        node[parts[-1]] = yaml.safe_load(value)
    return out


def variant_label(items: list[str]) -> str:
    """The clones' folder suffix for ``--set`` items without ``--label``: the values
    joined (``refine.tracks=both`` -> ``tracks-both``)."""
    label = "_".join(f"{k.split('.')[-1]}-{v}" for k, _, v in (i.partition("=")
                                                                 for i in items))
    return re.sub(r"[^A-Za-z0-9_.-]+", "", label)


#: what a clone shares with its capture by hard links instead of copies (a default-geometry
#: capture's lenslet images and views are 0.8 of its 1.2 GB): the simulator's images and the
#: converted views, which a change after the conversion does not write. Snakemake removes a
#: job's old outputs before it runs, so a clone that does convert again writes files of
#: its own and leaves the capture's alone.
LINKED = ("data", f"results/{DATASET}/views")


def clone_capture(src: Path, dest: Path) -> None:
    """A copy of a capture's folder with its files' times (Snakemake then reruns only what
    the new config changes: the refinement and what reads the calibration), the folders of
    :data:`LINKED` hard-linked. Made in a hidden sibling folder and renamed to ``dest``
    when whole: a clone that fails part way (a full disk, an interrupt) leaves nothing, so
    the next run clones again instead of running Snakemake in half a capture (which would
    make the missing part again, from the conversion on)."""
    linked = [src / d for d in LINKED]
    part = dest.with_name(f".{dest.name}.partial")

    def copy(a: str, b: str) -> None:
        if any(Path(a).is_relative_to(d) for d in linked):
            os.link(a, b)
        else:
            shutil.copy2(a, b)

    shutil.rmtree(part, ignore_errors=True)  # a clone an earlier run left half made
    try:
        shutil.copytree(src, part, symlinks=True, copy_function=copy)
        for p in src.rglob("*"):
            q = part / p.relative_to(src)
            if q.is_dir() and not q.is_symlink():
                st = p.stat()
                os.utime(q, ns=(st.st_atime_ns, st.st_mtime_ns))
        shutil.rmtree(part / ".snakemake" / "locks", ignore_errors=True)
        part.rename(dest)
    except BaseException:
        shutil.rmtree(part, ignore_errors=True)
        raise


def run_capture(work: Path, cfg: dict, forcerun: list[str], jobs: int,
                triggers: list[str] | None = None, targets: tuple[str, ...] = TARGETS
                ) -> float:
    """Snakemake on the capture's ``targets`` in ``work``; the wall seconds."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    cmd = [sys.executable, "-m", "snakemake", f"-j{jobs}", "--snakefile", str(ROOT / "Snakefile"),
           "--directory", str(work), "--configfile", str(work / "config.yaml"),
           "--workflow-profile", "none", "--scheduler", "greedy",
           *(["--forcerun", *forcerun] if forcerun else []),
           *(["--rerun-triggers", *triggers] if triggers else []),
           "--", *(f"results/{DATASET}/{t}" for t in targets)]
    t0 = time.perf_counter()
    with open(work / "bench.log", "w") as log:
        proc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT)
    if proc.returncode != 0:
        raise RuntimeError(f"snakemake failed in {work}: see {work / 'bench.log'}")
    return time.perf_counter() - t0


def _json(work: Path, rel: str) -> dict:
    return read_json(work / "results" / DATASET / rel)


def _psnr(exp: dict, cameras: str, depth: str = "estimated") -> float | None:
    for t in exp["tables"]:
        if t["cameras"] == cameras and t["depth"] == depth and t["renderer"] == "dibr":
            vals = list(t["psnr_db"].values())
            return float(statistics.fmean(vals)) if vals else None
    return None


def _abs(v):
    return None if v is None else abs(float(v))


def current_exp1(work: Path) -> bool:
    """Whether the capture's Exp. 1 file is there and no older than its calibration (a
    capture re-measured with ``--no-exp1`` keeps an Exp. 1 of the cameras before)."""
    exp1 = work / "results" / DATASET / "eval" / "synthesis_exp1.json"
    cams = work / "results" / DATASET / "calibration" / "cameras.json"
    return exp1.is_file() and cams.is_file() and exp1.stat().st_mtime >= cams.stat().st_mtime


def measured(work: Path) -> bool:
    """Whether the capture in ``work`` has been measured (its ``eval/gt_errors.json``)."""
    return (work / "results" / DATASET / "eval" / "gt_errors.json").is_file()


def require_kept_capture(work: Path, needs: tuple[str, ...] = ("eval/gt_errors.json",),
                         remedy: str = "") -> Path:
    """``work`` where it holds a capture this script kept (its ``config.yaml``) with the
    files ``needs`` under ``results/<dataset>/``. Otherwise SystemExit naming the folder,
    what it lacks and the remedy (``remedy`` where the files are not this script's): the
    benches that read kept captures stopped on the first file they opened, with a remedy
    meant for a workflow run (rerun a rule)."""
    if not (work / "config.yaml").is_file():
        what = "no config.yaml" if work.is_dir() else "no such folder"
        raise SystemExit(f"{work}: not a kept capture of bench_accuracy.py ({what}): run "
                         "bench/bench_accuracy.py for it first (it keeps each capture in "
                         f"{OUT}/<geometry>-s<seed>)")
    files = [f"results/{DATASET}/{rel}" for rel in needs]
    missing = [rel for rel in files if not (work / rel).is_file()]
    if missing:
        exp1 = " (without --no-exp1: Exp. 1)" if "synthesis_exp1" in missing[0] else ""
        raise SystemExit(f"{work}: the capture has no {missing[0]} yet: "
                         + (remedy or f"run bench/bench_accuracy.py for it{exp1}"))
    return work


def kept_captures(geometries: list[str]) -> list[tuple[str, Path]]:
    """Every kept capture of ``geometries`` (``bench/out/accuracy/<geometry>-s<seed>`` with
    its ``gt_errors.json``), by geometry, then seed."""
    found = []
    for geom in geometries:
        pat = re.compile(rf"{re.escape(geom)}-s(\d+)")
        seeds = sorted(int(m.group(1)) for p in OUT.glob(f"{geom}-s*")
                       if (m := pat.fullmatch(p.name)) and measured(p))
        found += [(f"{geom}-s{s}", OUT / f"{geom}-s{s}") for s in seeds]
    return found


def collect(work: Path, exp1: bool = True) -> dict:
    """One capture's figures (the columns of the table); ``exp1``: with Exp. 1's (not
    with ``--no-exp1``, where a kept file may predate the calibration)."""
    gt, tab = _json(work, "eval/gt_errors.json"), _json(work, "eval/reprojection.json")
    exp1 = _json(work, "eval/synthesis_exp1.json") if exp1 else None
    a, c = gt["registration_a"], gt["complete"]
    rows = tab["rows"]
    step_mm = 1000.0 * a["array_step_m"]

    def table(name: str, key: str = "mean_px") -> float | None:
        row = rows.get(name)
        return None if row is None else row.get(key)

    out = {
        "focal_pct": abs(c["focal_err_pct"]["max"]),
        "focal_signed_pct": c.get("focal_err_signed_pct"),
        "centre_mm": c["centre_rmse_mm"],
        "centre_pct_step": 100.0 * c["centre_rmse_mm"] / step_mm,
        "rot_deg": c["rotation_err_deg"]["max"],
        "scale_pct": abs(gt["scale"]["err_pct"]),
        "eq5_scale_pct": _abs(gt["scale"].get("r_eq5_err_pct")),
        "step_scale_pct": _abs(gt["scale"].get("r_array_step_err_pct")),
        "residual_scale_pct": abs(c["residual_scale_err_pct"]),
        "table_complete": table("complete"),
        "table_naive": table("baseline_sfm"),
        # the naive SfM keeps the views it registered: its mean is over those alone
        "naive_views": table("baseline_sfm", "num_images"),
        "complete_views": table("complete", "num_images"),
        "table_truth": table("ground_truth"),
        "exp1_db": None if exp1 is None else _psnr(exp1, "complete"),
        "exp1_truth_cams_db": None if exp1 is None else _psnr(exp1, "ground_truth"),
        "a_focal_pct": abs(a["focal_err_pct"]),
    }
    eq6 = gt.get("eq6")
    if eq6 is not None:
        out.update({"eq6_focal_pct": abs(eq6["focal_err_pct"]["max"]),
                    "eq6_centre_mm": eq6["centre_rmse_mm"],
                    "eq6_rot_deg": eq6["rotation_err_deg"]["max"],
                    "table_eq6": table("eq6")})
    ref = gt.get("refined_scale")
    if ref is not None:
        out["refined_scale_pct"] = abs(ref["err_pct"])
    if "sources" in gt:
        out["sources"] = gt["sources"]
    rf = work / "results" / DATASET / "calibration" / "refine.json"
    if rf.is_file():
        out["refine"] = read_json(rf)
    out["refine_job"] = refine_job(work)
    return out


COLUMNS = [  # (key, header, format)
    ("focal_pct", "focal %", "{:.3f}"),
    ("focal_signed_pct", "signed", "{:+.3f}"),
    ("centre_mm", "centres mm", "{:.3f}"),
    ("centre_pct_step", "% step", "{:.2f}"),
    ("rot_deg", "rot. deg", "{:.4f}"),
    ("scale_pct", "merge r %", "{:.3f}"),  # the Eq. 6 result's scale (calibration/eq6/)
    # the written calibration's own scale (a similarity fitted to the truth): the merge's r,
    # or where refine.scale fits the stage's step to the refined array shots, that
    ("residual_scale_pct", "written scale %", "{:.3f}"),
    ("eq5_scale_pct", "Eq. 5 r %", "{:.3f}"),
    ("step_scale_pct", "step r %", "{:.3f}"),
    ("table_complete", "T.I complete", "{:.4f}"),
    ("table_eq6", "T.I Eq. 6", "{:.4f}"),
    ("table_naive", "T.I naive", "{:.4f}"),
    ("table_truth", "T.I truth", "{:.4f}"),
    ("exp1_db", "Exp.1 dB", "{:.2f}"),
    ("exp1_truth_cams_db", "Exp.1 true cams dB", "{:.2f}"),
]
EQ6_COLUMNS = [
    ("eq6_focal_pct", "focal %", "{:.3f}"),
    ("eq6_centre_mm", "centres mm", "{:.3f}"),
    ("eq6_rot_deg", "rot. deg", "{:.4f}"),
    ("a_focal_pct", "A focal %", "{:.3f}"),
]
#: columns where larger is better (the worst case is the smallest)
HIGHER_BETTER = {"exp1_db", "exp1_truth_cams_db"}
#: signed columns: the median keeps the sign (a lean shows), the worst is the largest in size
SIGNED = {"focal_signed_pct"}


def _fmt(fmt: str, v) -> str:
    return "-" if v is None else fmt.format(v)


def summary_rows(results: dict[str, dict], columns) -> list[str]:
    """A markdown table of ``columns`` with one row per capture, then median and worst."""
    keys = [k for k, _, _ in columns]
    lines = ["| capture | " + " | ".join(h for _, h, _ in columns) + " |",
             "|---|" + "---:|" * len(columns)]
    for name, r in results.items():
        lines.append(f"| {name} | " + " | ".join(_fmt(f, r.get(k)) for k, _, f in columns)
                     + " |")
    for label in ("median", "worst"):
        cells = []
        for k, f in zip(keys, [f for _, _, f in columns], strict=True):
            vals = [r[k] for r in results.values() if r.get(k) is not None]
            if not vals:
                cells.append("-")
            elif label == "median":
                cells.append(f.format(statistics.median(vals)))
            elif k in SIGNED:
                cells.append(f.format(max(vals, key=abs)))
            else:
                cells.append(f.format(min(vals) if k in HIGHER_BETTER else max(vals)))
        lines.append(f"| **{label}** | " + " | ".join(cells) + " |")
    return lines


def geometry_of(capture: str) -> str:
    """``wide-raytrix-s3`` -> ``wide-raytrix``."""
    return capture.rsplit("-s", 1)[0]


def geometry_rows(results: dict[str, dict]) -> list[str]:
    """Per geometry, then over every capture: how many, and median / worst of the focal
    length (with the signed errors' mean), centres, largest rotation and written scale, and
    how many captures are past each of :data:`LIMITS`."""
    groups: dict[str, list[dict]] = {}
    for name, r in results.items():
        groups.setdefault(geometry_of(name), []).append(r)
    if len(groups) > 1:
        groups["all"] = list(results.values())
    cols = [("focal_pct", "focal %", "{:.3f}"), ("centre_mm", "centres mm", "{:.3f}"),
            ("rot_deg", "rotation deg", "{:.4f}"),
            ("residual_scale_pct", "written scale %", "{:.3f}")]
    lines = ["| geometry | captures | " + " | ".join(f"{h} median / worst" for _, h, _ in cols)
             + " | signed focal mean % | past a target (focal / centres / rotation / scale) |",
             "|---|---:|" + "---|" * len(cols) + "---:|---|"]
    for geom, rs in groups.items():
        cells = []
        for k, _, f in cols:
            vals = [r[k] for r in rs]
            cells.append(f"{f.format(statistics.median(vals))} / {f.format(max(vals))}")
        signed = [r["focal_signed_pct"] for r in rs if r.get("focal_signed_pct") is not None]
        past = " / ".join(str(sum(r[k] > lim for r in rs)) for k, lim in LIMITS.items())
        label = f"**{geom}**" if geom == "all" else geom
        lines.append(f"| {label} | {len(rs)} | " + " | ".join(cells) + " | "
                     + _fmt("{:+.3f}", statistics.fmean(signed) if signed else None)
                     + f" | {past} |")
    return lines


def ratio_rows(results: dict[str, dict]) -> list[str]:
    """Table I's ratios: complete / ground truth and complete / naive per capture."""
    lines = ["| capture | complete / truth | Eq. 6 / truth | complete / naive |",
             "|---|---:|---:|---:|"]
    for name, r in results.items():
        t, c, n, e = (r.get(k) for k in ("table_truth", "table_complete", "table_naive",
                                          "table_eq6"))
        lines.append(f"| {name} | {_fmt('{:.4f}', c / t if c and t else None)} | "
                     f"{_fmt('{:.4f}', e / t if e and t else None)} | "
                     f"{_fmt('{:.4f}', c / n if c and n else None)}"
                     f"{_fewer_views(r)} |")
    return lines


def _fewer_views(r: dict) -> str:
    """Where the naive SfM registered fewer views than the calibration holds: its Table I
    mean is over those alone (the views it could not place are often the hard ones)."""
    nv, cv = r.get("naive_views"), r.get("complete_views")
    return f" (naive: {nv} of {cv} views)" if nv is not None and cv and nv < cv else ""


SOURCE_COLUMNS = [
    ("a_focal_pct", "A focal %", "{:+.3f}"),
    ("a_focal_std_pct", "its std %", "{:.3f}"),
    ("handheld_axis_mean_deg", "hand-held axes deg", "{:.1f}"),
    ("a_array_centre_mm", "A array centres mm", "{:.3f}"),
    ("a_hand_centre_mm", "A hand-held centres mm", "{:.3f}"),
    ("a_rot_deg", "A rot. deg", "{:.4f}"),
    ("scale_pct", "merge r %", "{:+.3f}"),  # the r Eq. 6 used: Eq. 5's or the step's
    ("only_a_poses_mm", "only A poses: centres mm", "{:.3f}"),
    ("only_scale_mm", "only scale: centres mm", "{:.3f}"),
    ("only_rig_mm", "only rig: centres mm", "{:.4f}"),
    ("dominant", "dominant", "{}"),
]


def source_rows(results: dict[str, dict]) -> list[str]:
    flat = {}
    for name, r in results.items():
        s = r.get("sources")
        if s is not None:
            ang = (s.get("handheld") or {}).get("axis_angle_deg") or {}
            flat[name] = {**s, "handheld_axis_mean_deg": ang.get("mean"),
                          "scale_pct": s.get("scale_pct")}
    if not flat:
        return ["(no error sources: gt_errors.json has no 'sources')"]
    lines = ["| capture | " + " | ".join(h for _, h, _ in SOURCE_COLUMNS) + " |",
             "|---|" + "---:|" * len(SOURCE_COLUMNS)]
    for name, s in flat.items():
        lines.append(f"| {name} | " + " | ".join(_fmt(f, s.get(k)) for k, _, f in SOURCE_COLUMNS)
                     + " |")
    return lines


def refined_sd_pct(r: dict) -> float | None:
    """The refined focal length's own standard deviation (%) that ``refine.json`` gives
    (``refine.focal_sd``), where the refinement was kept and gave one."""
    d = r.get("refine") or {}
    if not d.get("enabled") or d.get("rejected"):
        return None
    return ((d.get("focal_px") or {}).get("std") or {}).get("std_pct")


def sd_summary(results: dict[str, dict]) -> str | None:
    """How well the refined focal length's own deviation predicts its error against the
    truth: the errors over it, their RMS and largest, and how many lie within 2."""
    pairs = [(r.get("focal_signed_pct"), refined_sd_pct(r)) for r in results.values()]
    z = [err / sd for err, sd in pairs if sd and err is not None]
    if not z:
        return None
    rms = math.sqrt(statistics.fmean(v * v for v in z))
    return (f"The refined focal length's error over its own standard deviation "
            f"(`refine.json` `focal_px.std`): RMS {rms:.2f}, at most {max(map(abs, z)):.2f}, "
            f"{sum(abs(v) <= 2 for v in z)} of {len(z)} within 2.")


def refine_rows(results: dict[str, dict]) -> list[str]:
    """What rule ``refine`` did on each capture (``calibration/refine.json``): its gain in
    the median reprojection error of its observations, the largest shot shift against the
    limit, whether ``calibration/`` holds the refined cameras, and the refined focal
    length's own standard deviation with the error over it."""
    lines = ["| capture | median obs. error before / after px | gain % | largest shot shift "
             "mm (limit) | written | focal sd % | focal error / sd |",
             "|---|---:|---:|---:|---|---:|---:|"]
    for name, r in results.items():
        d = r.get("refine")
        if not d or not d.get("enabled"):
            lines.append(f"| {name} | - | - | - | Eq. 6 (refine off) | - | - |")
            continue
        g = d.get("gain") or {}
        sd = refined_sd_pct(r) if r.get("focal_signed_pct") is not None else None
        shifted = d.get("max_shift_mm") is not None and d["max_shift_mm"] > d["limit_mm"]
        written = ("refined" if not d.get("rejected") else
                   "Eq. 6 (a shot moved too far)" if shifted else "Eq. 6 (gain too small)")
        lines.append(f"| {name} | {_fmt('{:.4f}', g.get('median_before_px'))} / "
                     f"{_fmt('{:.4f}', g.get('median_after_px'))} | "
                     f"{_fmt('{:+.2f}', g.get('gain_pct'))} | "
                     f"{_fmt('{:.2f}', d.get('max_shift_mm'))} "
                     f"({_fmt('{:.2f}', d.get('limit_mm'))}) | {written} | "
                     f"{_fmt('{:.3f}', sd)} | "
                     f"{_fmt('{:+.2f}', r['focal_signed_pct'] / sd if sd else None)} |")
    return lines


def refine_job(work: Path) -> tuple[float, float] | None:
    """Rule ``refine``'s last benchmark record in a capture: (seconds, peak RSS MB)."""
    files = sorted((work / "results" / DATASET / "benchmarks" / "refine").glob("*"))
    if not files:
        return None
    last = files[-1].read_text().strip().splitlines()[-1].split("\t")
    return float(last[0]), float(last[2])


PAIRED = [("focal_signed_pct", "focal % signed", "{:+.3f}"), ("centre_mm", "centres mm",
                                                                 "{:.3f}"),
          ("rot_deg", "rot. deg", "{:.4f}"), ("residual_scale_pct", "scale %", "{:.3f}")]


def paired_rows(base: dict[str, dict], other: dict[str, dict], label: str) -> list[str]:
    """Each capture as kept against its ``label`` clone, side by side (``a -> b``): the
    complete calibration's focal length (signed), centres, largest rotation, written scale
    and the refine job's seconds and peak memory (its benchmark file: noisy where other
    runs shared the cores); then the median and the worst (in size) of each, and how many
    captures are past each of :data:`LIMITS`."""
    names = [n for n in base if n in other]
    lines = ["| capture | " + " | ".join(f"{h}: as kept -> {label}" for _, h, _ in PAIRED)
             + " | refine job s | refine job MB |", "|---|" + "---:|" * (len(PAIRED) + 2)]

    def cell(k: str, f: str, a: dict, b: dict) -> str:
        return f"{_fmt(f, a.get(k))} -> {_fmt(f, b.get(k))}"

    for n in names:
        jobs = [base[n].get("refine_job"), other[n].get("refine_job")]
        sec = " -> ".join(_fmt("{:.0f}", j and j[0]) for j in jobs)
        mb = " -> ".join(_fmt("{:.0f}", j and j[1]) for j in jobs)
        lines.append(f"| {n} | " + " | ".join(cell(k, f, base[n], other[n])
                                               for k, _, f in PAIRED) + f" | {sec} | {mb} |")
    for what in ("median", "worst"):
        cells = []
        for k, _, f in PAIRED:
            pair = []
            for src in (base, other):
                vals = [abs(src[n][k]) for n in names if src[n].get(k) is not None]
                v = (statistics.median(vals) if what == "median" else max(vals)) if vals \
                    else None
                pair.append(_fmt(f.replace("+", ""), v))
            cells.append(" -> ".join(pair))
        lines.append(f"| **{what}** (in size) | " + " | ".join(cells) + " | | |")
    keys = {"focal_pct": "focal", "centre_mm": "centres", "rot_deg": "rotation",
            "residual_scale_pct": "scale"}
    past = "; ".join(
        f"{keys[k]} {sum(base[n][k] > lim for n in names)} -> "
        f"{sum(other[n][k] > lim for n in names)}" for k, lim in LIMITS.items())
    lines += ["", f"Captures past a target ({len(names)} pairs), as kept -> {label}: {past}."]
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(DEFAULT_SEEDS))
    ap.add_argument("--geometries", nargs="+", default=["default", "wide"],
                    choices=sorted(GEOMETRIES))
    ap.add_argument("--forcerun", nargs="*", default=[],
                    help="rules to run again (after a change inside the plenocal package)")
    ap.add_argument("--triggers", nargs="*", default=None,
                    help="Snakemake's --rerun-triggers (e.g. mtime input: after a change "
                         "that moved no result, such as a new check in a script)")
    ap.add_argument("--collect-only", action="store_true",
                    help="read the kept captures' results without running Snakemake")
    ap.add_argument("--refine", action="store_true",
                    help="with the joint refinement on: each capture's folder is cloned to "
                         "<capture>-refine (only the refinement and what reads the "
                         "calibration run again); the table then holds the refined "
                         "calibration and the Eq. 6 result beside it")
    ap.add_argument("--no-exp1", action="store_true",
                    help="the calibration and Table I only, without Exp. 1's depth maps and "
                         "view synthesis (a third of a capture's time): to re-measure after "
                         "a change before the calibration; the Exp. 1 columns read '-'")
    ap.add_argument("--kept", action="store_true",
                    help="with --collect-only: every kept capture of the geometries, whatever "
                         "its seed (--seeds is not read); Exp. 1 where its file is as new as "
                         "the calibration")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a config change (dotted key, YAML value; repeatable), e.g. "
                         "refine.tracks=both: each capture is cloned to "
                         "<capture>-<label> and only what the change reaches runs again "
                         "there, the kept captures left as they are")
    ap.add_argument("--label", default=None,
                    help="with --set: the clones' suffix (default: the values, "
                         "e.g. tracks-both)")
    ap.add_argument("--paired", action="store_true",
                    help="with --collect-only and --set: each capture as kept against its "
                         "clone, side by side, in a section of its own")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=None, help="BENCHMARKS.md to update (its section)")
    args = ap.parse_args()
    if 0 in args.seeds:
        print("note: seed 0 is the default dataset's, the luckiest we know; it is not "
              "a capture the user brings", file=sys.stderr)
    if args.kept and not args.collect_only:
        ap.error("--kept reads the kept captures: give it with --collect-only")
    if args.refine:
        args.set.append("refine.enabled=true")
        args.label = args.label or "refine"
    try:
        changes = parse_changes(args.set)
    except ValueError as e:
        ap.error(str(e))
    label = (args.label or variant_label(args.set)) if args.set else None
    if args.paired and not (args.collect_only and label):
        ap.error("--paired reads kept captures against their clones: give it with "
                 "--collect-only and --set")
    if args.kept and label:
        ap.error("--kept reads the captures as kept, not their clones (--set, --refine)")
    results: dict[str, dict] = {}
    kept: dict[str, dict] = {}  # --paired: the captures as kept
    walls: dict[str, float] = {}
    if args.kept:
        captures = kept_captures(args.geometries)
        if not captures:
            raise SystemExit(f"no kept captures of {', '.join(args.geometries)} under {OUT}")
        for name, work in captures:
            results[name] = collect(work, exp1=not args.no_exp1 and current_exp1(work))
    for geom in [] if args.kept else args.geometries:
        for seed in args.seeds:
            name = f"{geom}-s{seed}"
            work = OUT / name
            if label:
                base, work = work, OUT / f"{name}-{label}"
                if not work.exists() and base.exists() and not args.collect_only:
                    clone_capture(base, work)
            if not args.collect_only:
                print(f"[{time.strftime('%H:%M:%S')}] {name}: running ...", flush=True)
                walls[name] = run_capture(work, capture_config(geom, seed, changes),
                                          args.forcerun, args.jobs, args.triggers,
                                          TARGETS[:2] if args.no_exp1 else TARGETS)
            if args.collect_only and not measured(work):
                print(f"  {work.name}: not measured yet (no eval/gt_errors.json): left out",
                      file=sys.stderr)
                continue
            results[name] = collect(work, exp1=not args.no_exp1)
            if args.paired and measured(base):
                kept[name] = collect(base, exp1=False)
            print(f"  {name}: " + ", ".join(f"{k} {_fmt(f, results[name].get(k))}"
                                            for k, _, f in COLUMNS[:7]), flush=True)
    if not results:
        sys.exit("bench_accuracy: no capture measured: none of "
                 + ("the kept captures" if args.kept else
                    f"seeds {' '.join(map(str, args.seeds))}")
                 + f" of {' '.join(args.geometries)} has eval/gt_errors.json under {OUT} "
                 "(run without --collect-only to make them, or give --seeds / --kept)")
    out = Lines()
    which = ("every kept capture" if args.kept else
             f"seeds {', '.join(map(str, args.seeds))}")
    out.say(f"Captures: {which} of geometries {', '.join(args.geometries)} "
            f"(bench/bench_accuracy.py; {len(results)} captures). "
            "The complete calibration against the simulator's ground truth (rigid "
            "alignment, gt_errors), Table I's mean px on the same matches, Exp. 1's mean "
            "PSNR with our own depth.")
    out.say("")
    out.say("By geometry (the targets: " + ", ".join(
        f"{k} {lim}" for k, lim in LIMITS.items()) + "):")
    out.say("")
    for line in geometry_rows(results):
        out.say(line)
    out.say("")
    out.say("Per capture:")
    out.say("")
    for line in summary_rows(results, COLUMNS):
        out.say(line)
    if any("eq6_focal_pct" in r for r in results.values()):
        out.say("")
        out.say("The paper's method alone (Eq. 6, `calibration/eq6/`), and registration A's "
                "focal length:")
        out.say("")
        for line in summary_rows(results, EQ6_COLUMNS):
            out.say(line)
    out.say("")
    out.say("The joint refinement (rule `refine`), per capture:")
    out.say("")
    for line in refine_rows(results):
        out.say(line)
    summary = sd_summary(results)
    if summary:
        out.say("")
        out.say(summary)
    out.say("")
    out.say("Table I, ratios:")
    out.say("")
    for line in ratio_rows(results):
        out.say(line)
    out.say("")
    out.say("Where the Eq. 6 result's error comes from (gt_errors `sources`):")
    out.say("")
    for line in source_rows(results):
        out.say(line)
    worst = {k: max(r[k] for r in results.values()) for k in LIMITS}
    out.say("")
    out.say("Targets on the worst capture: " + "; ".join(
        f"{k} {worst[k]:.4g} (<= {lim}: {'pass' if worst[k] <= lim else 'FAIL'})"
        for k, lim in LIMITS.items()))
    merge_r = [r["scale_pct"] for r in results.values() if r.get("scale_pct") is not None]
    if merge_r:
        lim = LIMITS["residual_scale_pct"]
        out.say(f"The paper's Eq. 6 alone (`calibration/eq6/`): the merge's r at most "
                f"{max(merge_r):.4g} % off, {sum(v > lim for v in merge_r)} of {len(merge_r)} "
                f"captures past {lim} % (not the verdict: the written calibration's scale is).")
    if walls:
        out.say("")
        out.say("Wall time per capture (s, what had to run): " + ", ".join(
            f"{k} {v:.0f}" for k, v in walls.items()))
    sections = {}
    if args.paired:
        pair = Lines()
        pair.say(f"Seeds {', '.join(map(str, args.seeds))} of geometries "
                 f"{', '.join(args.geometries)}, each capture as kept (config.yaml) -> its "
                 f"clone with {', '.join(args.set)} (bench/bench_accuracy.py --collect-only "
                 "--paired); the complete calibration against the simulator's truth:")
        pair.say("")
        for line in paired_rows(kept, results, label):
            pair.say(line)
        sections[f"Paired: {', '.join(args.set)} (issue 32)"] = list(pair)
    if args.out:
        title = ("Every kept capture" if args.kept else "Accuracy over captures"
                 + (f", {', '.join(args.set)}" if args.set else ""))
        update_sections(args.out, {f"{title} (issue 32)": list(out), **sections})


if __name__ == "__main__":
    main()
