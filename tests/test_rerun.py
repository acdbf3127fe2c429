"""Rerun semantics on the tiny config (issue 7): after one complete run, a dry run plans
exactly the jobs that a change makes stale, and a killed run leaves nothing that a
rerun would wrongly trust.

Expectations are derived from the workflow's own job graph (`snakemake --dag
--forceall`), not from a hand-written list: "rule R and everything downstream" is the
set of jobs reachable from R's jobs, counted per rule, so the tests keep holding as
stages are added. Every test starts from a copy of the one complete run that the
session fixture `tiny_run` (tests/conftest.py) makes."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
import yaml
from conftest import clone_run, parse_job_stats, planned_jobs, run_snakemake, tail

pytestmark = pytest.mark.workflow

# Verification and report rules: what a change of the `verify:` block may rerun.
VERIFY_PREFIXES = ("synthesis_", "reprojection", "gt_errors", "convert_quality", "report")
# Rules upstream of the converter: a conversion setting must never rerun them.
SIMULATOR_RULES = {"simulate_setup", "simulate"}
# Rules that take the view geometry (convert.tile_size, view_spacing_px) besides
# `convert` itself: the ground truth is traced for the converter's views (DESIGN.md).
VIEW_GEOMETRY_RULES = {"ground_truth_cam"}

_NODE = re.compile(r'^\s*(\d+)\[label = "([^"\\]+)')
_EDGE = re.compile(r"^\s*(\d+) -> (\d+)")


def job_graph(workdir: Path) -> tuple[dict[int, str], dict[int, set[int]]]:
    """(job -> rule, job -> the jobs that consume its outputs) of the whole workflow."""
    proc = run_snakemake(workdir, "--dag", "--forceall", "--quiet", "all")
    assert proc.returncode == 0, tail(proc)
    rule_of, children = {}, {}
    for line in proc.stdout.splitlines():
        if m := _NODE.match(line):
            rule_of[int(m.group(1))] = m.group(2)
        elif m := _EDGE.match(line):
            children.setdefault(int(m.group(1)), set()).add(int(m.group(2)))
    assert rule_of, "no job graph in the output of snakemake --dag:\n" + tail(proc)
    return rule_of, children


def downstream(graph, rules: set[str]) -> dict[str, int]:
    """{rule: job count} of the jobs of `rules` and every job that depends on them."""
    rule_of, children = graph
    todo = [j for j, r in rule_of.items() if r in rules]
    seen = set(todo)
    while todo:
        for child in children.get(todo.pop(), ()):
            if child not in seen:
                seen.add(child)
                todo.append(child)
    return dict(Counter(rule_of[j] for j in seen))


@pytest.fixture(scope="module")
def graph(tiny_run: Path):
    return job_graph(tiny_run)


def edit_config(work: Path, change) -> None:
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    change(cfg)
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))


def script_rules(work: Path, script: str, rules: set[str]) -> set[str]:
    """The rules (among `rules`) that run scripts/<script>, read from rules/*.smk: rules
    named in `rule NAME:`, and rules named by a `name:` directive (every string literal
    on its line, f-string fields matching any name: `f"synthesis_exp{_exp}"`)."""
    patterns: list[str] = []
    for smk in sorted((work / "rules").glob("*.smk")):
        names: list[str] = []
        in_name = False
        for line in smk.read_text().splitlines():
            if m := re.match(r"^\s*(?:rule|checkpoint)\s*(\w*)\s*:", line):
                names, in_name = [re.escape(m.group(1))] if m.group(1) else [], False
            elif re.match(r"^\s*name:\s*$", line):
                in_name = True
            elif in_name:
                literals = re.findall(r'f?"([^"]+)"', line)
                names = [re.sub(r"\\\{[^}]*\\\}", r"\\w+", re.escape(x)) for x in literals]
                in_name = False
            elif names and line.strip().strip('"').endswith("scripts/" + script):
                patterns += names
    return {r for r in rules if any(re.fullmatch(p, r) for p in patterns)}


def test_complete_run_leaves_nothing_to_do(tiny_run: Path, graph):
    assert planned_jobs(tiny_run) == {}
    rule_of, _ = graph
    assert {"simulate", "convert"} <= set(rule_of.values())


def test_verification_change_reruns_only_verification_and_report(
    tiny_run: Path, graph, tmp_path: Path
):
    rules = set(graph[0].values())
    seeds = {r for r in rules if r.startswith("synthesis_")}
    if not seeds:
        pytest.skip("no rule takes the verify block yet (the synthesis stage)")
    work = clone_run(tiny_run, tmp_path / "w")
    edit_config(work, lambda c: c.setdefault("verify", {}).update(psnr_border_px=9))
    jobs = planned_jobs(work)
    assert jobs == downstream(graph, seeds), jobs
    assert all(r == "all" or r.startswith(VERIFY_PREFIXES) for r in jobs), jobs


def test_conversion_change_reruns_conversion_and_downstream(tiny_run: Path, graph, tmp_path: Path):
    work = clone_run(tiny_run, tmp_path / "w")
    edit_config(work, lambda c: c["convert"].update(tile_size=7))
    jobs = planned_jobs(work)
    rules = set(graph[0].values())
    expected = downstream(graph, {"convert"} | (VIEW_GEOMETRY_RULES & rules))
    assert jobs == expected, jobs
    assert jobs["convert"] == Counter(graph[0].values())["convert"]  # every shot
    assert not SIMULATOR_RULES & set(jobs), jobs


@pytest.mark.parametrize("script", ["convert.py", "rig_b.py", "synthesis.py"])
def test_script_edit_reruns_that_rule_and_dependants(
    tiny_run: Path, graph, tmp_path: Path, script: str
):
    work = clone_run(tiny_run, tmp_path / "w")
    rules = script_rules(work, script, set(graph[0].values()))
    if not rules:
        pytest.skip(f"no rule runs scripts/{script} yet")
    path = work / "scripts" / script
    path.write_text(path.read_text() + "\n# edited by tests/test_rerun.py\n")
    jobs = planned_jobs(work)
    assert jobs == downstream(graph, rules), jobs


def test_untouched_copy_plans_nothing(tiny_run: Path, tmp_path: Path):
    """The mutation tests start from a faithful copy (else they prove nothing)."""
    work = clone_run(tiny_run, tmp_path / "w")
    assert planned_jobs(work) == {}


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["kill", "term"])
def test_run_killed_during_conversion_leaves_nothing_trusted(
    tiny_run: Path, graph, tmp_path: Path, sig: signal.Signals
):
    """Rerun the conversion (--forcerun) and stop it while a convert job writes its
    views: the jobs that were cut short must be planned again, though their outputs
    exist (some rewritten, some old); finished and never-started ones must not."""
    work = clone_run(tiny_run, tmp_path / "w")
    logs = work / "results" / "tiny" / "logs" / "convert"
    shutil.rmtree(logs, ignore_errors=True)
    out_log = work / "killed.log"
    with open(out_log, "w") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "snakemake", "--cores", "1", "--forcerun", "convert"]
            + ["--until", "convert"],
            cwd=work,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    # stop it when a job has written some of its views (its log says "view ... written"
    # and not yet "in all"); if the jobs are too quick for that, 10 s into the stage
    deadline, first_start = time.time() + 600, None
    while time.time() < deadline and proc.poll() is None:
        texts = [p.read_text() for p in logs.glob("*.log")] if logs.is_dir() else []
        if any("written" in t and "in all" not in t for t in texts):
            break
        if first_start is None and _convert_jobs(out_log.read_text()):
            first_start = time.time()
        if first_start is not None and time.time() - first_start > 10:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be stopped:\n" + out_log.read_text()
    if sig == signal.SIGKILL:
        os.killpg(proc.pid, sig)  # snakemake and its jobs, no chance to clean up
    else:
        os.kill(proc.pid, sig)  # snakemake alone: it must stop its jobs and clean up
    proc.wait(timeout=120)
    text = out_log.read_text()
    started = _convert_jobs(text)
    finished = set(re.findall(r"Finished jobid: (\d+) \(Rule: convert\)", text))
    cut_short = {cam for job, cam in started.items() if job not in finished}
    assert started, text[-3000:]
    if sig == signal.SIGKILL:
        assert cut_short, "the convert jobs finished before the kill:\n" + text[-3000:]
    # a rerun trusts nothing a stopped job left: a plain dry run refuses (incomplete
    # outputs) or plans exactly the jobs that were cut short
    proc = run_snakemake(work, "--dry-run")
    refused = proc.returncode != 0
    if sig == signal.SIGKILL:
        # Snakemake cannot clean up after a kill: it must know the job's outputs for
        # incomplete, those it removed before the job as well as those the job wrote
        assert refused, tail(proc)
    if refused:
        assert "incomplete" in proc.stdout.lower(), tail(proc)
        for cam in cut_short:
            left = sorted((work / "results/tiny/views" / cam).glob("[!.]*"))
            for f in left:
                assert str(f.relative_to(work)) in proc.stdout, (f, tail(proc))
        proc = run_snakemake(work, "--dry-run", "--rerun-incomplete")
        assert proc.returncode == 0, tail(proc)
    jobs = parse_job_stats(proc.stdout)
    print(
        f"{sig.name}: convert started for {sorted(started.values())}, cut short for "
        f"{sorted(cut_short)}; plain dry run {'refused' if refused else 'ran'}; plan {jobs}"
    )
    assert jobs.get("convert", 0) == len(cut_short), (jobs, cut_short, text[-3000:])
    for cam in cut_short:
        assert re.search(rf"wildcards: [^\n]*cam={cam}\b", proc.stdout), tail(proc)
    # what is left under an output's name is whole: atomic writes leave at most
    # hidden .part files, which no rule reads
    import cv2

    for p in (work / "results").rglob("*.png"):
        assert cv2.imread(str(p), cv2.IMREAD_UNCHANGED) is not None, f"{p} is corrupt"


_JOB = re.compile(
    r"^(?:local)?rule convert:\n(?:    .*\n)*?    jobid: (\d+)\n(?:    .*\n)*?"
    r"    wildcards: [^\n]*cam=(\w+)",
    re.M,
)


def _convert_jobs(text: str) -> dict[str, str]:
    """{jobid: shot} of the convert jobs that a run's output says were started."""
    return dict(_JOB.findall(text))
