"""Issue 34 on the tiny run: a deleted or killed intermediate is made again, and the
workflow leaves nothing of its own in $TMPDIR.

Snakemake makes a missing file again only where a target or a job that must run asks for
it; the default target now asks for every missing output of the default run
(rules/common.smk, default_run_gaps). Two tests keep that from coming back:

* every file of the complete tiny run (results/ and the simulator's data/; logs,
  benchmarks and Snakemake's own .snakemake_timestamp aside), in a dry run. A file inside
  a directory output (COLMAP models, the MPEG exports, the synthesized images, the staged
  central views) is removed, one folder at a time: the job that wrote the folder is forced.
  Every other file (views, renders, depth maps, databases, analyses, JSON, lenslet images)
  is deleted, all at once: each one is named a missing output of a job that runs, i.e. the
  default target asks for it by name. That does not depend on the other files, so one dry
  run checks each of them as if it alone were deleted (600 dry runs would take 15 min).
* a sample of them deleted for real, one of each kind, with the run of the issue's
  SIGKILL probe (killed during --forcerun baseline_sfm, then --unlock and
  --rerun-incomplete): killed outputs (baseline/), a plain intermediate read by others
  (matches/database.db), a file that no job reads (convert/quality.json), an output of a
  rule with wildcards besides the dataset (depth/views/<cam>/<view>.json), and a file
  inside a directory output (calibration/mpeg/rvs/): after one `snakemake -j2`, every file
  is back with the bytes of the first run (and Table I's naive row is the new run's).
"""

from __future__ import annotations

import hashlib
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import clone, snakemake

pytestmark = pytest.mark.workflow

SNAKEMAKE_OWN = (".snakemake_timestamp",)


