"""The joint refinement (rule refine, issue 32) in the tiny workflow: it keeps every view,
does not raise the errors against ground truth that the paper's Eq. 6 result has, and
stands beside it in Table I, gt_errors and the report; `refine.enabled: false` gives the
paper's method alone."""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import clone, snakemake, tiny_workflow

from plenocal import job_memory
from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.results import read_gt_errors, read_reprojection_table

pytestmark = pytest.mark.workflow


def test_refinement_keeps_every_view_and_does_not_raise_the_errors(tiny_complete_run: Path):
    res = tiny_complete_run / "results" / "tiny"
    refined = read_cameras(res / "calibration" / "cameras.json")
    eq6 = read_cameras(res / "calibration" / "eq6" / "cameras.json")
    assert sorted(refined) == sorted(eq6) and len(refined) == 10 * 9
    info = json.loads((res / "calibration" / "refine.json").read_text())
    assert info["enabled"] and info["views"] == len(eq6)
    obs = info["observations"]
    assert obs["after"]["mean_px"] <= obs["before"]["mean_px"]
    gt = read_gt_errors(res / "eval" / "gt_errors.json")
    for key in ("centre_rmse_mm", "centre_max_mm"):
        assert gt.complete[key] <= gt.eq6[key] * 1.001, key
    for key in ("rms", "max"):
        assert (gt.complete["rotation_err_deg"][key]
                <= gt.eq6["rotation_err_deg"][key] * 1.001), key
    # gt_errors' figures are over every view after one rigid alignment of them all, so one
    # group's largest error may rise while every figure falls: with the patch sizes matched
    # devignetted (registration A's focal length 7 % off) the refinement lowered the
    # rotations' rms 0.154 -> 0.086 and largest 0.312 -> 0.168 deg, and raised the array
    # cameras' largest 0.049 -> 0.069 deg (before: 0.099 -> 0.080, a hand-held shot's
    # 0.165 -> 0.187). Each stays within a tenth of a degree of the truth
    truth = read_cameras(res / "ground_truth" / "cameras.json")
    array = {k for k in truth if not k.startswith("hand")}
    assert array and max_rotation_deg(refined, truth, array) < 0.1
    # the refinement's scale against Eq. 5's and the truth, and where Eq. 6's error lies
    assert gt.refinement["rig_scale_err_pct"] is not None
    assert gt.sources["dominant"] in ("registration A's poses", "the merge's scale",
                                      "the rig")
    rows = read_reprojection_table(res / "eval" / "reprojection.json").rows
    assert rows["complete"]["mean_px"] <= rows["eq6"]["mean_px"]
    assert rows["complete"]["num_images"] == rows["eq6"]["num_images"] == 90
    html = (res / "report" / "index.html").read_text()
    assert 'id="t1-eq6"' in html and 'id="kpi-refine"' in html
    # the calibration's files for other tools that the run made, linked from the page
    for rel in ("cameras.json", "mpeg/cameras.json", "mpeg/rvs", "colmap", "colmap_points",
                "eq6/cameras.json"):
        assert f'href="../calibration/{rel}"' in html, rel
    # the refinement's points and where they came from (refine.tracks, carry_every)
    assert ("from the central views&#x27; matches carried into every 3rd of each shot&#x27;s "
            "other views and from the matches of every view, in one adjustment "
            "(refine.tracks: both, carry_every: 3)") in html
    # the focal length with registration A's standard deviation, which needs no truth
    assert 'id="kpi-focal"' in html and "&plusmn;" in html
    assert "The paper&#x27;s Eq. 6 result (all views, rigid alignment)" in html


def test_colmap_points_hold_the_calibration_and_table_i_points(tiny_complete_run: Path):
    """calibration/colmap_points (rule reprojection_complete): every view of
    calibration/cameras.json with its camera and pose, the 3-D points of Table I's complete
    row as COLMAP filters its models (each observation within 4 px), and image names that
    the views folder holds (a Gaussian-splatting trainer's images folder)."""
    import cv2  # noqa: F401, PLC0415  (before pycolmap)
    import pycolmap  # noqa: PLC0415

    from plenocal.calib.reg_a.colmap import pinhole_from_colmap  # noqa: PLC0415

    res = tiny_complete_run / "results" / "tiny"
    cams = read_cameras(res / "calibration" / "cameras.json")
    rows = read_reprojection_table(res / "eval" / "reprojection.json").rows
    rec = pycolmap.Reconstruction(str(res / "calibration" / "colmap_points"))
    assert rec.num_reg_images() == len(cams) == 90
    assert 0.9 * rows["complete"]["num_points3D"] <= rec.num_points3D() > 100
    assert rec.num_points3D() <= rows["complete"]["num_points3D"]
    for image in rec.images.values():
        assert (res / "views" / image.name).is_file(), image.name
        got = pinhole_from_colmap(image, rec.camera(image.camera_id))
        want = cams[image.name[:-4]]
        np.testing.assert_allclose(got.K, want.K, atol=1e-9)
        np.testing.assert_allclose(got.cam_to_world, want.cam_to_world, atol=1e-9)
        for p2 in image.points2D:
            if p2.has_point3D():
                uv = image.project_point(rec.points3D[p2.point3D_id].xyz)
                assert np.linalg.norm(uv - p2.xy) <= 4.0 + 1e-6


