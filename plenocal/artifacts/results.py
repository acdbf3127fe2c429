"""The evaluation results that the report reads (Section III of the paper), each with one
typed definition: its writing, its reading, a format name and version, and a clear
error for a file of another version (issue 16). What a file holds - the experiment, the
calibrations compared, the metric - is a field of the file, never parsed from its name.

* ``eval/reprojection.json`` - Table I (rule ``reprojection``): :class:`ReprojectionTable`
* ``eval/gt_errors.json`` - errors against ground truth (rule ``gt_errors``):
  :class:`GroundTruthErrors`
* ``eval/synthesis_exp<k>.json`` - the view-synthesis experiments of Figs. 6-9 (rules
  ``synthesis_exp1..3``): :class:`SynthesisResult`, with the PSNR tables of Figs. 7-9 and
  the synthesised images of Fig. 10
* ``convert/quality.json`` - the converted views against ideal renders (rule
  ``convert_quality``): :class:`ConvertQuality`
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from plenocal.artifacts.versioned import decode
from plenocal.io.files import atomic_write_bytes, read_npz, write_json

# ---------------------------------------------------------------------------
# Table I: eval/reprojection.json
# ---------------------------------------------------------------------------

TABLE1_FORMAT = "plenocal.table1"
TABLE1_VERSION = 1
#: the rows of Table I, in the paper's order (registration A, B, the complete calibration -
#: refined where the refinement ran, the paper's Eq. 6 result beside it -, the naive A+SfM
#: baseline), then SfM from scratch and the ground-truth cameras
TABLE1_ROWS = ("reg_a", "reg_b", "complete", "eq6", "baseline_sfm", "sfm_scratch",
               "ground_truth")


@dataclass(frozen=True)
class ReprojectionTable:
    """Table I: row (one of :data:`TABLE1_ROWS`) -> the figures of that calibration as
    :mod:`plenocal.verify.reprojection` computes them: ``mean_px``, ``median_px``,
    ``num_images``, ``num_observations``, ``num_array_images`` + ``num_handheld_images``,
    ``num_registered`` (the baseline), ``sets`` (registration B, one entry per N x N set);
    ``sfm_scratch`` has image, registration and model counts only."""

    rows: dict[str, dict]
    metric: str = "reprojection_error_px"  # per observation, after triangulation

    def __post_init__(self) -> None:
        unknown = sorted(set(self.rows) - set(TABLE1_ROWS))
        if unknown:
            raise ValueError(f"Table I: unknown rows {unknown}; the rows are "
                             f"{', '.join(TABLE1_ROWS)}")

    def to_dict(self) -> dict:
        return {"format": TABLE1_FORMAT, "version": TABLE1_VERSION, "metric": self.metric,
                "rows": {k: self.rows[k] for k in TABLE1_ROWS if k in self.rows}}


def write_reprojection_table(path: str | Path, table: ReprojectionTable) -> None:
    write_json(path, table.to_dict())


def read_reprojection_table(path: str | Path) -> ReprojectionTable:
    """Read ``eval/reprojection.json`` (this version only)."""
    return decode(path, TABLE1_FORMAT, TABLE1_VERSION, "Table I (reprojection.json)",
                  "run rule reprojection", lambda doc: ReprojectionTable(
                      rows={k: dict(v) for k, v in doc["rows"].items()},
                      metric=str(doc["metric"])))


# ---------------------------------------------------------------------------
# Errors against ground truth: eval/gt_errors.json
# ---------------------------------------------------------------------------

GT_ERRORS_FORMAT = "plenocal.gt_errors"
GT_ERRORS_VERSION = 1


@dataclass(frozen=True)
class Check:
    """One target of issues 4-5: ``value`` (None when its stage was not compared) <=
    ``target`` in ``unit``."""

    name: str
    what: str
    value: float | None
    target: float
    unit: str
    passed: bool | None

    def to_dict(self) -> dict:
        return {"name": self.name, "what": self.what, "value": self.value,
                "target": self.target, "unit": self.unit, "pass": self.passed}


@dataclass(frozen=True)
class GroundTruthErrors:
    """Every calibration stage against the simulator's ground truth, as
    :func:`plenocal.verify.gt_errors.gt_errors` computes it: the checks with their
    verdicts, and per stage (None when not compared) the figures behind them."""

    n_views: int
    checks: tuple[Check, ...]
    targets: dict  # check name -> {"limit", "unit", "what"}
    registration_a: dict | None = None
    registration_b: dict | None = None
    scale: dict | None = None
    complete: dict | None = None
    eq6: dict | None = None  # the paper's Eq. 6 result, where the refinement ran
    refinement: dict | None = None  # the refinement's scales against the truth
    sources: dict | None = None  # where the Eq. 6 result's error comes from

    def to_dict(self) -> dict:
        out = {"format": GT_ERRORS_FORMAT, "version": GT_ERRORS_VERSION,
               "n_views": self.n_views, "checks": [c.to_dict() for c in self.checks],
               "targets": self.targets}
        for name in _GT_STAGES:
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        return out

    @classmethod
    def from_dict(cls, doc: Mapping) -> GroundTruthErrors:
        """From the result of :func:`plenocal.verify.gt_errors.gt_errors` (or a read file)."""
        return cls(n_views=int(doc["n_views"]),
                   checks=tuple(Check(str(c["name"]), str(c["what"]),
                                      None if c["value"] is None else float(c["value"]),
                                      float(c["target"]), str(c["unit"]),
                                      None if c["pass"] is None else bool(c["pass"]))
                                for c in doc["checks"]),
                   targets=dict(doc["targets"]),
                   **{n: dict(doc[n]) for n in _GT_STAGES if doc.get(n) is not None})


_GT_STAGES = ("registration_a", "registration_b", "scale", "complete", "eq6",
              "refinement", "sources")


def write_gt_errors(path: str | Path, errors: GroundTruthErrors) -> None:
    write_json(path, errors.to_dict())


def read_gt_errors(path: str | Path) -> GroundTruthErrors:
    """Read ``eval/gt_errors.json`` (this version only)."""
    return decode(path, GT_ERRORS_FORMAT, GT_ERRORS_VERSION, "gt_errors.json",
                  "run rule gt_errors", GroundTruthErrors.from_dict)


# ---------------------------------------------------------------------------
# View synthesis: eval/synthesis_exp<k>.json
# ---------------------------------------------------------------------------

SYNTHESIS_FORMAT = "plenocal.synthesis"
#: 2: the figures that the PSNR tables hold are no longer repeated in a ``summary`` (they
#: are derived where they are read: :meth:`SynthesisResult.psnr_stats`,
#: :meth:`SynthesisResult.mean_db_lost`); what the tables do not hold is the typed ``setup``
SYNTHESIS_VERSION = 2
EXPERIMENTS = (1, 2, 3)
#: the camera sets a synthesis is rendered with (``ground_truth`` on synthetic data only)
CAMERA_SETS = ("complete", "ground_truth")
#: the depth maps it is rendered from: the project's, or the simulator's true depth
DEPTHS = ("estimated", "true")


@dataclass(frozen=True)
class PsnrTable:
    """One run of an experiment: the targets' PSNR [dB] against the captured views,
    synthesised from ``inputs`` by ``renderer`` with the ``depth`` maps and the
    ``cameras``. ``run``: "" (Exp. 1), the set's shot (Exp. 2), or the inputs of Exp. 3,
    ``central`` or ``lateral``. ``surface_psnr_db``: the PSNR over each target's surface
    pixels (:mod:`plenocal.verify.surface`; synthetic data, the targets with a true depth
    map, Exps. 1 and 2; absent from the file where empty)."""

    renderer: str  # dibr | rvs
    depth: str  # one of DEPTHS
    cameras: str  # one of CAMERA_SETS
    run: str
    inputs: tuple[str, ...]  # "<shot>/<view>"
    psnr_db: dict[str, float]  # target "<shot>/<view>" -> dB
    surface_psnr_db: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.depth not in DEPTHS or self.cameras not in CAMERA_SETS:
            raise ValueError(f"PSNR table: depth {self.depth!r} (use {', '.join(DEPTHS)}), "
                             f"cameras {self.cameras!r} (use {', '.join(CAMERA_SETS)})")

    @property
    def mean_db(self) -> float | None:
        return float(np.mean(list(self.psnr_db.values()))) if self.psnr_db else None

    def to_dict(self) -> dict:
        out = {"renderer": self.renderer, "depth": self.depth, "cameras": self.cameras,
               "run": self.run, "inputs": list(self.inputs), "psnr_db": self.psnr_db}
        if self.surface_psnr_db:
            out["surface_psnr_db"] = self.surface_psnr_db
        return out


@dataclass(frozen=True)
class PsnrStats:
    """The PSNR [dB] of a group of targets: mean, least, largest and how many."""

    mean_db: float
    min_db: float
    max_db: float
    count: int

    @classmethod
    def of(cls, tables: Iterable[PsnrTable]) -> PsnrStats | None:
        """Over every target of ``tables`` (None when they have none)."""
        vals = np.array([v for t in tables for v in t.psnr_db.values()], dtype=float)
        if len(vals) == 0:
            return None
        return cls(float(vals.mean()), float(vals.min()), float(vals.max()), int(len(vals)))


@dataclass(frozen=True)
class SynthImage:
    """A synthesised view kept for Fig. 10: ``path`` relative to the folder of the
    synthesis file, ``view`` ``"<shot>/<view>"``, ``cameras`` and ``run`` as in
    :class:`PsnrTable` (the primary renderer, the estimated depth)."""

    path: str
    view: str
    cameras: str
    run: str

    def to_dict(self) -> dict:
        return {"path": self.path, "view": self.view, "cameras": self.cameras, "run": self.run}


@dataclass(frozen=True)
class DepthQuality:
    """The depth maps an experiment renders from, against the simulator's true depth
    (:func:`plenocal.depth.quality.depth_quality`, one input view): the ground-truth
    pixels, the shares with an estimate and within ``tolerance`` (relative), and the
    median relative error of the estimates (None without any)."""

    pixels: int
    valid_share: float
    within_share: float
    within_of_valid: float
    median_rel_error: float | None
    tolerance: float

    def to_dict(self) -> dict:
        return {"pixels": self.pixels, "valid_share": self.valid_share,
                "within_share": self.within_share, "within_of_valid": self.within_of_valid,
                "median_rel_error": self.median_rel_error, "tolerance": self.tolerance}

    @classmethod
    def from_dict(cls, d: Mapping) -> DepthQuality:
        return cls(pixels=int(d["pixels"]), valid_share=float(d["valid_share"]),
                   within_share=float(d["within_share"]),
                   within_of_valid=float(d["within_of_valid"]),
                   median_rel_error=(None if d["median_rel_error"] is None
                                     else float(d["median_rel_error"])),
                   tolerance=float(d["tolerance"]))


@dataclass(frozen=True)
class SynthesisSetup:
    """What an experiment was run with that its PSNR tables do not hold: the depth range
    of the renders (metres), the border left out of the PSNR, how the depth maps were
    estimated, their quality against the true depth (``"<shot>/<view>"`` -> figures;
    empty without true depth) and Exp. 3's view stride (None for Exps. 1-2)."""

    near_m: float
    far_m: float
    psnr_border_px: int
    depth_method: str
    depth_quality: dict[str, DepthQuality]
    view_stride: int | None = None

    def to_dict(self) -> dict:
        return {"near_m": self.near_m, "far_m": self.far_m,
                "psnr_border_px": self.psnr_border_px, "depth_method": self.depth_method,
                "depth_quality": {k: q.to_dict() for k, q in sorted(self.depth_quality.items())},
                "view_stride": self.view_stride}

    @classmethod
    def from_dict(cls, d: Mapping) -> SynthesisSetup:
        return cls(near_m=float(d["near_m"]), far_m=float(d["far_m"]),
                   psnr_border_px=int(d["psnr_border_px"]), depth_method=str(d["depth_method"]),
                   depth_quality={k: DepthQuality.from_dict(q)
                                  for k, q in d["depth_quality"].items()},
                   view_stride=None if d["view_stride"] is None else int(d["view_stride"]))