def run_files(work: Path) -> dict[str, str]:
    """SHA-256 of every file the run made (results/ and the simulator's data/), by path;
    logs, benchmarks and Snakemake's directory time stamps left out."""
    out = {}
    for top in ("results", "data"):
        for p in sorted((work / top).rglob("*")):
            rel = p.relative_to(work)
            if p.is_dir() or p.name in SNAKEMAKE_OWN or rel.parts[2:3] in (("logs",),
                                                                             ("benchmarks",)):
                continue
            out[rel.as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def in_directory_output(work: Path, rel: str) -> str | None:
    """The directory output (a folder that holds Snakemake's time stamp) that holds the
    file ``rel``, or None."""
    for parent in Path(rel).parents:
        if (work / parent / ".snakemake_timestamp").is_file():
            return parent.as_posix()
    return None


def dry_run_jobs(work: Path) -> list[tuple[list[str], str]]:
    """[(outputs, reason)] of each job that a dry run plans."""
    proc = snakemake(work, "-n")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    jobs = []
    for block in re.split(r"\n(?=(?:local)?rule \w+:\n)", out):
        outputs = re.search(r"^    output: (.*)$", block, flags=re.M)
        reason = re.search(r"^    reason: (.*)$", block, flags=re.M)
        if reason:
            jobs.append((outputs.group(1).split(", ") if outputs else [], reason.group(1)))
    return jobs


def missing_named(reason: str) -> set[str]:
    m = re.search(r"Missing output files: ([^;]*)", reason)
    return set(m.group(1).split(", ")) if m else set()


def test_every_deleted_file_is_made_again(tiny_complete_run: Path, tmp_path: Path):
    work = clone(tiny_complete_run, tmp_path / "w")
    files = run_files(work)
    assert len(files) > 350
    folders = {rel: in_directory_output(work, rel) for rel in files}
    inside = sorted({d for d in folders.values() if d is not None})
    assert {"results/tiny/reg_a/model", "results/tiny/calibration/colmap",
            "results/tiny/calibration/mpeg/rvs"} <= set(inside)
    # a file removed from a directory output: the job that wrote the folder is forced, one
    # folder at a time (a forced job upstream would hide the reason of those below it)
    for folder in inside:
        gone = next(rel for rel in sorted(files) if folders[rel] == folder)
        aside = tmp_path / "aside"
        (work / gone).rename(aside)
        forced = [outs for outs, reason in dry_run_jobs(work) if reason == "Forced execution"]
        aside.rename(work / gone)
        os.utime(work / folder / ".snakemake_timestamp")  # the folder as its job left it
        assert any(folder in outs for outs in forced), (gone, forced)
    # every other file deleted, all at once: each is named a missing output of a job that
    # runs (the default target asks for it by name: a file that only a job which needs
    # no rerun would read, a file no job reads)
    plain = [rel for rel in files if folders[rel] is None]
    for rel in plain:
        (work / rel).unlink()
    named = set().union(*(missing_named(reason) for _, reason in dry_run_jobs(work)))
    assert [rel for rel in plain if rel not in named] == []
    # every kind is there: views, renders, depth maps, databases, analyses, lenslet images
    for kind in ("/views/x00_y00/0_0.png", "/ground_truth/renders/", "/depth/views/", ".db",
                 "/analysis.npz", "data/tiny/lenslet/", "/eval/reprojection/"):
        assert any(kind in rel for rel in plain), kind


def _kill_when_started(proc: subprocess.Popen, log: Path, marker: Path, since: float) -> None:
    """SIGKILL the whole run (its process group) once the job whose ``log`` is written
    after ``since`` has made its working folder (``marker``'s parent holds ``marker``'s
    name as a prefix) - or at the deadline."""
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None:
        started = log.exists() and log.stat().st_mtime > since
        working = any(p.name.startswith(marker.name) for p in marker.parent.iterdir()) \
            if marker.parent.is_dir() else False
        if started and working:
            time.sleep(0.2)
            break
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def test_killed_and_deleted_intermediates_are_rebuilt_byte_identical(
        tiny_complete_run: Path, tmp_path: Path):
    work = clone(tiny_complete_run, tmp_path / "w")
    tmpdir = tmp_path / "tmpdir"
    tmpdir.mkdir()
    before = run_files(work)
    res = work / "results" / "tiny"
    table = (res / "eval" / "reprojection.json").read_bytes()

    # the probe: killed during a forced rerun of the naive baseline
    since = time.time()
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", "-j2", "--workflow-profile",
                             "none", "--forcerun", "baseline_sfm"], cwd=work,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True, env={**os.environ, "TMPDIR": str(tmpdir)})
    _kill_when_started(proc, res / "logs" / "baseline_sfm" / "tiny.log",
                       res / "baseline" / ".baseline_sfm.", since)
    assert not (res / "baseline" / "cameras.json").exists()  # Snakemake removed it first
    assert snakemake(work, "--unlock").returncode == 0

    # one file of each kind deleted besides (module docstring)
    depth_info = sorted((res / "depth" / "views").rglob("*.json"))[0]
    rvs = sorted(p for p in (res / "calibration" / "mpeg" / "rvs").iterdir()
                 if p.name != ".snakemake_timestamp")[0]
    for p in (res / "matches" / "database.db", res / "convert" / "quality.json", depth_info,
              rvs):
        p.unlink()

    proc = snakemake(work, "--rerun-incomplete", tmpdir=tmpdir)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    after = run_files(work)
    assert sorted(after) == sorted(before)
    assert [p for p in before if after[p] != before[p]] == []
    assert (res / "eval" / "reprojection.json").read_bytes() == table
    assert "Nothing to be done" in snakemake(work, "-n").stdout
    # no working folder left beside the outputs, nothing of the workflow's in $TMPDIR
    assert list(res.rglob("*.tmpdir")) == []
    assert _workflow_leftovers(tmpdir) == []


def _workflow_leftovers(tmpdir: Path) -> list[str]:
    """What the workflow's jobs left in ``tmpdir``: COLMAP's working folders
    (plenocal_*) and glog's files (<program>.<host>.<user>.log.<LEVEL>.<time>)."""
    return sorted(p.name for p in tmpdir.iterdir()
                  if p.name.startswith("plenocal") or re.search(r"\.log\.[A-Z]+", p.name))


def test_nothing_left_in_tmpdir(tiny_complete_run: Path, tiny_tmpdir: Path):
    """The session's complete run (tests/conftest.py) ran with its own $TMPDIR: COLMAP's
    glog wrote *.INFO / *.WARNING files there after every job, and the naive baseline and
    Table I their working folders (left behind by a kill)."""
    assert _workflow_leftovers(tiny_tmpdir) == []
