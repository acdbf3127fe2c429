"""Shared workflow fixtures: one complete run of the tiny config per test session (the
rerun suite and the real-capture test both start from it, so it is simulated once)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW_FILES = ["Snakefile", "rules", "scripts", "config.schema.yaml", "report", "envs",
                  "profiles"]


def snakemake(work: Path, *args: str, timeout: int = 1500) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", "-j2", "--workflow-profile",
                           "none", *args], cwd=work, capture_output=True, text=True,
                          timeout=timeout)


def workflow_copy(dest: Path) -> Path:
    """The workflow's files (no data, no results) in ``dest``."""
    dest.mkdir(parents=True, exist_ok=True)
    for name in WORKFLOW_FILES:
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy2)(src, dest / name)
    return dest


def tiny_workflow(dest: Path) -> Path:
    """The workflow's files with tests/tiny/config.yaml as its config, in ``dest``."""
    work = workflow_copy(dest)
    shutil.copy2(ROOT / "tests" / "tiny" / "config.yaml", work / "config.yaml")
    return work


@pytest.fixture(scope="session")
def tiny_complete_run(tmp_path_factory) -> Path:
    """A folder in which the whole default target of tests/tiny/config.yaml has run."""
    work = tiny_workflow(tmp_path_factory.mktemp("complete"))
    proc = snakemake(work)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    return work
