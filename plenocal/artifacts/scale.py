"""``merge/scale.json``: the scale r between registrations A and B (Eq. 5), written by
rule ``scale`` and read by the merge (Eq. 6) and the ground-truth check.

The paper's ``r`` is the mean of the per-shot ratios ``r_i``; the file also holds the
robust estimates beside it (their median, the median of the per-shot median ratios),
the spread across shots and which estimate the merge uses (``scale.estimator``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

from plenocal.artifacts.versioned import decode
from plenocal.io.files import write_json

FORMAT = "plenocal.scale"
VERSION = 1
ESTIMATORS = ("mean", "median", "median_of_ratios")


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

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"scale.estimator = {self.estimator!r}: use one of "
                             f"{', '.join(ESTIMATORS)}")

    @property
    def r_used(self) -> float:
        return {"mean": self.r, "median": self.r_median,
                "median_of_ratios": self.r_median_of_ratios}[self.estimator]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["percentiles"] = list(self.percentiles)
        return {"format": FORMAT, "version": VERSION, **d, "r_used": self.r_used}


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
        percentiles=tuple(float(x) for x in doc["percentiles"]), method=str(doc["method"])))