@dataclass(frozen=True)
class SynthesisResult:
    """One view-synthesis experiment (Section III, Fig. 6): its PSNR tables, what it was
    run with (``setup``) and the images kept for Fig. 10. The figures per renderer,
    depth and camera set (means, the dB lost) are derived from the tables:
    :meth:`psnr_stats`, :meth:`mean_db_lost`, :meth:`db_lost`."""

    experiment: int
    renderer: str  # the primary renderer (verify.renderer)
    tables: tuple[PsnrTable, ...]
    setup: SynthesisSetup
    images: tuple[SynthImage, ...] = ()
    metric: str = "psnr_db"

    def __post_init__(self) -> None:
        if self.experiment not in EXPERIMENTS:
            raise ValueError(f"synthesis: no experiment {self.experiment} (1, 2 or 3)")

    @property
    def renderers(self) -> tuple[str, ...]:
        """The renderers of the tables, the primary one first."""
        others = dict.fromkeys(t.renderer for t in self.tables if t.renderer != self.renderer)
        return (self.renderer, *others)

    def part(self, table: PsnrTable) -> str:
        """The part of the experiment whose figures ``table`` counts in: Exp. 3's input
        choice (``central``, ``lateral``: two experiments in one); "" for Exp. 1 and for
        Exp. 2, whose sets are one experiment."""
        return table.run if self.experiment == 3 else ""

    def psnr_stats(self, renderer: str, depth: str, cameras: str) -> dict[str, PsnrStats]:
        """Part (:meth:`part`) -> the PSNR over its targets rendered by ``renderer`` from
        the ``depth`` maps with the ``cameras``; parts without targets are left out."""
        parts: dict[str, list[PsnrTable]] = {}
        for t in self.tables:
            if (t.renderer, t.depth, t.cameras) == (renderer, depth, cameras):
                parts.setdefault(self.part(t), []).append(t)
        out = {p: PsnrStats.of(ts) for p, ts in parts.items()}
        return {p: s for p, s in out.items() if s is not None}

    def mean_db_lost(self, renderer: str, ours: tuple[str, str], ref: tuple[str, str]
                     ) -> dict[str, float]:
        """Part -> the mean PSNR of ``ref`` minus that of ``ours`` (each a (depth, cameras)
        pair, the same renderer), each over its own targets, where both have targets:
        with ``ours`` = (estimated, complete) and ``ref`` = (estimated, ground_truth) the
        dB lost to calibration, with ``ref`` = (true, complete) the dB lost to depth.
        (:meth:`db_lost` compares the targets both tables scored, per run.)"""
        a = self.psnr_stats(renderer, *ours)
        b = self.psnr_stats(renderer, *ref)
        return {p: b[p].mean_db - a[p].mean_db for p in a if p in b}

    def db_lost(self) -> list[tuple[PsnrTable, PsnrTable, float, int]]:
        """(complete, ground truth, mean dB lost to calibration, views compared) for every
        table of the complete calibration whose twin with the ground-truth cameras (same
        renderer, depth and run) shares targets with it."""
        return self._lost("psnr_db")

    def surface_db_lost(self) -> list[tuple[PsnrTable, PsnrTable, float, int]]:
        """As :meth:`db_lost`, over the targets' surface pixels (``surface_psnr_db``):
        the dB lost to calibration without the renderer's per-pixel choices at occlusion
        edges (:mod:`plenocal.verify.surface`); tables without surface figures are left
        out."""
        return self._lost("surface_psnr_db")

    def _lost(self, field: str) -> list[tuple[PsnrTable, PsnrTable, float, int]]:
        """:meth:`db_lost` over the per-target PSNRs in the tables' attribute ``field``."""
        truth = {(t.renderer, t.depth, t.run): t for t in self.tables
                 if t.cameras == "ground_truth"}
        out = []
        for t in self.tables:
            g = truth.get((t.renderer, t.depth, t.run))
            if t.cameras != "complete" or g is None:
                continue
            ours, true = getattr(t, field), getattr(g, field)
            common = sorted(set(ours) & set(true))
            if common:
                out.append((t, g, float(np.mean([true[k] - ours[k] for k in common])),
                            len(common)))
        return out

    def to_dict(self) -> dict:
        return {"format": SYNTHESIS_FORMAT, "version": SYNTHESIS_VERSION,
                "experiment": self.experiment, "metric": self.metric,
                "renderer": self.renderer, "tables": [t.to_dict() for t in self.tables],
                "images": [i.to_dict() for i in self.images], "setup": self.setup.to_dict()}


