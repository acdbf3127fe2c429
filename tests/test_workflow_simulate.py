"""The workflow on the tiny config through `simulate` and `ground_truth`, from a clean
directory, twice: the same seed gives byte-identical files."""

from __future__ import annotations

import copy
import hashlib
import re
import subprocess
from pathlib import Path

import pytest
import yaml
from conftest import snakemake, tiny_workflow


def array_shots(work: Path) -> list[str]:
    a = yaml.safe_load((work / "config.yaml").read_text())["datasets"]["tiny"]["simulate"]["array"]
    return [f"x{c:02d}_y{r:02d}" for r in range(a["rows"]) for c in range(a["cols"])]


def targets(work: Path) -> list[str]:
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    sim = cfg["datasets"]["tiny"]["simulate"]
    cams = array_shots(work) + [f"hand{k:02d}" for k in range(sim["handheld"]["count"])]
    full = array_shots(work)[len(array_shots(work)) // 2]  # the full-set shot
    out = [f"data/tiny/lenslet/{c}.png" for c in cams]
    out += ["results/tiny/ground_truth/cameras.json",
            "results/tiny/ground_truth/renders/x01_y00/0_0.png",
            "results/tiny/ground_truth/renders/hand00/1_1.png",
            f"results/tiny/ground_truth/renders/{full}/0_0.png"]
    return out


def run(work: Path, *args: str) -> subprocess.CompletedProcess:
    return snakemake(work, *args, timeout=900)


def digest(work: Path) -> dict[str, str]:
    out = {}
    for base in ("data", "results"):
        for p in sorted((work / base).rglob("*")):
            rel = p.relative_to(work)
            if p.is_file() and "logs" not in rel.parts and "benchmarks" not in rel.parts:
                out[str(rel)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def differences(a: Path, b: Path, da: dict[str, str], db: dict[str, str]) -> list[str]:
    """What differs between two runs' files, for the failure message: a file on one side
    only, or for an image or array that differs, whether its decoded values differ too and
    by how much (bytes alone would point at the encoder, a few values at floating-point
    rounding, many at the inputs)."""
    import numpy as np  # noqa: PLC0415

    from plenocal.io.files import read_image  # noqa: PLC0415

    out = []
    for rel in sorted(set(da) | set(db)):
        if da.get(rel) == db.get(rel):
            continue
        if rel not in da or rel not in db:
            out.append(f"{rel}: only in run {'b' if rel not in da else 'a'}")
            continue
        load = read_image if rel.endswith(".png") else np.load if rel.endswith(".npy") else None
        if load is None:
            out.append(f"{rel}: the bytes differ")
            continue
        x, y = load(a / rel), load(b / rel)
        if x.shape != y.shape:
            out.append(f"{rel}: shapes {x.shape} / {y.shape}")
            continue
        d = np.abs(x.astype(np.float64) - y.astype(np.float64))
        where = np.argwhere(d > 0)
        at = f", first at {tuple(int(i) for i in where[0])}" if len(where) else " (bytes only)"
        out.append(f"{rel}: {len(where)} of {d.size} values differ, by at most {d.max():g}{at}")
    return out


@pytest.mark.workflow
def test_simulate_from_clean_directory_is_reproducible(tmp_path: Path):
    a = tiny_workflow(tmp_path / "a")
    b = tiny_workflow(tmp_path / "b")
    for work in (a, b):
        proc = run(work, *targets(work))
        assert proc.returncode == 0, proc.stderr[-3000:]
    da, db = digest(a), digest(b)
    assert len(da) >= 10 + 3 + 5
    assert da == db, "\n".join(differences(a, b, da, db))
    # the log of a long step says what it did, shot by shot (one job traces them all)
    log = (a / "results/tiny/logs/simulate/tiny.log").read_text()
    for cam in array_shots(a) + ["hand00"]:
        assert f"{cam}: tracing" in log and f"{cam}: done" in log, cam
    # the full-set shot's other views come from one job (rule ground_truth_render_set),
    # other single views from rule ground_truth_render
    full = array_shots(a)[len(array_shots(a)) // 2]
    log = (a / f"results/tiny/logs/ground_truth_render_set/{full}.log").read_text()
    assert f"{full}/0_0:" in log and f"{full}/2_2:" in log and f"{full}/1_1:" not in log
    assert (a / "results/tiny/logs/ground_truth_render/x01_y00_0_0.log").exists()
    # and the central view of every shot from one job (rule ground_truth_render_central)
    log = (a / "results/tiny/logs/ground_truth_render_central/tiny.log").read_text()
    assert all(f"{c}/1_1:" in log for c in array_shots(a))
    assert not (a / "results/tiny/logs/ground_truth_render/x01_y00_1_1.log").exists()
    # and nothing is left to do
    proc = run(a, "-n", *targets(a))
    assert "Nothing to be done" in proc.stdout + proc.stderr


@pytest.mark.workflow
def test_bad_config_stops_before_any_job(tmp_path: Path):
    work = tiny_workflow(tmp_path / "w")
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg["datasets"]["tiny"]["views"] = 4
    (work / "config.yaml").write_text(yaml.safe_dump(cfg))
    proc = run(work, "-n")
    assert proc.returncode != 0
    assert "datasets.tiny.views = 4: must be an odd number" in proc.stdout + proc.stderr
    assert not (work / "results").exists() and not (work / "data").exists()


def _planned_priorities(out: str) -> dict[str, set[int]]:
    """rule (with its calib wildcard for reprojection_calib) -> the priorities of its
    planned jobs, from a dry run's job list (a job without a priority line has 0)."""
    prios: dict[str, set[int]] = {}
    for block in re.split(r"\n(?=(?:local)?rule \w+:)", out):
        m = re.match(r"(?:local)?rule (\w+):", block)
        if not m:
            continue
        name = re.sub(r"_\d+$", "", m.group(1))  # view_features_0, depth_b_1, ... by step
        calib = re.search(r"wildcards: .*calib=(\w+)", block)
        if calib:
            name += f"[{calib.group(1)}]"
        p = re.search(r"^\s+priority: (\d+)", block, flags=re.M)
        prios.setdefault(name, set()).add(int(p.group(1)) if p else 0)
    return prios


@pytest.mark.workflow
def test_critical_chain_goes_first(tmp_path: Path):
    """The longest chain of the run (simulate -> convert -> registration A and
    view_features -> view_matches -> baseline_sfm -> its Table I row) is scheduled
    first, then the views and their SIFT that view_matches waits for, then the
    calibration (B, depth, scale, merge), then the synthesis (ground-truth renders,
    synthesis depth, the experiments), then what can wait (the other Table I rows, the
    hand-held shots' depth maps): rules/common.smk PRIORITY."""
    work = tiny_workflow(tmp_path / "w")
    proc = run(work, "-n")
    assert proc.returncode == 0, proc.stderr[-3000:]
    prios = _planned_priorities(proc.stdout + proc.stderr)
    levels = {
        # the lenslet images (one job, every core) with the chain
        20: ["simulate", "convert_setup", "convert", "features_a", "match_a", "map_a",
             "view_matches", "baseline_sfm", "reprojection_calib[baseline_sfm]"],
        # the views other than the central ones and their SIFT, beside registration A
        18: ["convert_views", "view_features"],
        # the calibration, beside the COLMAP jobs
        16: ["rig_b", "depth_a", "depth_b", "scale", "merge"],
        # then the synthesis (its depth maps, the ideal renders, the experiments) ...
        5: ["ground_truth_render", "ground_truth_render_central", "depth_view",
            "synthesis_exp3_part", "synthesis_exp3"],
        # ... and last what only feeds short jobs
        0: ["reprojection_complete", "depth_a_other", "depth_b_other",
            "convert_quality"],
    }
    for level, rules in levels.items():
        for rule in rules:
            assert prios.get(rule) == {level}, (rule, prios.get(rule))


def _planned_gpus(out: str) -> dict[str, set[int]]:
    """rule (by step) -> the ``gpu`` resource of its planned jobs in a dry run."""
    gpus: dict[str, set[int]] = {}
    for block in re.split(r"\n(?=(?:local)?rule \w+:)", out):
        m = re.match(r"(?:local)?rule (\w+):", block)
        if m:
            g = re.search(r"^\s+resources: .*\bgpu=(\d+)", block, flags=re.M)
            gpus.setdefault(re.sub(r"_\d+$", "", m.group(1)), set()).add(
                int(g.group(1)) if g else 0)
    return gpus


@pytest.mark.workflow
def test_gpu_jobs_ask_for_a_gpu_only_where_the_config_names_cuda(tmp_path: Path):
    """``sfm.device: cuda`` and ``depth.backend: colmap`` give COLMAP's SIFT, matching
    and depth jobs one GPU each (a cluster sends them to a GPU node) and no other job;
    the default ``auto`` asks for none (it takes a GPU only where a job finds one)."""
    work = tiny_workflow(tmp_path / "w")
    gpu_rules = {"features_a", "match_a", "match_central", "view_features", "view_matches",
                 "depth_a", "depth_b", "depth_a_other", "depth_b_other"}
    proc = run(work, "-n", "--config", 'sfm={"device": "cuda"}', 'depth={"backend": "colmap"}')
    assert proc.returncode == 0, proc.stderr[-3000:]
    gpus = _planned_gpus(proc.stdout + proc.stderr)
    assert gpu_rules <= set(gpus), sorted(gpus)
    for rule, seen in gpus.items():
        assert seen == ({1} if rule in gpu_rules else {0}), (rule, seen)
    proc = run(work, "-n")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert set().union(*_planned_gpus(proc.stdout + proc.stderr).values()) == {0}


@pytest.mark.workflow
def test_two_datasets_each_get_their_own_rules(tmp_path: Path):
    """Two synthetic datasets of different N and shots in one run: the rules made for
    one dataset (simulate, convert, depth_a, depth_b_<k>, view_features_<k>, the ideal
    renders of whole sets) exist once per dataset, name their files in full, and each
    dataset's jobs write under its own folder only."""
    work = tiny_workflow(tmp_path / "w")
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    other = copy.deepcopy(cfg["datasets"]["tiny"])
    other["views"] = 5 if other["views"] != 5 else 3
    other["simulate"]["array"]["cols"] += 1
    cfg["datasets"]["tiny2"] = other
    (work / "config.yaml").write_text(yaml.safe_dump(cfg))
    proc = run(work, "-n")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    rules = {m.group(1) for m in re.finditer(r"^(?:local)?rule (\w+):", out, flags=re.M)}
    for base in ("simulate", "depth_a", "ground_truth_render_set",
                 "ground_truth_render_central"):
        assert {base, f"{base}_1"} <= rules, (base, sorted(rules))
    assert {"view_features_0", "view_features_1_0", "depth_b_0", "depth_b_1_0", "convert_0",
            "convert_1_0", "convert_views_0", "convert_views_1_0"} <= rules
    # every job of a per-dataset rule writes into its own dataset's folders
    own = {"simulate": "tiny", "simulate_1": "tiny2", "convert_0": "tiny",
           "convert_1_0": "tiny2", "convert_views_0": "tiny", "convert_views_1_0": "tiny2",
           "depth_a": "tiny", "depth_a_1": "tiny2", "view_features_0": "tiny",
           "view_features_1_0": "tiny2", "depth_b_0": "tiny", "depth_b_1_0": "tiny2"}
    seen = set()
    for block in re.split(r"\n(?=(?:local)?rule \w+:)", out):
        m = re.match(r"(?:local)?rule (\w+):", block)
        outs = re.search(r"^\s+output: (.+)$", block, flags=re.M)
        if m and outs and m.group(1) in own:
            seen.add(m.group(1))
            for path in outs.group(1).split(", "):
                assert f"/{own[m.group(1)]}/" in path, (m.group(1), path)
    assert seen == set(own)
    n2 = other["views"]
    assert f"results/tiny2/views/x00_y00/{n2 - 1}_{n2 - 1}.png" in out


def test_the_truth_cameras_own_depth_maps_only_where_asked_for(tmp_path):
    """verify.ground_truth_own_depth (off by default: 12 depth maps, about 75 s, on the
    default run) plans rule depth_view_truth for every map rule depth_view makes, and the
    synthesis reads them; off, none is planned."""
    work = tiny_workflow(tmp_path / "run")

    def planned() -> dict[str, int]:
        dry = snakemake(work, "-n")
        out = dry.stdout + dry.stderr
        assert dry.returncode == 0, out[-3000:]
        table = out[out.index("Job stats:"):].splitlines()[3:]
        return {m.group(1): int(m.group(2)) for m in
                map(re.compile(r"^(\w+)\s+(\d+)$").match, table) if m}

    off = planned()
    assert "depth_view_truth" not in off and off["depth_view"] > 0
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg.setdefault("verify", {})["ground_truth_own_depth"] = True
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    on = planned()
    assert on["depth_view_truth"] == on["depth_view"] == off["depth_view"]
    assert on["total"] == off["total"] + on["depth_view_truth"]
