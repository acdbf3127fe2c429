"""Helpers shared by every rule file: config validation, the shot and view lists,
paths, and per-stage config slices (passed as ``params`` so that a change of one
stage's settings reruns that stage and what depends on it, nothing else)."""

import re
from pathlib import Path

from plenocal.config import ConfigError, validate_config
from plenocal.viewgeom import central_view, view_names

try:
    validate_config(config, Path(workflow.basedir) / "config.schema.yaml")
except ConfigError as err:
    raise ValueError(str(err)) from None

DATASETS = sorted(config["datasets"])
SYNTHETIC = [d for d in DATASETS if "simulate" in config["datasets"][d]]
CAM_RE = re.compile(r"^(x\d{2}_y\d{2}|hand\d{2})$")


wildcard_constraints:
    dataset="|".join(re.escape(d) for d in DATASETS),
    cam=r"x\d{2}_y\d{2}|hand\d{2}",
    view=r"\d+_\d+",


def ds_config(dataset):
    return config["datasets"][dataset]


def is_synthetic(dataset):
    return dataset in SYNTHETIC


def array_cams(dataset):
    """Array shots x{col:02d}_y{row:02d}, row-major."""
    sim = ds_config(dataset).get("simulate")
    if sim is not None:
        a = sim["array"]
        return [f"x{c:02d}_y{r:02d}" for r in range(a["rows"]) for c in range(a["cols"])]
    return [c for c in real_cams(dataset) if c.startswith("x")]


def hand_cams(dataset):
    sim = ds_config(dataset).get("simulate")
    if sim is not None:
        return [f"hand{k:02d}" for k in range(sim["handheld"]["count"])]
    return [c for c in real_cams(dataset) if c.startswith("hand")]


def real_cams(dataset):
    folder = Path("data") / dataset / "lenslet"
    if not folder.is_dir():
        raise ValueError(
            f"dataset {dataset!r}: {folder}/ does not exist; put the lenslet images "
            "there (x00_y00.png ... and hand00.png ...) or give the dataset a "
            "'simulate' block"
        )
    names = sorted(p.stem for p in folder.glob("*.png"))
    bad = [n for n in names if not CAM_RE.match(n)]
    if bad:
        raise ValueError(
            f"dataset {dataset!r}: lenslet images must be named x<col>_y<row>.png or "
            f"hand<k>.png with two-digit numbers; cannot use {', '.join(bad)}"
        )
    return names


def cams(dataset):
    return array_cams(dataset) + hand_cams(dataset)


def n_views(dataset):
    return ds_config(dataset)["views"]


def views(dataset):
    return view_names(n_views(dataset))


def centre(dataset):
    return central_view(n_views(dataset))


def full_set_cam(dataset):
    """The shot whose complete N x N ground truth is rendered: the array's middle."""
    a = array_cams(dataset)
    return a[len(a) // 2]


def data(dataset, *parts):
    return str(Path("data", dataset, *parts))


def res(dataset, *parts):
    return str(Path("results", dataset, *parts))


def log_path(rule, name="{dataset}"):
    return f"results/{{dataset}}/logs/{rule}/{name}.log"


def bench_path(rule, name="{dataset}"):
    return f"results/{{dataset}}/benchmarks/{rule}/{name}.tsv"


def stage_config(name):
    return config[name]


# The targets of `rule all`: each stage adds its final outputs once it is real.
TARGETS = []


def final_targets():
    out = []
    for d in DATASETS:
        for fn in TARGETS:
            out.extend(fn(d))
    return out
