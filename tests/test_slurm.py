"""The workflow through SLURM (issue 7): a single-node cluster on this machine
(tests/slurm/start_cluster.sh installs Debian's slurmctld, slurmd and munge when they
are missing and starts them as root), the tiny config submitted with `--executor slurm`
and the workflow profile profiles/slurm, and its outputs byte-identical to the local
run's (the session fixture `tiny_run`).

To stay within a few minutes the SLURM run stops after the conversion (`--until
convert`: simulate_setup, 10 x simulate, 10 x convert = 21 SLURM jobs); every file it
writes under data/ and results/ (logs and benchmarks aside) must equal the local one.
Where SLURM cannot be installed or started the test is skipped with the reason."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import pytest
from conftest import ROOT, copy_workflow, output_digests, run_snakemake, tail

pytestmark = [pytest.mark.slurm, pytest.mark.workflow]

SLURM_DIR = ROOT / "tests" / "slurm"
UNTIL = "convert"
# the plugin waits 40 s before its first status check, and as long after each check
# that sees a job finish; a test cluster answers at once
POLL_S = "3"


@pytest.fixture(scope="module")
def slurm_env() -> dict[str, str]:
    try:
        proc = subprocess.run(
            [str(SLURM_DIR / "start_cluster.sh")],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=1200,
        )
    except (OSError, subprocess.TimeoutExpired) as err:
        pytest.skip(f"SLURM cannot be started here: {err}")
    if proc.returncode != 0:
        pytest.skip(f"SLURM cannot be installed or started here: {proc.stdout.strip()}")
    conf = [line for line in proc.stdout.splitlines() if line.startswith("SLURM_CONF=")]
    env = dict(os.environ)
    env["SLURM_CONF"] = conf[-1].split("=", 1)[1]
    return env


def test_slurm_run_equals_local_run(slurm_env, tiny_run: Path, tmp_path: Path):
    work = copy_workflow(tmp_path / "slurm")
    t0 = time.monotonic()
    proc = run_snakemake(
        work,
        "--workflow-profile",
        "profiles/slurm",
        "--slurm-init-seconds-before-status-checks",
        POLL_S,
        "--jobs",
        "4",
        "--until",
        UNTIL,
        env=slurm_env,
        timeout=900,
    )
    seconds = time.monotonic() - t0
    assert proc.returncode == 0, tail(proc, 8000)
    out = proc.stdout
    # the jobs went through SLURM, not the local executor
    assert "localrule convert:" not in out, tail(proc)
    submitted = out.count("has been submitted with SLURM jobid")
    assert submitted >= 21, tail(proc)
    print(f"{submitted} SLURM jobs in {seconds:.0f} s")

    got = output_digests(work)
    local = output_digests(tiny_run)
    views = [p for p in got if p.startswith("results/tiny/views/") and p.endswith(".png")]
    assert len(views) >= 10 * 9, sorted(got)
    differ = [p for p in got if local.get(p) != got[p]]
    assert not differ, f"SLURM outputs that differ from the local run's: {differ}"
