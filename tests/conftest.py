"""Shared helpers of the workflow-level tests (markers `workflow` and `slurm`).

Every workflow test runs in a copy of the workflow in a temporary directory, never in
the working tree:

- `copy_workflow(dest)` copies the workflow files and the tiny config there;
- `run_snakemake(workdir, *args)` runs Snakemake there and keeps its output (also in
  `workdir/.test-logs/`, so a failing test can show it);
- `planned_jobs(workdir, *args)` is {rule: job count} of a dry run (empty: nothing to do);
- `output_digests(workdir)` is {path: sha256} of every output under data/ and results/
  except logs and benchmarks;
- `clone_run(src, dest)` copies a finished run, modification times and Snakemake's
  metadata included, so that a mutation test starts from a complete run;
- the session fixture `tiny_run` is one complete run of the tiny config (target `all`,
  whatever stages the Snakefile includes), shared by every test that needs one: copy it
  with `clone_run` before changing anything.
"""

from __future__ import annotations

import hashlib
import itertools
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TINY_CONFIG = ROOT / "tests" / "tiny" / "config.yaml"
# what a user needs besides the package itself (installed with `pip install -e .`)
WORKFLOW_FILES = (
    "Snakefile",
    "rules",
    "scripts",
    "config.schema.yaml",
    "report",
    "envs",
    "profiles",
)
# a complete tiny run on two cores takes minutes: never let a hung run stall CI forever
RUN_TIMEOUT_S = 1800
_RUN_IDS = itertools.count()


def copy_workflow(dest: Path, config: Path = TINY_CONFIG) -> Path:
    """A runnable copy of the workflow in `dest` (created), with `config` as config.yaml."""
    dest.mkdir(parents=True, exist_ok=True)
    for name in WORKFLOW_FILES:
        src = ROOT / name
        if not src.exists():
            continue
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, dest / name)
    shutil.copy2(config, dest / "config.yaml")
    return dest


def run_snakemake(
    workdir: Path, *args: str, timeout: float = RUN_TIMEOUT_S, env: dict | None = None
) -> subprocess.CompletedProcess:
    """`snakemake *args` in `workdir` (its workflow profile profiles/default applies
    unless args say otherwise). Output is captured (stdout and stderr together, in
    `.stdout`) and also written to `workdir/.test-logs/<n>.log`."""
    cmd = [sys.executable, "-m", "snakemake", *args]
    proc = subprocess.run(
        cmd,
        cwd=workdir,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=timeout,
        env=env,
    )
    logs = Path(workdir) / ".test-logs"
    logs.mkdir(exist_ok=True)
    (logs / f"{next(_RUN_IDS):03d}.log").write_text("$ " + " ".join(cmd) + "\n" + proc.stdout)
    return proc


def tail(proc: subprocess.CompletedProcess, n: int = 4000) -> str:
    """The end of a run's output, for assertion messages."""
    return f"exit {proc.returncode}\n" + (proc.stdout or "")[-n:]


_STATS_ROW = re.compile(r"^(\S+)\s+(\d+)$")


def parse_job_stats(text: str) -> dict[str, int]:
    """{rule: count} of the first "Job stats:" table in Snakemake's output (the jobs a
    dry run plans), without the `total` row; {} when nothing is to be done."""
    lines = text.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "Job stats:")
    except StopIteration:
        if "Nothing to be done" in text:
            return {}
        raise ValueError("no 'Job stats:' table in Snakemake's output:\n" + text[-3000:]) from None
    jobs: dict[str, int] = {}
    # header "job count", a dashed rule, then one row per rule and "total"
    for line in lines[start + 3 :]:
        m = _STATS_ROW.match(line.strip())
        if not m:
            break
        if m.group(1) == "total":
            assert sum(jobs.values()) == int(m.group(2)), text[-3000:]
            break
        jobs[m.group(1)] = int(m.group(2))
    return jobs


def planned_jobs(workdir: Path, *args: str) -> dict[str, int]:
    """{rule: job count} that `snakemake --dry-run *args` plans ({} = nothing to do)."""
    proc = run_snakemake(workdir, "--dry-run", *args)
    assert proc.returncode == 0, tail(proc)
    return parse_job_stats(proc.stdout)


def output_digests(workdir: Path, roots: tuple[str, ...] = ("data", "results")) -> dict:
    """{relative path: sha256} of every file under `roots`, logs and benchmarks left out
    (they hold times and host names)."""
    out = {}
    for base in roots:
        for p in sorted((Path(workdir) / base).rglob("*")):
            rel = p.relative_to(workdir)
            if {"logs", "benchmarks"} & set(rel.parts) or not p.is_file():
                continue
            out[str(rel)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def clone_run(src: Path, dest: Path) -> Path:
    """Copy a finished run (workflow, outputs, .snakemake metadata) with every file's
    modification time kept, so that Snakemake sees the same state there."""
    shutil.copytree(src, dest, symlinks=True, ignore=shutil.ignore_patterns(".test-logs", "locks"))
    # copytree keeps the files' times; keep the directories' too (outputs can be dirs)
    for p in sorted(Path(src).rglob("*"), reverse=True):
        q = dest / p.relative_to(src)
        if p.is_dir() and not p.is_symlink() and q.is_dir():
            st = p.stat()
            os.utime(q, ns=(st.st_atime_ns, st.st_mtime_ns))
    return dest


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> Path:
    """One complete run of the tiny config (default target) with the default profile;
    read-only for tests: `clone_run` it before changing anything.

    PLENOCAL_TINY_RUN=<dir> reuses a finished run made by this fixture before (its
    directory `.../tiny_runN/w`), for working on the tests; it is checked, not trusted:
    a run with anything left to do fails the first test of test_rerun.py."""
    reuse = os.environ.get("PLENOCAL_TINY_RUN")
    if reuse:
        return Path(reuse)
    work = copy_workflow(tmp_path_factory.mktemp("tiny_run") / "w")
    proc = run_snakemake(work, "--cores", "2")
    if proc.returncode != 0:
        pytest.fail("the complete tiny run failed:\n" + tail(proc, 8000))
    return work
