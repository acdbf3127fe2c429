"""The workflow passes `snakemake --lint` and `snakefmt --check`, the code `ruff`."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(*cmd: str) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_snakemake_lint_reports_nothing():
    proc = _run(sys.executable, "-m", "snakemake", "--lint", "--workflow-profile", "none")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    assert "Lints for" not in out, out[-3000:]


def test_snakefmt_check():
    exe = shutil.which("snakefmt")
    assert exe, "snakefmt is installed by the test extra of pyproject.toml"
    proc = _run(exe, "--check", "Snakefile", "rules")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_clean():
    exe = shutil.which("ruff")
    assert exe, "ruff is installed by the test extra of pyproject.toml"
    proc = _run(exe, "check", ".")
    assert proc.returncode == 0, proc.stdout + proc.stderr
