"""Shared workflow fixtures: one complete run of the tiny config per test session (the
rerun suite and the real-capture test both start from it, so it is simulated once)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW_FILES = ["Snakefile", "rules", "scripts", "config.schema.yaml", "report", "envs",
                  "profiles"]


def snakemake(work: Path, *args: str, timeout: int = 1500,
              tmpdir: Path | None = None) -> subprocess.CompletedProcess:
    """``snakemake -j2 <args>`` in ``work`` (``tmpdir``: the run's $TMPDIR)."""
    env = None if tmpdir is None else {**os.environ, "TMPDIR": str(tmpdir)}
    return subprocess.run([sys.executable, "-m", "snakemake", "-j2", "--workflow-profile",
                           "none", *args], cwd=work, capture_output=True, text=True,
                          timeout=timeout, env=env)


def snakemake_each(work: Path, calls: list[tuple[str, ...]], workers: int = 2
                   ) -> list[subprocess.CompletedProcess]:
    """:func:`snakemake` with each argument tuple of ``calls`` in ``work``, ``workers`` at a
    time (for dry runs, which lock nothing: one process each, one core each), in order."""
    from concurrent.futures import ThreadPoolExecutor  # noqa: PLC0415

    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(lambda args: snakemake(work, *args), calls))


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


def clone(src: Path, dest: Path) -> Path:
    """A copy of the run folder ``src`` with the same mtimes (copying rewrites them in
    copy order: Snakemake would see newer inputs)."""
    shutil.copytree(src, dest, symlinks=True)
    for p in src.rglob("*"):
        q = dest / p.relative_to(src)
        if q.exists() and not q.is_symlink():
            st = p.stat()
            os.utime(q, ns=(st.st_atime_ns, st.st_mtime_ns))
    return dest


@pytest.fixture(scope="session")
def tiny_tmpdir(tmp_path_factory) -> Path:
    """The $TMPDIR of the session's complete tiny run (tests/test_workflow_faults.py checks
    that the workflow leaves nothing of its own there)."""
    return tmp_path_factory.mktemp("tmpdir")


@pytest.fixture(scope="session")
def tiny_complete_run(tmp_path_factory, tiny_tmpdir) -> Path:
    """A folder in which the whole default target of tests/tiny/config.yaml has run."""
    work = tiny_workflow(tmp_path_factory.mktemp("complete"))
    proc = snakemake(work, tmpdir=tiny_tmpdir)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    return work


# Under pytest-xdist (pyproject's addopts: two workers, ``--dist loadgroup``) every test
# module runs whole on one worker, so its module fixtures are made once. The modules that
# start from the session's complete tiny run share one worker (one run, not one a worker)
# and go first, in collection order kept (``--no-loadscope-reorder``): they are the
# suite's longest part, and the other worker takes every other module meanwhile.
SHARED_RUN = "tiny_complete_run"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Each item's xdist group: its module's file, or :data:`SHARED_RUN` for every item of a
    module where any test needs that run; those modules' items moved to the front."""
    def module(item: pytest.Item) -> str:
        return item.nodeid.split("::")[0]

    shared = {module(item) for item in items
              if SHARED_RUN in getattr(item, "fixturenames", ())}
    for item in items:
        name = module(item)
        item.add_marker(pytest.mark.xdist_group(SHARED_RUN if name in shared else name))
    items.sort(key=lambda item: module(item) not in shared)