def write_synthesis(path: str | Path, result: SynthesisResult) -> None:
    write_json(path, result.to_dict())


def read_synthesis(path: str | Path) -> SynthesisResult:
    """Read ``eval/synthesis_exp<k>.json`` (this version only)."""
    return decode(path, SYNTHESIS_FORMAT, SYNTHESIS_VERSION, "synthesis result",
                  "rerun rule synthesis_exp<k>", lambda doc: SynthesisResult(
                      experiment=int(doc["experiment"]), renderer=str(doc["renderer"]),
                      tables=tuple(PsnrTable(
                          str(t["renderer"]), str(t["depth"]), str(t["cameras"]),
                          str(t["run"]), tuple(t["inputs"]),
                          {k: float(v) for k, v in t["psnr_db"].items()},
                          {k: float(v) for k, v in t.get("surface_psnr_db", {}).items()})
                          for t in doc["tables"]),
                      setup=SynthesisSetup.from_dict(doc["setup"]),
                      images=tuple(SynthImage(str(i["path"]), str(i["view"]),
                                              str(i["cameras"]), str(i["run"]))
                                   for i in doc["images"]),
                      metric=str(doc["metric"])))


# ---------------------------------------------------------------------------
# One camera set's runs of an experiment: eval/synthesis_exp<k>/<cameras>.json + .npz
# ---------------------------------------------------------------------------

