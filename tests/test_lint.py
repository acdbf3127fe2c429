"""The workflow passes `snakemake --lint` and `snakefmt --check`, the code `ruff`; the
profiles use only options this Snakemake (and its SLURM plugin) knows, and hold no site
settings."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
SITE_RESOURCES = {"slurm_partition", "slurm_account", "slurm_qos", "slurm_reservation"}


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
    proc = _run(exe, "--check", ".")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_clean():
    exe = shutil.which("ruff")
    assert exe, "ruff is installed by the test extra of pyproject.toml"
    proc = _run(exe, "check", ".")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_profiles_use_known_options_and_no_site_settings():
    proc = _run(sys.executable, "-m", "snakemake", "--help")
    assert proc.returncode == 0, proc.stderr
    options = set(re.findall(r"--([a-z0-9][a-z0-9-]*)", proc.stdout))
    assert "slurm-status-command" in options, (
        "the SLURM executor plugin is not installed: it comes with the test extra "
        '(pip install -e ".[test]") or the slurm extra (pip install -e ".[slurm]")')
    profiles = sorted((ROOT / "profiles").glob("*/config.yaml"))
    assert {p.parent.name for p in profiles} >= {"default", "slurm"}
    for path in profiles:
        profile = yaml.safe_load(path.read_text())
        unknown = sorted(set(profile) - options)
        assert not unknown, f"{path}: unknown options {unknown}"
        site = SITE_RESOURCES & set(profile.get("default-resources") or {})
        assert not site, (f"{path}: site settings {site} belong on the command line "
                          "(--default-resources) or in the user's copy of the profile")
        # a constant disk_mb: Snakemake's default is a coroutine that `snakemake --report`
        # never awaits, one RuntimeWarning per job kind
        assert isinstance((profile.get("default-resources") or {}).get("disk_mb"), int), path
    # ... and nor does the workflow
    for smk in [ROOT / "Snakefile", *sorted((ROOT / "rules").glob("*.smk"))]:
        for name in SITE_RESOURCES:
            assert name not in smk.read_text(), f"{smk.name} sets {name}"
