"""Rerun semantics on the tiny config (issue 7): after one complete run, Snakemake
plans exactly the jobs that a change makes stale, and a killed run leaves nothing
that a rerun would wrongly trust."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import clone, snakemake

from plenocal.names import central_view, view_names
from plenocal.report.sources import stage_warnings

VERIFY_RULES = {"synthesis_exp1", "synthesis_exp2", "synthesis_exp3_part", "synthesis_exp3",
                "report", "all"}

pytestmark = pytest.mark.workflow


def planned(work: Path) -> dict[str, int]:
    """Rule -> job count of a dry run (empty when nothing is to be done)."""
    proc = snakemake(work, "-n")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    if "Nothing to be done" in out:
        return {}
    table = out[out.index("Job stats:"):]
    jobs = {}
    for line in table.splitlines()[3:]:
        m = re.match(r"^(\w+)\s+(\d+)$", line.strip())
        if not m:
            break
        if m.group(1) != "total":
            # the rules of runs of shots (view_features_0, depth_b_1, ...) by their step
            rule = re.sub(r"_\d+$", "", m.group(1))
            jobs[rule] = jobs.get(rule, 0) + int(m.group(2))
    return jobs


@pytest.fixture(scope="module")
def complete_run(tiny_complete_run) -> Path:
    """The session's complete tiny run (tests/conftest.py), shared with the real-capture
    test so the tiny config is simulated once."""
    return tiny_complete_run


def edit_config(work: Path, change) -> None:
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    change(cfg)
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))


def test_complete_run_leaves_nothing_to_do(complete_run: Path):
    assert planned(complete_run) == {}
    assert (complete_run / "results/tiny/report/index.html").is_file()
    assert (complete_run / "results/tiny/calibration/cameras.json").is_file()


def test_complete_run_report_reads_every_stage_record(complete_run: Path):
    """The report's warnings box reads every stage's record of a plain run: none is
    "unreadable" (registration A wrote its ``warnings`` key only where a shot was weak, and
    every report of a run without one said reg_a.json was unreadable)."""
    results = complete_run / "results/tiny"
    cams = sorted(p.name for p in (results / "views").iterdir() if p.is_dir())
    found, read = stage_warnings(results, cams)
    assert read >= len(cams) + 4  # disparity.json per shot, convert_setup, reg_a, ...
    assert not [w for w in found if w.message.startswith("unreadable")], found
    assert "unreadable" not in (results / "report/index.html").read_text()


def test_every_script_job_records_the_code_it_ran(complete_run: Path):
    """Snakemake's record of each job that ran a script holds, among its params, the hash
    of the package modules that script imports (plenocal.codehash, rules/common.smk's
    add_code_params): a later version of one of them reruns the job."""
    import json  # noqa: PLC0415

    from plenocal.codehash import script_code  # noqa: PLC0415

    scripts = Path(__file__).resolve().parents[1] / "scripts"
    checked = set()
    for record in (complete_run / ".snakemake" / "metadata").iterdir():
        meta = json.loads(record.read_text())
        m = re.search(r"scripts/(\w+\.py)", meta.get("code") or "")
        if not m:
            continue
        assert repr(script_code(scripts / m.group(1))) in meta["params"], (record.name,
                                                                          meta["rule"])
        checked.add(m.group(1))
    assert {"simulate.py", "convert.py", "merge.py", "refine.py", "report.py"} <= checked


def test_verification_change_reruns_only_verification(complete_run: Path, tmp_path: Path):
    """How the views are scored (the PSNR's border) reruns the experiments' scoring but
    not Exp. 3's renders, whose parts keep each target's errors per ring of pixels; how
    they are rendered (the DIBR's soft z-test) reruns those too; Exp. 2's sets rerun
    Exp. 2 (and make the new sets' inputs) but not Exp. 1 or 3; nothing before the
    verification reruns."""
    work = clone(complete_run, tmp_path / "w")
    edit_config(work, lambda c: c.setdefault("verify", {}).update(psnr_border_px=9))
    assert set(planned(work)) == VERIFY_RULES - {"synthesis_exp3_part"}
    edit_config(work, lambda c: c["verify"].update(dibr={"depth_exponent": 6.0}))
    assert set(planned(work)) == VERIFY_RULES
    work = clone(complete_run, tmp_path / "w2")
    edit_config(work, lambda c: c.setdefault("verify", {}).update(exp2_sets="all"))
    jobs = set(planned(work))
    # every set's views: their depth maps, ideal renders and MPEG exports are new jobs
    assert "synthesis_exp2" in jobs and jobs <= VERIFY_RULES | {
        "depth_view", "depth_view_truth", "ground_truth_render", "mpeg_views"}, jobs
    assert not jobs & {"synthesis_exp1", "synthesis_exp3_part", "synthesis_exp3"}, jobs


def test_a_key_a_job_does_not_read_reruns_nothing_of_it(complete_run: Path, tmp_path: Path):
    """The refine job's thread count (the same cameras to the bit for any number),
    convert.upsample under a given tile, the colmap block under the plane sweep, one track
    set's own keys and RVS's settings under the DIBR: each reran every job it reached (the
    refinement, the synthesis depth maps and the experiments: 24 jobs; the registrations'
    depth maps on: 33; the conversion on: 59) because the rules were given whole config
    blocks."""
    work = clone(complete_run, tmp_path / "w")
    edit_config(work, lambda c: c["refine"].update(num_threads=2))
    assert planned(work) == {}
    # the tiny config gives the tile: upsample sets an automatic one only
    edit_config(work, lambda c: c["convert"].update(upsample=2.0))
    assert isinstance(yaml.safe_load((work / "config.yaml").read_text())["convert"]
                      ["tile_size"], int) and planned(work) == {}
    edit_config(work, lambda c: c["depth"].update(colmap={"window_radius": 7}))
    assert depth_backend(work) == "planesweep" and planned(work) == {}
    # carry_every is the central views' set's, matches every view's: one set each
    edit_config(work, lambda c: c["refine"].update(carry_every=2))
    jobs = planned(work)
    assert jobs.get("refine_tracks") == 1 and "refine" in jobs, jobs
    assert not {"match_central", "view_matches", "merge"} & set(jobs), jobs
    # the ideal renders' supersampling: the lenslet images do not read it (it reran the
    # simulation and every job after it: 60)
    edit_config(work, lambda c: c["datasets"]["tiny"]["simulate"].setdefault(
        "render", {}).update(ideal_supersample=3))
    jobs = planned(work)
    assert "ground_truth_render" in jobs, jobs
    assert not {"simulate", "simulate_setup", "convert", "map_a", "merge"} & set(jobs), jobs
    # RVS's blending factor under the project's DIBR: the MPEG exports carry it, the
    # experiments (rendered by the DIBR) do not read it
    work = clone(complete_run, tmp_path / "w2")
    edit_config(work, lambda c: c.setdefault("verify", {}).update(rvs_blending_factor=6.0))
    assert planned(work) == {"mpeg_views": 1, "report": 1, "all": 1}


def depth_backend(work: Path) -> str:
    """The tiny config's depth backend (the test above needs the plane sweep)."""
    return yaml.safe_load((work / "config.yaml").read_text())["depth"]["backend"]


def test_conversion_change_reruns_conversion_and_downstream(complete_run: Path,
                                                           tmp_path: Path):
    work = clone(complete_run, tmp_path / "w")
    edit_config(work, lambda c: c["convert"].update(tile_size=7))
    jobs = planned(work)
    assert jobs.get("convert") == 2 and jobs.get("convert_views") == 2  # every shot
    assert "simulate" not in jobs and "simulate_setup" not in jobs
    for rule in ("features_a", "map_a", "rig_b", "depth_a", "depth_b", "scale", "merge",
                 "report"):
        assert rule in jobs, (rule, jobs)


def test_deleted_view_reruns_its_conversion(complete_run: Path, tmp_path: Path):
    """The views on disk are not in the DAG (rules/common.smk missing_views): a view
    deleted by hand is declared again, so its conversion job reruns, and a full run
    brings it back with the same bytes. The job also removes the views of an earlier
    ``views`` setting from the shot's folder (here two of a 5 x 5 run's, put there by
    hand), which Snakemake does not track (plenocal.convert.viewset.remove_stale_views).
    A shot's folders the config does not name (a shot taken out of the dataset: its views
    and its views' depth maps) are named at the run's start with the command that removes
    them, and left as they are."""
    work = clone(complete_run, tmp_path / "w")
    gone = work / "results/tiny/views/x09_y09"
    gone.mkdir()
    (gone / "0_0.png").write_bytes(b"an earlier run's view")
    gone_depth = work / "results/tiny/depth/views/x09_y09"
    gone_depth.mkdir(parents=True)
    (gone_depth / "0_0.npy").write_bytes(b"an earlier run's depth map")
    shot = sorted(p for p in (work / "results/tiny/views").iterdir() if p.is_dir())[0]
    n = yaml.safe_load((work / "config.yaml").read_text())["datasets"]["tiny"]["views"]
    view = shot / f"{view_names(n)[0]}.png"
    assert view.stem != central_view(n) and view.is_file()
    before = view.read_bytes()
    stale = [shot / f"{n + 1}_{n + 1}.png", shot / f"0_{n}.png"]
    for p in stale:
        p.write_bytes(before)
    kept = {p.name: p.read_bytes() for p in shot.iterdir() if p != view and p not in stale}
    view.unlink()
    jobs = planned(work)
    assert jobs.get("convert_views") == 1, jobs
    assert "convert" not in jobs and "simulate" not in jobs, jobs
    proc = snakemake(work, "-j2", str(view.relative_to(work)))
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert view.read_bytes() == before
    warning = " ".join(proc.stderr.split())
    assert "that the config no longer names (x09_y09)" in warning, proc.stderr[-3000:]
    assert "rm -r results/tiny/views/x09_y09 results/tiny/depth/views/x09_y09" in warning
    assert (gone / "0_0.png").is_file() and (gone_depth / "0_0.npy").is_file()
    assert not any(p.exists() for p in stale)
    assert {p.name: p.read_bytes() for p in shot.iterdir() if p != view} == kept
    # the shot's views.json is written again with the same bytes: nothing else reruns
    assert planned(work) == {}


def test_script_edit_reruns_that_rule_and_dependants(complete_run: Path, tmp_path: Path):
    work = clone(complete_run, tmp_path / "w")
    script = work / "scripts" / "rig_b.py"
    script.write_text(script.read_text() + "\n# edited\n")
    jobs = planned(work)
    assert jobs.get("rig_b") == 1
    for rule in ("scale", "merge", "report"):
        assert rule in jobs, (rule, jobs)
    for rule in ("simulate", "convert", "features_a", "map_a"):
        assert rule not in jobs, (rule, jobs)


def test_killed_run_leaves_nothing_trusted(complete_run: Path, tmp_path: Path):
    work = clone(complete_run, tmp_path / "w")
    edit_config(work, lambda c: c["convert"].update(tile_size=5))
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", "-j1", "--workflow-profile",
                             "none", "--until", "convert_views_0"], cwd=work,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    logs = work / "results/tiny/logs/convert"
    deadline = time.time() + 300
    started = set(logs.glob("*.log")) if logs.exists() else set()
    # wait until a convert job is under way, then kill the whole run hard
    while time.time() < deadline:
        now = set(logs.glob("*.log")) if logs.exists() else set()
        fresh = [p for p in now if p.stat().st_mtime > time.time() - 60]
        if fresh or now - started:
            time.sleep(1.0)
            break
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    # no half-written file sits under a final name: atomic writes leave only .part temps
    views = list((work / "results/tiny/views").rglob("*.png"))
    assert views
    import cv2

    for p in views:
        assert cv2.imread(str(p)) is not None, f"{p} is corrupt"
    # a rerun does not trust what the killed job left: it reruns the conversions
    rerun = snakemake(work, "-n", "--rerun-incomplete")
    out = rerun.stdout + rerun.stderr
    assert rerun.returncode == 0, out[-3000:]
    assert re.search(r"^convert_\d+\s+\d+$", out, flags=re.M), out[-3000:]


def _reversed_keys(value):
    if isinstance(value, dict):
        return {k: _reversed_keys(value[k]) for k in reversed(list(value))}
    if isinstance(value, list):
        return [_reversed_keys(v) for v in value]
    return value


def test_reordered_config_keys_rerun_nothing(complete_run: Path, tmp_path: Path):
    """Issue 16: params are compared in a canonical key order, so a config.yaml whose
    keys are merely reordered (every mapping reversed, ``seed`` below ``array``...) is the
    same config."""
    work = clone(complete_run, tmp_path / "w")
    before = (work / "config.yaml").read_text()
    cfg = yaml.safe_load(before)
    (work / "config.yaml").write_text(yaml.safe_dump(_reversed_keys(cfg), sort_keys=False))
    assert (work / "config.yaml").read_text() != before
    assert planned(work) == {}
    # and a real change still reruns: the check above is not blind
    edit_config(work, lambda c: c["convert"].update(tile_size=7))
    assert planned(work).get("convert") == 2


def test_snakemake_report_attaches_every_caption(complete_run: Path, tmp_path: Path):
    """Issue 16: every report/*.rst is the caption of an output, and Snakemake's own
    report builds with all of them."""
    work = clone(complete_run, tmp_path / "w")
    used = set()
    for smk in list((work / "rules").glob("*.smk")) + [work / "Snakefile"]:
        used |= set(re.findall(r"report/(\w+\.rst)", smk.read_text()))
    assert used == {p.name for p in (work / "report").glob("*.rst")}
    proc = snakemake(work, "--report", "report.zip")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert (work / "report.zip").stat().st_size > 10_000


def test_snakemake_report_with_the_workflow_profile_warns_nothing(complete_run: Path,
                                                                  tmp_path: Path):
    """``snakemake --report`` as a user types it (the workflow's profile, picked up by
    itself) prints no RuntimeWarning: Snakemake's default disk_mb, which its report
    evaluates as a coroutine it never awaits (snakemake issue 4280), is a constant in
    profiles/default."""
    work = clone(complete_run, tmp_path / "w")
    proc = subprocess.run([sys.executable, "-m", "snakemake", "--report", "report.zip"],
                          cwd=work, capture_output=True, text=True, timeout=600)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    assert "profiles/default" in out  # the workflow's own profile was read
    assert (work / "report.zip").stat().st_size > 10_000
    assert "RuntimeWarning" not in out, out[-3000:]