SYNTHESIS_RUNS_FORMAT = "plenocal.synthesis_runs"
SYNTHESIS_RUNS_VERSION = 2  # 2: the targets' errors per ring of pixels, in the .npz


@dataclass(frozen=True)
class SynthesisRuns:
    """Runs of one view-synthesis experiment before they become its result (rule
    synthesis_exp3_part, one per camera set; rule synthesis_exp3 joins them): each
    run's scores by (renderer, depth, cameras) as the experiment function returns them,
    and the synthesized images kept for the figures by (cameras, key)."""
    experiment: int
    renderers: tuple[str, ...]
    runs: dict[tuple[str, str, str], dict]
    kept: dict[tuple[str, str], np.ndarray]

    def joined(self, other: SynthesisRuns) -> SynthesisRuns:
        """Both parts' runs and images; they must be of one experiment and renderers, and
        share no run."""
        if (other.experiment, other.renderers) != (self.experiment, self.renderers):
            raise ValueError(f"synthesis runs of experiment {self.experiment} "
                             f"({', '.join(self.renderers)}) and {other.experiment} "
                             f"({', '.join(other.renderers)}) cannot be joined")
        both = sorted(set(self.runs) & set(other.runs))
        if both:
            raise ValueError(f"synthesis run {both[0]} is in two parts")
        return SynthesisRuns(self.experiment, self.renderers, {**self.runs, **other.runs},
                             {**self.kept, **other.kept})