def test_gaussian_splatting_dataset_asked_for_by_path(tiny_complete_run: Path, tmp_path):
    """calibration/gaussian_splatting (rule gaussian_splatting), off the default run: asked
    for by path after a complete run, it is the one job that runs; every view of
    colmap_points with its principal point at its image's centre, named flat, with the
    model's points; the default run still has nothing to do; with
    export.gaussian_splatting on, the default run makes it."""
    import cv2  # noqa: F401, PLC0415  (before pycolmap)
    import pycolmap  # noqa: PLC0415

    work = clone(tiny_complete_run, tmp_path / "run")
    target = "results/tiny/calibration/gaussian_splatting"
    dry = snakemake(work, "-n", target)
    out = dry.stdout + dry.stderr
    assert dry.returncode == 0, out[-3000:]
    assert re.search(r"^gaussian_splatting\s+1$", out, re.M) and re.search(
        r"^total\s+1$", out, re.M), out[-3000:]
    proc = snakemake(work, target)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    gs = work / target
    rec = pycolmap.Reconstruction(str(gs / "sparse" / "0"))
    points = pycolmap.Reconstruction(
        str(work / "results" / "tiny" / "calibration" / "colmap_points"))
    assert rec.num_reg_images() == points.num_reg_images() == 90
    assert rec.num_points3D() == points.num_points3D()
    assert len(list((gs / "images").glob("*.png"))) == 90
    for image in rec.images.values():
        assert "/" not in image.name and (gs / "images" / image.name).is_file()
        cam = rec.camera(image.camera_id)
        assert tuple(cam.params[2:]) == (cam.width / 2, cam.height / 2)
        h, w = cv2.imread(str(gs / "images" / image.name)).shape[:2]
        assert (w, h) == (cam.width, cam.height)
    noop = snakemake(work, "-n")
    assert "Nothing to be done" in noop.stdout + noop.stderr
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg.setdefault("export", {})["gaussian_splatting"] = True
    (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    shutil.rmtree(gs)
    dry = snakemake(work, "-n")
    out = dry.stdout + dry.stderr
    # the switch reruns nothing else (no job's params hold the export block): the export,
    # the report, which lists it now, and the default target's own rule, which runs nothing
    table = out[out.index("Job stats:"):].splitlines()[3:]
    jobs = dict(m.groups() for m in map(re.compile(r"^(\w+)\s+(\d+)$").match, table) if m)
    assert jobs == {"gaussian_splatting": "1", "report": "1", "all": "1", "total": "3"}, \
        out[-3000:]
    html = (work / "results" / "tiny" / "report" / "index.html").read_text()
    assert "calibration/gaussian_splatting</code> <span class=\"missing\">not made" in html
    proc = snakemake(work)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    html = (work / "results" / "tiny" / "report" / "index.html").read_text()
    assert 'href="../calibration/gaussian_splatting"' in html


def max_rotation_deg(calib, truth, keys) -> float:
    """The largest rotation error over ``keys`` after gt_errors' rigid alignment of all
    the views the calibration and the truth share."""
    from plenocal.camera import rotation_angle_deg
    from plenocal.verify.gt_errors import pose_similarity

    shared = sorted(set(calib) & set(truth))
    _, R, _ = pose_similarity(np.array([calib[k].centre for k in shared]),
                              np.array([truth[k].centre for k in shared]),
                              [calib[k].R for k in shared], [truth[k].R for k in shared],
                              with_scale=False)
    return max(rotation_angle_deg(R @ calib[k].R, truth[k].R) for k in shared if k in keys)


def test_refine_disabled_gives_the_paper_method_alone(tiny_complete_run: Path,
                                                      tmp_path: Path):
    work = clone(tiny_complete_run, tmp_path / "run")
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    cfg["refine"] = {**cfg.get("refine", {}), "enabled": False}
    (work / "config.yaml").write_text(yaml.safe_dump(cfg))
    target = "results/tiny/eval/reprojection.json"
    proc = snakemake(work, target, "results/tiny/calibration/refine.json")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    res = work / "results" / "tiny"
    assert _same(res)
    assert json.loads((res / "calibration" / "refine.json").read_text())["enabled"] is False
    rows = read_reprojection_table(res / "eval" / "reprojection.json").rows
    assert "eq6" not in rows and "complete" in rows


def _same(res: Path) -> bool:
    import numpy as np  # noqa: PLC0415

    a = read_cameras(res / "calibration" / "cameras.json")
    b = read_cameras(res / "calibration" / "eq6" / "cameras.json")
    return sorted(a) == sorted(b) and all(
        np.array_equal(a[k].cam_to_world, b[k].cam_to_world) and np.array_equal(a[k].K, b[k].K)
        for k in a)


def _planned_rules(out: str) -> set[str]:
    """The rules (by step: view_features_0 -> view_features) of a dry run's job list."""
    import re  # noqa: PLC0415

    return {re.sub(r"_\d+$", "", m) for m in re.findall(r"^(?:local)?rule (\w+):", out,
                                                         flags=re.M)}


def test_the_calibration_waits_for_no_view_matching_on_the_central_views_tracks(
        tmp_path: Path):
    """refine.tracks: central takes the refinement's points from the central views' own
    matches (rule match_central): the calibration alone plans no SIFT of the other views
    and no view matching; refine.tracks: views plans both and no match_central; both
    plans all three (plenocal.calib.central_tracks)."""
    work = tiny_workflow(tmp_path / "w")
    target = "results/tiny/calibration/cameras.json"
    planned = {}
    for tracks in ("central", "views", "both"):
        proc = snakemake(work, "-n", target, "--config", f'refine={{"tracks": "{tracks}"}}')
        assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
        planned[tracks] = _planned_rules(proc.stdout + proc.stderr)
    assert {"refine", "match_central", "convert_views"} <= planned["central"]
    assert not {"view_features", "view_matches"} & planned["central"]
    assert {"view_features", "view_matches", "refine"} <= planned["views"]
    assert "match_central" not in planned["views"]
    # both: the two matchings
    assert {"match_central", "view_features", "view_matches", "refine"} <= planned["both"]


def _mem_mb(out: str, rule: str) -> int:
    """The memory request of the dry run's first job of ``rule``."""
    import re  # noqa: PLC0415

    block = out[out.index(f"rule {rule}:"):]
    return int(re.search(r"\bmem_mb=(\d+)", block).group(1))


def test_the_memory_requests_grow_with_the_match_databases(tiny_complete_run: Path,
                                                            tmp_path: Path):
    """SLURM kills a job past its request: the refinement's track sets' and Table I's
    triangulations' grow with the databases they read, rule refine's with the track sets
    (plenocal.job_memory), from the fixed requests that every measured geometry fits
    under."""
    work = clone(tiny_complete_run, tmp_path / "run")
    target = "results/tiny/eval/reprojection/complete.json"
    proc = snakemake(work, "-n", target, "--forcerun", "refine_tracks")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    out = proc.stdout + proc.stderr
    # the tiny capture's databases and track sets are small
    assert (_mem_mb(out, "refine_tracks"), _mem_mb(out, "refine"),
            _mem_mb(out, "reprojection_complete")) == (3000, 3000, 1500)
    matches = work / "results" / "tiny" / "matches"
    os.truncate(matches / "database.db", 400 * 10**6)  # a larger array's, as a sparse file
    view_db = (matches / "database.db").stat().st_size
    tracks = work / "results" / "tiny" / "refine" / "tracks" / "views" / "elements.npy"
    with open(tracks, "r+b") as fh:  # a larger array's track set (the dry run reads none)
        fh.truncate(100 * 10**6)
    proc = snakemake(work, "-n", target, "--forcerun", "refine_tracks")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    out = proc.stdout + proc.stderr
    requests = {int(m) for m in re.findall(
        r"rule refine_tracks:[^\n]*\n(?:    [^\n]*\n)*?    resources:[^\n]*\bmem_mb=(\d+)",
        out)}
    assert requests == {3000, job_memory.refine_tracks_mem_mb(view_db)}
    assert job_memory.refine_tracks_mem_mb(view_db) == 4500
    assert _mem_mb(out, "refine") == job_memory.refine_mem_mb(
        sum(f.stat().st_size for f in tracks.parent.parent.glob("*/*"))) >= 3500
    assert _mem_mb(out, "reprojection_complete") == job_memory.reprojection_mem_mb(
        view_db) == 2600


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs two cores for -j2")
def test_the_refine_job_takes_every_core_only_where_it_is_the_runs_sole_target(tmp_path):
    """The calibration alone (its cameras the only target) gives rule refine both cores of
    -j2, since every other job comes before it; the full run, where the verification's
    jobs can run beside it, keeps refine.num_threads (1), as does --set-threads."""
    work = tiny_workflow(tmp_path / "run")
    target = "results/tiny/calibration/cameras.json"

    def refine_threads(*args: str) -> int:
        # a dry run counts one core unless told (Snakemake's -j is --cores only when jobs run)
        dry = snakemake(work, "-n", "--cores", "2", *args)
        out = dry.stdout + dry.stderr
        assert dry.returncode == 0, out[-3000:]
        block = out[out.index("\nrule refine:"):].split("\n\n", 1)[0]
        m = re.search(r"^\s+threads: (\d+)$", block, re.M)
        return int(m.group(1)) if m else 1

    assert refine_threads(target) == 2
    assert refine_threads() == 1
    assert refine_threads(target, "--set-threads", "refine=1") == 1
