"""plenocal.malloc.no_huge_pages: numpy's arrays on ordinary pages in every rule's job and
in the command line, and the same numbers (each case in a fresh process: the switch lasts
for a process's life)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

PROBE = r"""
import json, sys
import numpy as np
get = np._core.multiarray._get_madvise_hugepage
before = get()
case, result = sys.argv[1], sys.argv[2]
if case == "switch":
    from plenocal.malloc import no_huge_pages
    taken = no_huge_pages()
elif case == "rulelog":
    from plenocal.rulelog import log_to_file
    log_to_file(sys.argv[3])
    taken = None
elif case == "cli":
    from plenocal.cli import main
    main(["convert", sys.argv[3], sys.argv[3], "-o", sys.argv[3] + "_out", "-q"])
    taken = None
rng = np.random.default_rng(5)
a = rng.random((1024, 1024, 3), dtype=np.float32)  # 12 MB: over numpy's 4 MB
digest = float((a * a + 1.0).sum(dtype=np.float64))
with open(result, "w") as f:  # a rule job's stdout goes to its log
    json.dump({"before": before, "after": get(), "taken": taken, "digest": digest}, f)
"""


def _run(tmp: Path, *args: str, env: str | None = None) -> dict:
    environ = dict(os.environ)
    environ.pop("NUMPY_MADVISE_HUGEPAGE", None)
    if env is not None:
        environ["NUMPY_MADVISE_HUGEPAGE"] = env
    result = tmp / f"result_{args[0]}_{env}.json"
    subprocess.run([sys.executable, "-c", PROBE, args[0], str(result), *args[1:]],
                   capture_output=True, text=True, check=True, env=environ, cwd=tmp)
    return json.loads(result.read_text())


def test_the_switch_turns_numpys_huge_pages_off_and_changes_no_number(tmp_path):
    """numpy as imported (huge pages asked for on a kernel from 4.6 on), then switched:
    the same numbers as with ``NUMPY_MADVISE_HUGEPAGE=0`` from the start."""
    switched = _run(tmp_path, "switch")
    assert switched["taken"] is True and switched["after"] is False
    off = _run(tmp_path, "switch", env="0")
    assert off["before"] is False and off["taken"] is False  # the environment chose
    assert switched["digest"] == off["digest"]


def test_a_users_numpy_madvise_hugepage_is_left_as_numpy_took_it(tmp_path):
    """``NUMPY_MADVISE_HUGEPAGE=1`` in the environment: huge pages stay on."""
    on = _run(tmp_path, "switch", env="1")
    assert on["before"] is True and on["taken"] is False and on["after"] is True


def test_every_rule_job_and_the_command_line_start_without_huge_pages(tmp_path):
    """Every script in scripts/ starts with plenocal.rulelog.log_to_file, and plenocal
    convert with plenocal.cli.main: both leave numpy's huge pages off (the command line
    even when its input is missing)."""
    job = _run(tmp_path, "rulelog", str(tmp_path / "job.log"))
    assert job["after"] is False, job
    cli = _run(tmp_path, "cli", str(tmp_path / "missing.png"))
    assert cli["after"] is False, cli
    scripts = sorted((Path(__file__).resolve().parents[1] / "scripts").glob("*.py"))
    assert scripts
    for script in scripts:
        text = script.read_text()
        assert "log_to_file(" in text or "rule_logger(" in text, script.name