def _arrays_out(obj: Any, arrays: dict[str, np.ndarray]) -> Any:
    """``obj`` with each array replaced by ``{"npz": "array<k>"}``, the array in
    ``arrays`` (exact bits: the JSON would round them)."""
    if isinstance(obj, np.ndarray):
        key = f"array{len(arrays)}"
        arrays[key] = obj
        return {"npz": key}
    if isinstance(obj, dict):
        return {k: _arrays_out(v, arrays) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_arrays_out(v, arrays) for v in obj]
    return obj


def _arrays_in(obj: Any, z: Mapping[str, np.ndarray]) -> Any:
    """:func:`_arrays_out` undone with the .npz ``z``."""
    if isinstance(obj, dict):
        if obj.keys() == {"npz"}:
            return z[obj["npz"]]
        return {k: _arrays_in(v, z) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_arrays_in(v, z) for v in obj]
    return obj


def write_synthesis_runs(json_path: str | Path, npz_path: str | Path,
                         runs: SynthesisRuns) -> None:
    """The runs as JSON (format plenocal.synthesis_runs) and, in an uncompressed .npz,
    their kept images (``image<i>`` in the JSON's ``kept`` order) and the arrays of the
    runs' results (the targets' errors per ring of pixels; ``{"npz": "array<k>"}`` in
    the JSON)."""
    kept = sorted(runs.kept)
    arrays: dict[str, np.ndarray] = {}
    doc = {
        "format": SYNTHESIS_RUNS_FORMAT, "version": SYNTHESIS_RUNS_VERSION,
        "experiment": runs.experiment, "renderers": list(runs.renderers),
        "runs": [{"renderer": r, "depth": d, "cameras": c, "result": _arrays_out(res, arrays)}
                 for (r, d, c), res in sorted(runs.runs.items())],
        "kept": [{"cameras": c, "key": k} for c, k in kept]}
    buf = io.BytesIO()
    np.savez(buf, **{f"image{i}": runs.kept[k] for i, k in enumerate(kept)}, **arrays)
    atomic_write_bytes(npz_path, buf.getvalue())
    write_json(json_path, doc)


