"""``merge/scale.json``: the scale r between registrations A and B (Eq. 5), written by
rule ``scale`` and read by the merge (Eq. 6) and the ground-truth check.

The paper's ``r`` is the mean of the per-shot ratios ``r_i``; the file also holds the
robust estimates beside it (their median, the median of the per-shot median ratios),
the spread across shots and which estimate the merge uses (``scale.estimator``).

Beyond the paper, where the datasheet gives the stage's step between array shots, the
scale that step gives (``r_array_step``: the step over registration A's array spacing,
:func:`plenocal.calib.scale.array_step_scale`) is held beside Eq. 5's, and ``chosen``
says which of the two the merge uses (``scale.reference``); the two are compared, and a
disagreement is a warning (``warnings``) that reaches the report's first screen.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

from plenocal.artifacts.versioned import decode
from plenocal.io.files import write_json

FORMAT = "plenocal.scale"
VERSION = 1
ESTIMATORS = ("mean", "median", "median_of_ratios")
#: where the scale the merge uses comes from: Eq. 5, or the stage's step
SOURCES = ("eq5", "array_step")


@dataclass(frozen=True)
class ScaleResult:
    """Eq. 5 over the shots; ``r_used`` is what the merge multiplies registration B by."""

    r: float  # mean of r_i (the paper)
    r_median: float  # median of r_i
    r_median_of_ratios: float  # median over shots of each shot's median ratio d_B / d_A
    estimator: str  # which of the three the merge uses
    r_i: dict[str, float] = field(default_factory=dict)
    r_i_median_of_ratios: dict[str, float] = field(default_factory=dict)
    n_pixels: dict[str, int] = field(default_factory=dict)
    spread: dict = field(default_factory=dict)  # std, min, max, relative, n_shots of r_i
    percentiles: tuple[float, float] = (10.0, 90.0)
    method: str = "Eq. 5: mean of d_B/d_A over pixels valid in both maps"
    chosen: str = "eq5"  # which scale the merge uses (SOURCES)
    r_array_step: float | None = None  # the stage's step over A's array spacing
    array_step: dict = field(default_factory=dict)  # the lattice fit behind it
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"scale.estimator = {self.estimator!r}: use one of "
                             f"{', '.join(ESTIMATORS)}")
        if self.chosen not in SOURCES:
            raise ValueError(f"scale source {self.chosen!r}: use one of {', '.join(SOURCES)}")
        if self.chosen == "array_step" and not self.r_array_step:
            raise ValueError("the scale from the stage's step was chosen but not measured")

    @property
    def r_eq5(self) -> float:
        """Eq. 5's r by the chosen estimator."""
        return {"mean": self.r, "median": self.r_median,
                "median_of_ratios": self.r_median_of_ratios}[self.estimator]

    @property
    def r_used(self) -> float:
        return float(self.r_array_step) if self.chosen == "array_step" else self.r_eq5

    def to_dict(self) -> dict:
        d = asdict(self)
        d["percentiles"] = list(self.percentiles)
        d["warnings"] = list(self.warnings)
        return {"format": FORMAT, "version": VERSION, **d, "r_eq5": self.r_eq5,
                "r_used": self.r_used}


def write_scale(path: str | Path, result: ScaleResult) -> None:
    write_json(path, result.to_dict())


def read_scale(path: str | Path) -> ScaleResult:
    """Read ``scale.json`` (this version only)."""
    return decode(path, FORMAT, VERSION, "scale.json", "run rule scale", lambda doc: ScaleResult(
        r=float(doc["r"]), r_median=float(doc["r_median"]),
        r_median_of_ratios=float(doc["r_median_of_ratios"]), estimator=doc["estimator"],
        r_i={k: float(v) for k, v in doc["r_i"].items()},
        r_i_median_of_ratios={k: float(v) for k, v in doc["r_i_median_of_ratios"].items()},
        n_pixels={k: int(v) for k, v in doc["n_pixels"].items()}, spread=dict(doc["spread"]),
        percentiles=tuple(float(x) for x in doc["percentiles"]), method=str(doc["method"]),
        chosen=str(doc.get("chosen") or SOURCES[0]),
        r_array_step=None if doc.get("r_array_step") is None else float(doc["r_array_step"]),
        array_step=dict(doc.get("array_step") or {}),
        warnings=tuple(doc.get("warnings") or ())))