def read_synthesis_runs(json_path: str | Path, npz_path: str | Path) -> SynthesisRuns:
    """Read what :func:`write_synthesis_runs` wrote (this version only)."""
    remedy = "rerun rule synthesis_exp3_part"

    def build(doc: dict) -> SynthesisRuns:
        z = read_npz(npz_path)
        kept = {(str(e["cameras"]), str(e["key"])): z[f"image{i}"]
                for i, e in enumerate(doc["kept"])}
        return SynthesisRuns(int(doc["experiment"]), tuple(doc["renderers"]),
                             {(str(r["renderer"]), str(r["depth"]), str(r["cameras"])):
                              _arrays_in(r["result"], z) for r in doc["runs"]}, kept)

    return decode(json_path, SYNTHESIS_RUNS_FORMAT, SYNTHESIS_RUNS_VERSION,
                  "synthesis runs", remedy, build)


# ---------------------------------------------------------------------------
# Converter quality: convert/quality.json
# ---------------------------------------------------------------------------

QUALITY_FORMAT = "plenocal.convert_quality"
QUALITY_VERSION = 1


@dataclass(frozen=True)
class ViewQuality:
    psnr_db: float
    ssim: float


@dataclass(frozen=True)
class ConvertQuality:
    """Every converted view against the simulator's ideal render, excluding a border, as
    :func:`plenocal.convert.quality.dataset_quality` computes it: per shot and view, the
    means (all views and the central views), the worst view and the verdict against the
    targets."""

    per_view: dict[str, dict[str, ViewQuality]]  # shot -> view -> quality
    border_px: int
    central_view: str
    mean_psnr_db: float | None
    mean_ssim: float | None
    mean_psnr_central_db: float | None
    mean_ssim_central: float | None
    min_psnr_db: float | None
    worst_view: str | None
    targets: dict  # figure -> the least it may be
    meets_targets: bool

    @property
    def views(self) -> int:
        return sum(len(v) for v in self.per_view.values())

    def to_dict(self) -> dict:
        return {"format": QUALITY_FORMAT, "version": QUALITY_VERSION,
                "per_view": {c: {v: {"psnr_db": q.psnr_db, "ssim": q.ssim}
                                 for v, q in views.items()}
                             for c, views in self.per_view.items()},
                "border_px": self.border_px, "central_view": self.central_view,
                "mean_psnr_db": self.mean_psnr_db, "mean_ssim": self.mean_ssim,
                "mean_psnr_central_db": self.mean_psnr_central_db,
                "mean_ssim_central": self.mean_ssim_central, "min_psnr_db": self.min_psnr_db,
                "worst_view": self.worst_view, "views": self.views, "targets": self.targets,
                "meets_targets": self.meets_targets}

    @classmethod
    def from_dict(cls, doc: Mapping) -> ConvertQuality:
        """From the result of :func:`plenocal.convert.quality.dataset_quality` (or a read
        file)."""
        def opt(key: str) -> float | None:
            return None if doc[key] is None else float(doc[key])

        return cls(per_view={c: {v: ViewQuality(float(q["psnr_db"]), float(q["ssim"]))
                                 for v, q in views.items()}
                             for c, views in doc["per_view"].items()},
                   border_px=int(doc["border_px"]), central_view=str(doc["central_view"]),
                   mean_psnr_db=opt("mean_psnr_db"), mean_ssim=opt("mean_ssim"),
                   mean_psnr_central_db=opt("mean_psnr_central_db"),
                   mean_ssim_central=opt("mean_ssim_central"), min_psnr_db=opt("min_psnr_db"),
                   worst_view=doc["worst_view"], targets=dict(doc["targets"]),
                   meets_targets=bool(doc["meets_targets"]))


def write_convert_quality(path: str | Path, quality: ConvertQuality) -> None:
    write_json(path, quality.to_dict())


def read_convert_quality(path: str | Path) -> ConvertQuality:
    """Read ``convert/quality.json`` (this version only)."""
    return decode(path, QUALITY_FORMAT, QUALITY_VERSION, "converter quality (quality.json)",
                  "run rule convert_quality", ConvertQuality.from_dict)
