"""The report page: built from a small fake results tree (realistic JSON structures and
small images), it shows Table I with the paper's values, the ground-truth checks, the
PSNR heat maps with the dB lost, the camera array, the Fig. 10 crops and the previews;
absent sources give a "not produced" line naming their rule; the bytes are
deterministic; and a headless Chromium renders it with every image decoded."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shutil
import subprocess
from html import escape
from pathlib import Path

import cv2
import numpy as np
import pytest

from plenocal.artifacts import results as typed
from plenocal.artifacts.cameras import write_cameras
from plenocal.artifacts.disparity import FORMAT as DISPARITY_FORMAT
from plenocal.artifacts.disparity import VERSION as DISPARITY_VERSION
from plenocal.artifacts.reg_a import RegistrationA, write_reg_a
from plenocal.artifacts.rig import write_rig
from plenocal.artifacts.scale import ScaleResult, write_scale
from plenocal.calib.refine import RefineSettings
from plenocal.camera import PinholeCamera, intrinsics, pose
from plenocal.convert.quality import summarise
from plenocal.io.files import write_image, write_json
from plenocal.report.exports import EXPORTS
from plenocal.report.html import _hundredths, build_report, shot_means_table
from plenocal.report.sources import PAPER_TABLE1, layout, table1_rows, table_name
from plenocal.verify.gt_errors import gt_errors
from plenocal.verify.synthesis import psnr_tables
from plenocal.versions import version_text

N = 3
COLS, ROWS = 3, 2
W, H = 96, 72
CENTRE_CAM = "x01_y01"
CAMS = [f"x{c:02d}_y{r:02d}" for r in range(ROWS) for c in range(COLS)] + ["hand00"]
VIEWS = [f"{r}_{c}" for r in range(N) for c in range(N)]


def stats(mean, median, n, array=None, hand=None):
    d = {"mean_px": mean, "median_px": median, "num_images": n, "num_observations": 40 * n,
         "num_points3D": 10 * n, "rms_px": mean * 1.3, "colmap_mean_px": mean * 0.9}
    if array is not None:
        d.update(num_array_images=array, num_handheld_images=hand)
    return d


def cameras(shift=0.0):
    out = {}
    for cam in CAMS:
        if cam.startswith("x"):
            M = pose(np.eye(3), [int(cam[1:3]) * 0.01, int(cam[5:7]) * 0.01, 0.0])
        else:
            M = pose(cv2.Rodrigues(np.array([0.0, 0.15, 0.02]))[0], [0.01, -0.02, 0.01])
        for v in VIEWS:
            r, c = int(v[0]), int(v[2])
            K = intrinsics(120.0, (W - 1) / 2 + 0.4 * (c - 1), (H - 1) / 2 + 0.4 * (r - 1))
            MB = pose(np.eye(3), [(c - 1) * 2e-4 + shift, (r - 1) * 2e-4, 0.0])
            out[f"{cam}/{v}"] = PinholeCamera(K, M @ MB, W, H)
    return out


def texture(seed, w=W, h=H):
    rng = np.random.default_rng(seed)
    img = cv2.resize(rng.integers(0, 255, (h // 6, w // 6, 3), dtype=np.uint8), (w, h),
                     interpolation=cv2.INTER_CUBIC)
    return img


def make_results(root: Path) -> Path:
    """A fake results/<d>/ tree as the stages write it (one depth preview missing)."""
    res = root / "results" / "fake"
    truth, calib = cameras(), cameras(shift=5e-6)
    write_cameras(res / "ground_truth" / "cameras.json", truth)
    write_cameras(res / "calibration" / "cameras.json", calib)
    # as plenocal.verify.reprojection and scripts/reprojection.py write it
    typed.write_reprojection_table(res / "eval" / "reprojection.json", typed.ReprojectionTable({
        "reg_a": stats(0.61, 0.48, 10, array=6, hand=4),
        "reg_b": {"sets": {c: stats(0.40 + 0.01 * i, 0.30, 9) for i, c in enumerate(CAMS)},
                  "mean_px": 0.43, "median_px": 0.30, "num_sets": 7, "num_images": 9,
                  "num_observations": 2520},
        "complete": stats(0.702, 0.55, 63, array=54, hand=9),
        "baseline_sfm": dict(stats(0.812, 0.60, 63, array=54, hand=9), num_registered=63),
        "ground_truth": stats(0.31, 0.25, 15),
        "sfm_scratch": {"num_images": 63, "num_registered": 58, "num_models": 2},
    }))
    sfm = {c: np.linalg.inv(pose(np.eye(3), [0.1, 0, 0])) @ truth[f"{c}/1_1"].cam_to_world
           for c in CAMS}
    for M in sfm.values():
        M[:3, 3] /= 0.02
    rig = {"model": "exact", "n_views": N, "width": W, "height": H, "focal_px": 120.0,
           "depth_range_m": [0.4, 0.8], "symbols": {},
           "views": {v: {"K": truth[f"x00_y00/{v}"].K,
                         "cam_to_central": pose(np.eye(3), [(int(v[2]) - 1) * 2e-4,
                                                            (int(v[0]) - 1) * 2e-4, 0])}
                     for v in VIEWS},
           "exact": {"B": 0.2}, "check": {"verdict": "pass", "rel_diff_B": 0.004,
                                          "rel_diff_alpha": -0.01, "tolerance": 0.05}}
    write_rig(res / "reg_b" / "rig.json", rig)
    write_scale(res / "merge" / "scale.json", ScaleResult(
        r=0.0201, r_median=0.0201, r_median_of_ratios=0.0201, estimator="mean",
        spread={"relative": 0.004, "n_shots": 7}))
    errors = gt_errors(
        truth, reg_a=RegistrationA(focal_px=120.3, width=W, height=H, mapper="incremental",
                                   cameras={c: PinholeCamera(np.eye(3), M, W, H)
                                            for c, M in sfm.items()}),
        rig=rig, r=0.0201, calib=calib)
    typed.write_gt_errors(res / "eval" / "gt_errors.json",
                          typed.GroundTruthErrors.from_dict(errors))
    # as scripts/synthesis.py writes them: the runs of experiment1..3
    # (plenocal.verify.synthesis) by (renderer, depth, cameras), flattened by psnr_tables
    corners = ["x00_y00", "x02_y00", "x00_y01", "x02_y01"]
    array = [c for c in CAMS if c.startswith("x")]

    def scores(keys, base):
        # each target one pixel whose error gives the PSNR base + 0.5 i (to rounding)
        return {"errors": {k: {"shape": [1, 1], "sse": np.array([10 ** (-(base + 0.5 * i) / 10)])}
                           for i, k in enumerate(keys)}}

    runs1 = {("dibr", "estimated", name): dict(
        scores([f"{c}/1_1" for c in array if c not in corners], 28.0 + off),
        inputs=[f"{c}/1_1" for c in corners]) for name, off in (("complete", 0.0),
                                                                ("ground_truth", 0.3))}
    sides = [f"{CENTRE_CAM}/{v}" for v in ("0_1", "1_0", "1_2", "2_1")]
    runs2 = {("dibr", "estimated", "complete"): {"sets": {CENTRE_CAM: dict(
        scores([f"{CENTRE_CAM}/{v}" for v in VIEWS if f"{CENTRE_CAM}/{v}" not in sides],
               36.0), inputs=sides)}}}
    runs3 = {}
    for name, off in (("complete", 0.0), ("ground_truth", 0.2)):
        runs3["dibr", "estimated", name] = {}
        for variant, v_in in (("central", "1_1"), ("lateral", "0_0")):
            inputs = [f"{c}/{v_in}" for c in corners]
            runs3["dibr", "estimated", name][variant] = dict(
                scores([f"{c}/{v}" for c in array for v in VIEWS
                        if f"{c}/{v}" not in inputs], 29.0 + off), inputs=inputs)
    # the images' names say nothing: what they show is in the synthesis files
    kept = {1: [("complete", ""), ("ground_truth", "")], 2: [("complete", CENTRE_CAM)],
            3: [("complete", "central"), ("complete", "lateral"), ("ground_truth", "lateral")]}
    cap = texture(1)
    write_image(res / "views" / CENTRE_CAM / "1_1.png", cap)
    k = 0
    for exp, runs in ((1, runs1), (2, runs2), (3, runs3)):
        images = []
        for cameras_, run in kept[exp]:
            noisy = np.clip(cap.astype(int) + np.random.default_rng(k).integers(
                -20, 20, cap.shape), 0, 255).astype(np.uint8)
            write_image(res / "eval" / "synth" / f"e{exp}" / f"kept{k}.png", noisy)
            images.append(typed.SynthImage(f"synth/e{exp}/kept{k}.png", f"{CENTRE_CAM}/1_1",
                                     cameras_, run))
            k += 1
        typed.write_synthesis(res / "eval" / f"synthesis_exp{exp}.json", typed.SynthesisResult(
            experiment=exp, renderer="dibr", tables=tuple(psnr_tables(exp, runs, ["dibr"], 0)),
            setup=typed.SynthesisSetup(near_m=0.4, far_m=0.8, psnr_border_px=8,
                                       depth_method="sgm", depth_quality={},
                                       view_stride=1 if exp == 3 else None),
            images=tuple(images)))
    typed.write_convert_quality(res / "convert" / "quality.json", typed.ConvertQuality.from_dict(
        summarise({c: {v: {"psnr_db": 33.0 + 0.1 * k, "ssim": 0.95}
                       for k, v in enumerate(VIEWS)} for c in CAMS}, "1_1")
        | {"border_px": 6}))
    for i, c in enumerate(CAMS):
        write_image(res / "views" / c / "patch_size.png", texture(10 + i)[:, :, 0])
        depth = (np.linspace(1000, 60000, W * H).reshape(H, W)).astype(np.uint16)
        write_image(res / "depth" / "a" / f"{c}.png", depth)
        if c != "hand00":
            write_image(res / "depth" / "b" / f"{c}.png", texture(30 + i))
    return res


def build(res: Path) -> str:
    out = res / "report" / "index.html"
    build_report(res, out, "fake", cams=CAMS, n_views=N, synthetic=True)
    return out.read_text()


# ---------------------------------------------------------------------------
# Content
# ---------------------------------------------------------------------------


def focal_card(tmp_path, std_px: float | None, refine: dict | None = None) -> str:
    """The report's focal-length card, up to its source link, for registration A at
    120.3 px with deviation ``std_px`` (None: not estimated) and ``refine`` as refine.json
    (None: no refinement)."""
    res = make_results(tmp_path)
    cams = {c: PinholeCamera(intrinsics(120.3, W, H), np.eye(4), W, H) for c in CAMS}
    stats = {} if std_px is None else {"focal_std_px": std_px}
    write_reg_a(res / "reg_a" / "reg_a.json", RegistrationA(
        focal_px=120.3, width=W, height=H, mapper="global", cameras=cams, stats=stats))
    write_json(res / "calibration" / "refine.json", refine or {"enabled": False})
    # up to the card's source link (the advice is a span of its own inside the card)
    return re.search(r'<span class="kpi" id="kpi-focal">(.*?)\[source\]', build(res),
                     re.S).group(1)


@pytest.mark.parametrize("std", [0.6015, None])
def test_focal_length_kpi_gives_registration_a_deviation(tmp_path, std):
    """The summary's focal length: registration A's with its deviation where reg_a.json
    has one (real captures too), else says it was not estimated; the refinement's
    focal length where it ran."""
    kpi = focal_card(tmp_path, std)
    assert "<b>120.30 px</b>as registration A's 120.30 px" in kpi
    if std is None:
        assert "not estimated" in kpi
    else:
        assert "&plusmn; 0.50 %" in kpi


@pytest.mark.parametrize(("std_px", "weak"), [(0.361, False), (0.903, True)])
def test_focal_length_kpi_advises_more_hand_held_shots_over_half_a_percent(tmp_path, std_px,
                                                                          weak):
    """Registration A's deviation over WEAK_FOCAL_SD_PCT (0.30 % and 0.75 % here): the
    summary says the capture fixes the focal length weakly and what to add."""
    kpi = focal_card(tmp_path, std_px)
    assert ("&plusmn; 0.75 %" if weak else "&plusmn; 0.30 %") in kpi
    assert ("fixes the focal length weakly" in kpi) is weak
    assert ("more hand-held shots fixed it better" in kpi) is weak


@pytest.mark.parametrize("std", [{"std_pct": 0.1093, "sigma_px": 0.28},
                                 {"std_pct": 0.0452, "sigma_px": 0.25}, None])
def test_focal_length_kpi_gives_the_refinements_own_deviation_where_asked(tmp_path, std):
    """refine.focal_sd: the refined focal length with its own standard deviation
    (refine.json's focal_px.std) beside registration A's, and over WEAK_REFINED_SD_PCT
    (0.05 %) the advice that the capture does not promise 0.1 %, in place of A's (its
    0.75 % here); without it, A's advice as before."""
    focal = {"registration_a": 120.3, "refined": 120.42, "change_pct": 0.0998,
             **({} if std is None else {"std": std})}
    refine = {"enabled": True, "focal_px": focal, "scale_vs_eq5": {"rig": 1.0001},
              "settings": dataclasses.asdict(RefineSettings(focal_sd=True)),
              "scale_source": "Eq. 5", "points": {"used": 900},
              "observations": {"before": {"mean_px": 0.3}, "after": {"mean_px": 0.2, "n": 9}}}
    kpi = focal_card(tmp_path, 0.903, refine)
    assert "<b>120.42 px</b>" in kpi and "moved it +0.100 % from" in kpi
    if std is not None:
        assert f"&plusmn; {std['std_pct']:.3f} % (1 sd, the refinement" in kpi
    assert ("does not promise it within 0.1 % (2 sd)" in kpi) is (
        std is not None and std["std_pct"] > 0.05)
    assert ("fixes the focal length weakly" in kpi) is (std is None)
    assert "&plusmn; 0.75 %" in kpi  # registration A's, as before


def test_table1_rows_pair_measurements_with_the_paper():
    table = typed.ReprojectionTable({
        "reg_a": stats(0.61, 0.48, 10, array=6, hand=4),
        "reg_b": {"sets": {"a": stats(0.4, 0.3, 9), "b": stats(0.5, 0.4, 9)},
                  "mean_px": 0.45, "median_px": 0.35, "num_images": 9},
        "complete": stats(0.7, 0.5, 63)})
    rows = {r.key: r for r in table1_rows(table)}
    assert rows["reg_a"].images == "6 + 4" and rows["reg_a"].paper_mean_px == 0.663
    assert rows["reg_b"].mean_px == pytest.approx(0.45) and rows["reg_b"].images == "9 per set"
    assert rows["reg_b"].note == "mean over 2 sets (range 0.400-0.500 px)"
    assert rows["reg_b"].paper_mean_px == 0.450
    assert rows["complete"].paper_mean_px == 0.714
    assert rows["baseline_sfm"].mean_px is None and rows["baseline_sfm"].paper_mean_px == 0.770
    assert rows["baseline_sfm"].note == "not in reprojection.json"
    assert "sfm_scratch" not in rows
    assert tuple(PAPER_TABLE1) == typed.TABLE1_ROWS  # every row of the file has its place


def test_table1_refuses_unknown_rows():
    with pytest.raises(ValueError, match=r"unknown rows \['registration_a'\]"):
        typed.ReprojectionTable({"registration_a": stats(0.6, 0.5, 10)})


def test_psnr_layouts_follow_figs_7_to_9(tmp_path):
    res = make_results(tmp_path)
    exp1 = typed.read_synthesis(res / "eval" / "synthesis_exp1.json")
    assert exp1.experiment == 1 and exp1.metric == "psnr_db"
    sets = {table_name(t, exp1.renderer): t for t in exp1.tables}
    assert sorted(sets) == ["complete", "ground_truth"]
    assert sets["complete"].inputs == ("x00_y00/1_1", "x02_y00/1_1", "x00_y01/1_1",
                                       "x02_y01/1_1")
    g = layout(sets["complete"], N, COLS, ROWS)
    assert g.kind == "shots" and g.values.shape == (ROWS, COLS)
    assert g.marks[0, 0] == "input" and math.isnan(g.values[0, 0])
    assert g.values[0, 1] == pytest.approx(28.0)  # x01_y00
    assert g.values[1, 1] == pytest.approx(28.5)  # x01_y01
    assert g.outside == {}
    ((t, gt, lost, n),) = exp1.db_lost()
    assert (t.cameras, gt.cameras, n) == ("complete", "ground_truth", 2)
    assert lost == pytest.approx(0.3)
    exp2 = typed.read_synthesis(res / "eval" / "synthesis_exp2.json")
    (s2,) = exp2.tables
    assert table_name(s2, exp2.renderer) == "complete/x01_y01" and exp2.db_lost() == []
    g2 = layout(s2, N, COLS, ROWS)
    assert g2.kind == "set" and g2.values.shape == (N, N) and g2.marks[0, 1] == "input"
    assert g2.values[0, 0] == pytest.approx(36.0) and g2.values[1, 1] == pytest.approx(37.0)
    exp3 = typed.read_synthesis(res / "eval" / "synthesis_exp3.json")
    s3 = exp3.tables
    assert [table_name(t, exp3.renderer) for t in s3] == [
        "complete/central", "complete/lateral", "ground_truth/central", "ground_truth/lateral"]
    g3 = layout(s3[0], N, COLS, ROWS)
    assert g3.kind == "views" and g3.values.shape == (ROWS * N, COLS * N)
    assert g3.marks[1, 1] == "input"  # x00_y00/1_1 in the central experiment
    assert g3.values[0, 0] == pytest.approx(29.0)  # x00_y00/0_0, the first target
    # x01_y01/2_2: after 8 + 9 + 8 + 8 targets of the shots before it, and 8 of its own
    assert g3.values[3 + 2, 3 + 2] == pytest.approx(29.0 + 0.5 * (8 + 9 + 8 + 8 + 8))
    # another renderer and the true depth are named by their fields
    rvs = typed.PsnrTable("rvs", "true", "complete", "lateral", (), {})
    assert table_name(rvs, "dibr") == "rvs/true_depth/complete/lateral"


def test_page_content_and_determinism(tmp_path):
    res = make_results(tmp_path)
    html = build(res)
    for key in ("reg_a", "reg_b", "complete", "baseline_sfm", "sfm_scratch", "ground_truth"):
        assert f'id="t1-{key}"' in html
    assert "58 of 63 views registered" in html and "<td>54 + 9</td>" in html
    for paper in ("0.663", "0.450", "0.714", "0.770"):
        assert f"<td>{paper}</td>" in html
    assert "0.702 / 0.812 = <b>0.865</b>" in html  # complete / baseline, target 0.9
    assert re.search(r'id="gt-a_focal_pct".*?0\.2500.*?pass', html)
    assert "0.30 dB lost over the whole view (vs ground-truth cameras, 2 views)" in html
    assert "0.20 dB lost over the whole view (vs ground-truth cameras, 50 views)" in html
    assert html.count("<svg") == 3 + 2 + 1 + 4  # array x3, exp1 x2, exp2, exp3 x4
    assert "Exp. 3 (checks A+B), lateral inputs (ground-truth cameras)" in html
    assert 'href="../eval/reprojection.json"' in html
    assert 'href="../views/x01_y01/patch_size.png"' in html
    assert "depth/b/hand00.png" in html and "made by rule <code>depth</code>" in html
    assert not re.search(r'(src|href)="(https?:)?//', html), "the page must not fetch"
    assert "Not produced" not in html.split('id="depth"')[0]
    n_img = html.count("<img ")
    # Fig. 10: captured + 6 syntheses, 2 zooms of captured + 4 calibrated; previews
    assert n_img == 7 + 2 * 5 + len(CAMS) + 2 * len(CAMS) - 1
    assert len(html) < 600_000
    # the versions that decide the bytes, last on the page (plenocal.versions)
    assert html.rstrip().endswith(f'<p class="note">Made by {escape(version_text())}.</p>'
                                  "</main></body></html>")
    assert "numpy " in version_text() and "pycolmap " in version_text()
    first = (res / "report" / "index.html").read_bytes()
    build(res)
    assert (res / "report" / "index.html").read_bytes() == first


SECTIONS = ("overview", "table1", "gt", "summary", "array", "files", "exp1", "exp2", "exp3",
            "fig10", "convert", "patch", "depth")


def sections(html: str) -> dict[str, str]:
    """Each section's HTML by its anchor."""
    parts = re.split(r'<h2 id="(\w+)">', html)
    return {parts[i]: parts[i + 1] for i in range(1, len(parts) - 1, 2)}


def test_every_section_is_shown_from_the_typed_files(tmp_path):
    res = make_results(tmp_path)
    by = sections(build(res))
    assert [k for k in by if k != "sources"] == list(SECTIONS)
    # (one depth preview is absent on purpose; the fake tree holds one export, cameras.json)
    for key in (k for k in SECTIONS[:-1] if k != "files"):
        assert 'class="missing"' not in by[key], (key, by[key][:500])
    assert 'id="table1-rows"' in by["table1"] and "<td>0.702</td>" in by["table1"]
    assert by["gt"].count('<tr id="gt-') == 11  # one row per target (gt_errors.TARGETS)
    # every view's errors: the largest rotation's view is named, as the largest centre
    # error's is
    tables = [t for t in by["gt"].split("<h3>")
              if t.startswith(("Complete calibration (all views", "The paper's Eq. 6 result"))]
    assert tables
    for table in tables:
        row = table.split("rotation error mean / max [deg]", 1)[1].split("</tr>", 1)[0]
        assert re.search(r"\(worst [\w/]+\)", row), row
    assert "0.0201</b>Eq. 5 mean 0.0201" in by["summary"] and "exact model" in by["summary"]
    for key, names in (("exp1", ["complete", "ground_truth"]), ("exp2", ["complete/x01_y01"]),
                       ("exp3", ["complete/central", "complete/lateral",
                                 "ground_truth/central", "ground_truth/lateral"])):
        assert re.findall(rf'id="hm-{key}-([\w/]+)"', by[key]) == names, key
    # Fig. 10: every image the synthesis files list, labelled by its fields (the files'
    # names say nothing)
    for label in ("Exp. 1 (checks A)", "Exp. 1 (checks A) (ground-truth cameras)",
                  "Exp. 2 (checks B)", "Exp. 3 (checks A+B), central inputs",
                  "Exp. 3 (checks A+B), lateral inputs",
                  "Exp. 3 (checks A+B), lateral inputs (ground-truth cameras)"):
        assert f'alt="{label}"' in by["fig10"], label
    assert 'href="../eval/synth/e3/kept5.png"' in by["fig10"]
    assert "<td>33.40</td>" in by["convert"]  # view 1_1: the 5th of each shot
    # how to read the previews: each depth preview stretched to its own range
    assert "each preview stretched to its own 1st-99th percentile" in by["depth"]
    assert "its scale in px on the bar" in by["patch"]


def test_a_file_of_another_version_is_named_on_the_page(tmp_path):
    res = make_results(tmp_path)
    for rel in ("eval/synthesis_exp2.json", "eval/reprojection.json"):
        doc = json.loads((res / rel).read_text())
        write_json(res / rel, {**doc, "version": 0})
    by = sections(build(res))
    assert ("eval/synthesis_exp2.json: not a synthesis result of version 2 (format "
            "&#x27;plenocal.synthesis&#x27;, version 0); rerun rule synthesis_exp&lt;k&gt;"
            in by["exp2"])
    assert "not a Table I (reprojection.json) of version 1" in by["table1"]
    assert "run rule reprojection" in by["table1"] and "is absent" not in by["table1"]
    # the other sections are unaffected, and Fig. 10 shows the images the others list
    assert 'id="hm-exp3-complete/central"' in by["exp3"]
    assert "Exp. 2 (checks B)" not in by["fig10"] and "Exp. 3 (checks A+B)" in by["fig10"]


def test_registration_a_without_an_array_step_is_given_in_millimetres(tmp_path):
    """An array of one shot has no step (gt_errors gives None): the section says so, and
    the check in % of the step reads n/a, where formatting None stopped the report."""
    res = make_results(tmp_path)
    rel = res / "eval" / "gt_errors.json"
    doc = json.loads(rel.read_text())
    a = doc["registration_a"]
    a["array_step_m"] = a["centre_rmse_pct_step"] = None
    a["centre_aligned"]["centre_rmse_pct_step"] = None
    for c in doc["checks"]:
        if c["name"] == "a_centre_pct_step":
            c["value"] = c["pass"] = None
    write_json(rel, doc)
    by = sections(build(res))
    assert "mm (no array step: no two array shots are neighbours)" in by["gt"]
    row = re.search(r'<tr id="gt-a_centre_pct_step">.*?</tr>', by["gt"]).group(0)
    assert '<span class="na">n/a</span>' in row


def test_the_scale_of_one_shot_gives_no_spread(tmp_path):
    """Eq. 5 on an array of one shot: a "relative spread 0.0000 over 1 shots" read as a
    measured agreement."""
    res = make_results(tmp_path)
    write_scale(res / "merge" / "scale.json", ScaleResult(
        r=0.0201, r_median=0.0201, r_median_of_ratios=0.0201, estimator="mean",
        spread={"relative": 0.0, "n_shots": 1}))
    summary = sections(build(res))["summary"]
    assert "Eq. 5 mean 0.0201, from one shot (no spread over shots to give)" in summary
    assert "relative spread" not in summary


def test_exp1_without_a_shot_to_synthesise_says_why(tmp_path):
    """Exp. 1 renders the array shots that are not corners: an array of one shot (or 2 x
    2) has none, and its empty tables are the array's doing, not a fault."""
    from plenocal.artifacts.results import read_synthesis
    from plenocal.report.html import Page, _psnr_section

    res = make_results(tmp_path)
    rel = res / "eval" / "synthesis_exp1.json"
    doc = json.loads(rel.read_text())
    for t in doc["tables"]:
        t["psnr_db"], t["surface_psnr_db"] = {}, {}
    write_json(rel, doc)
    result = read_synthesis(rel)
    for (cols, rows), said in (((1, 1), "every shot of this 1 x 1 array is a corner"),
                               ((2, 2), "every shot of this 2 x 2 array is a corner"),
                               ((3, 2), "holds no per-view PSNR")):
        page = Page(res, "fake")
        _psnr_section(page, "exp1", result, "", N, cols, rows)
        assert said in "".join(page.parts), (cols, rows, page.parts)


def test_the_synthesis_verdict_follows_the_surfaces_where_they_are_scored(tmp_path):
    """Exp. 1's complete calibration 2 dB under the ground-truth cameras over the whole view
    (where a renderer's choices at occlusion edges favour exactly aligned cameras) but 0.25
    dB on the surfaces: the card passes, on the surfaces' figure, and shows both. With
    estimated depth (each set on its own maps) the figures are shown and not judged: the
    estimator's answer to cameras moved by 1 um moves them by tenths of a dB."""
    from plenocal.artifacts.results import read_synthesis
    from plenocal.report.html import Page, _psnr_section

    res = make_results(tmp_path)
    rel = res / "eval" / "synthesis_exp1.json"
    doc = json.loads(rel.read_text())
    for t in doc["tables"]:
        whole = 30.0 if t["cameras"] == "complete" else 32.0
        surface = 40.0 if t["cameras"] == "complete" else 40.25
        t["psnr_db"] = {k: whole for k in t["psnr_db"]}
        t["surface_psnr_db"] = {k: surface for k in t["psnr_db"]}
    write_json(rel, doc)
    page = Page(res, "fake")
    _psnr_section(page, "exp1", read_synthesis(rel), "", N, COLS, ROWS)
    html = "".join(page.parts)
    card = "</span>".join(html.split('id="kpi-exp1-complete')[1].split("</span>")[0:3])
    assert "0.25 dB lost to calibration on the surfaces (2 views" in card
    assert "pass" not in card and "FAIL" not in card
    assert "estimated depth, each camera set on its own maps" in card
    for t in doc["tables"]:
        t["depth"] = "true"
    write_json(rel, doc)
    page = Page(res, "fake")
    _psnr_section(page, "exp1", read_synthesis(rel), "", N, COLS, ROWS)
    html = "".join(page.parts)
    card = html.split('id="kpi-exp1-true_depth/complete')[1].split("</span>")[0:3]
    card = "</span>".join(card)
    assert "estimated depth" not in card
    assert "2.00 dB lost over the whole view (vs ground-truth cameras, 2 views)" in card
    assert "0.25 dB lost to calibration on the surfaces (2 views" in card
    assert "pass" in card and "FAIL" not in card
    # without surface figures the whole view's is judged
    for t in doc["tables"]:
        t["surface_psnr_db"] = {}
    write_json(rel, doc)
    page = Page(res, "fake")
    _psnr_section(page, "exp1", read_synthesis(rel), "", N, COLS, ROWS)
    assert "FAIL" in "".join(page.parts)


def test_the_calibration_files_for_other_tools_are_listed_as_the_run_made_them(tmp_path):
    """Section "files": every export (exports.EXPORTS) with its tools; the ones the run made
    linked, an asked-for one that is gone said absent, the others named with their rule and
    the command that makes them."""
    res = make_results(tmp_path)
    (res / "calibration" / "colmap").mkdir(parents=True)
    (res / "calibration" / "colmap" / "cameras.txt").write_text("# model\n")
    (res / "calibration" / "gaussian_splatting").mkdir()  # on disk, not made by the run
    out = res / "report" / "index.html"
    made = ["calibration/cameras.json", "calibration/colmap", "calibration/mpeg/cameras.json"]
    build_report(res, out, "fake", cams=CAMS, n_views=N, synthetic=True, exports=made)
    files = sections(out.read_text())["files"]
    assert files.count("<tr id=\"file-") == len(EXPORTS)
    for rel in ("calibration/cameras.json", "calibration/colmap"):
        assert f'href="../{rel}"' in files
    assert "calibration/mpeg/cameras.json</code> <span class=\"missing\">absent" in files
    for e in EXPORTS:
        if e.rel not in made:
            assert (f"<code>{e.rel}</code> <span class=\"missing\">not made by this run"
                    f"</span> <span class=\"note\">(rule <code>{e.rule}</code>: <code>"
                    f"snakemake -j2 results/fake/{e.rel}</code>)") in files, e.rel
        assert escape(e.tools) in files
    # without the run's list, what is on disk
    build_report(res, out, "fake", cams=CAMS, n_views=N, synthetic=True)
    files = sections(out.read_text())["files"]
    assert 'href="../calibration/gaussian_splatting"' in files
    assert "calibration/mpeg/cameras.json</code> <span class=\"missing\">not made" in files


def test_absent_sources_are_named_with_their_rules(tmp_path):
    res = tmp_path / "results" / "fake"
    res.mkdir(parents=True)
    html = build(res)
    for rel, rule in (("eval/reprojection.json", "reprojection"),
                      ("eval/gt_errors.json", "gt_errors"),
                      ("eval/synthesis_exp1.json", "synthesis_exp1"),
                      ("eval/synthesis_exp3.json", "synthesis_exp3"),
                      ("calibration/cameras.json", "refine"),
                      ("convert/quality.json", "convert_quality")):
        assert f"<code>{rel}</code> is absent (made by rule <code>{rule}</code>" in html
    assert "<img " not in html


def _set_means(res: Path, complete: float, baseline: float, truth: float | None) -> None:
    path = res / "eval" / "reprojection.json"
    rows = typed.read_reprojection_table(path).rows
    rows["complete"]["mean_px"], rows["baseline_sfm"]["mean_px"] = complete, baseline
    if truth is None:
        rows.pop("ground_truth", None)
    else:
        rows["ground_truth"]["mean_px"] = truth
    typed.write_reprojection_table(path, typed.ReprojectionTable(rows))


def test_table1_verdict_judges_against_what_the_data_allow(tmp_path):
    res = make_results(tmp_path)
    # synthetic: 0.932 passes when the true cameras themselves only reach 0.929
    _set_means(res, 0.7456, 0.8, 0.7432)
    html = build(res)
    line = re.search(r'<p id="table1-verdict">.*?</p>', html).group(0)
    assert "<b>0.932</b>" in line and "0.929" in line and "ground-truth" in line
    assert 'class="pass"' in line, line
    # ... and fails well above that floor
    _set_means(res, 0.80, 0.8, 0.7432)
    line = re.search(r'<p id="table1-verdict">.*?</p>', build(res)).group(0)
    assert 'class="fail"' in line, line
    # a real capture: the paper's 0.927
    _set_means(res, 0.7456, 0.8, None)
    build_report(res, res / "report" / "index.html", "fake", cams=CAMS, n_views=N,
                 synthetic=False)
    line = re.search(r'<p id="table1-verdict">.*?</p>',
                     (res / "report" / "index.html").read_text()).group(0)
    assert "0.927" in line and 'class="fail"' in line, line
    _set_means(res, 0.7336, 0.8, None)  # 0.917
    build_report(res, res / "report" / "index.html", "fake", cams=CAMS, n_views=N,
                 synthetic=False)
    line = re.search(r'<p id="table1-verdict">.*?</p>',
                     (res / "report" / "index.html").read_text()).group(0)
    assert 'class="pass"' in line, line


def test_first_screen_says_real_or_synthetic_and_what_was_not_checked(tmp_path):
    res = make_results(tmp_path)
    html = build(res)
    first = html[:html.index('id="table1"')]
    assert "Synthetic dataset" in first and "Real capture" not in first
    assert 'id="not-checked"' not in html
    # a real capture: no ground truth, no ideal renders
    for rel in ("eval/gt_errors.json", "ground_truth/cameras.json", "convert/quality.json"):
        (res / rel).unlink()
    _set_means(res, 0.7336, 0.8, None)
    out = res / "report" / "index.html"
    build_report(res, out, "fake", cams=CAMS, n_views=N, synthetic=False)
    html = out.read_text()
    first = html[:html.index('id="table1"')]
    assert "Real capture" in first and 'id="not-checked"' in first
    for what in ("ideal renders", "focal length", "scale r", "centres (0.1 mm)", "(0.02 deg)",
                 "dB lost"):
        assert what in first, what
    # absent ground truth is expected here, not reported as a missing output
    assert "Not produced" not in html.split('id="patch"')[0]


def test_stage_warnings_reach_the_first_screen(tmp_path):
    res = make_results(tmp_path)
    html = build(res)
    assert 'id="warnings"' in html and "No warnings" in html
    # each output as its producer writes it: a list of messages
    write_json(res / "views" / "x01_y00" / "disparity.json", {
        "format": DISPARITY_FORMAT, "version": DISPARITY_VERSION, "D_min": 1.0, "D_max": 2.0,
        "warnings": ["only 12 % of the micro images have a confident patch size"]})
    write_json(res / "reg_a" / "features.json", {
        "keypoints": {}, "warnings": ["few features in hand01"]})
    rig = json.loads((res / "reg_b" / "rig.json").read_text())
    rig["check"] = {"verdict": "fail", "rel_diff_B": 0.12, "rel_diff_alpha": -0.01,
                    "tolerance": 0.05}
    write_json(res / "reg_b" / "rig.json", rig)
    html = build(res)
    box = re.search(r'<div class="warnbox" id="warnings">.*?</div>', html, flags=re.S)
    assert box, html[:3000]
    box = box.group(0)
    assert html.index('id="warnings"') < html.index('id="table1"')
    assert "Warnings (3)" in box
    assert "views/x01_y00/disparity.json" in box and "confident patch size" in box
    assert "reg_a/features.json" in box and "few features in hand01" in box
    assert ("the inverse check of Eqs. 2-3 failed: from the measured near/far distances "
            "(camera.yaml scene.near_mm, far_mm) B differs by +12.0 %, alpha differs by "
            "-1.0 % (tolerance 5 %); check those distances and the datasheet") in box


def test_a_shot_out_of_step_with_the_others_is_named(tmp_path):
    """A shot whose lenses matched far less than the others' (a frame of another camera,
    which only the set-up frame's check would catch) is named on the first screen with the
    shares; a capture whose shots differ as simulated ones do (0.74-1.0 of the median) is
    not."""
    from plenocal.report.sources import shots_out_of_step

    res = make_results(tmp_path)

    def shares(values):
        for cam, v in zip(CAMS, values, strict=True):
            write_json(res / "views" / cam / "disparity.json", {
                "format": DISPARITY_FORMAT, "version": DISPARITY_VERSION, "D_min": 1.0,
                "D_max": 2.0, "patch_size_px": {"confident_share": v}})

    shares([0.68] * (len(CAMS) - 1) + [0.01])
    (w,) = shots_out_of_step(res, CAMS)
    assert w.source == "views/hand00/disparity.json"
    assert w.message.startswith("hand00: 1 % of its lenses matched, against a median of 68 % "
                                f"over the {len(CAMS)} shots: a frame of another camera")
    box = re.search(r'<div class="warnbox" id="warnings">.*?</div>', build(res),
                    flags=re.S).group(0)
    assert "hand00: 1 % of its lenses matched" in box
    shares([0.68, 0.5, 0.7, 0.62, 0.43, 0.66, 0.7][: len(CAMS) - 1] + [0.55]
           + [0.6] * max(0, len(CAMS) - 8))
    assert shots_out_of_step(res, CAMS) == []


def test_stage_warnings_of_another_shape_are_named_not_guessed(tmp_path):
    """A warnings list of another shape, or rig.json's check with a renamed key, is not
    read as well as it can be (nor dropped): the box says which file, which key and what
    to do."""
    res = make_results(tmp_path)
    write_json(res / "reg_a" / "features.json", {
        "keypoints": {}, "warnings": [{"message": "few features in hand01"}]})
    rig = json.loads((res / "reg_b" / "rig.json").read_text())
    rig["check"] = {"result": "fail", "rel_diff_B": 0.12, "rel_diff_alpha": -0.01,
                    "tolerance": 0.05}
    write_json(res / "reg_b" / "rig.json", rig)
    box = re.search(r'<div class="warnbox" id="warnings">.*?</div>', build(res),
                    flags=re.S).group(0)
    assert "Warnings (2)" in box and "</a>: few features in hand01</li>" not in box
    assert ("reg_a/features.json: key &#x27;warnings&#x27;, entry 0 = {&#x27;message&#x27;: "
            "&#x27;few features in hand01&#x27;} is not a message (a non-empty string); "
            "rerun rule features_a") in box
    assert ("reg_b/rig.json: the inverse check of Eqs. 2-3 has no key "
            "&#x27;check.verdict&#x27;; rerun rule rig_b") in box


# ---------------------------------------------------------------------------
# Rendering in a browser
# ---------------------------------------------------------------------------

PROBE = """<script>
window.addEventListener('load', function () {
  var im = Array.prototype.slice.call(document.images);
  var ok = im.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  var svg = Array.prototype.filter.call(document.querySelectorAll('svg'), function (s) {
    return s.getBoundingClientRect().width > 0; }).length;
  var p = document.createElement('p');
  p.id = 'probe';
  p.textContent = 'images ' + ok + '/' + im.length + ' svg ' + svg;
  document.body.appendChild(p);
});
</script>"""


def chromium() -> str:
    """The Chromium binary; installed with apt-get when absent and possible, otherwise
    the test is skipped with the reason (never passed silently)."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    if os.geteuid() == 0 and shutil.which("apt-get"):
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        for cmd in (["apt-get", "update"], ["apt-get", "install", "-y", "chromium"]):
            try:
                subprocess.run(cmd, env=env, capture_output=True, timeout=600, check=False)
            except (OSError, subprocess.TimeoutExpired):
                break
        path = shutil.which("chromium")
        if path:
            return path
    pytest.skip("no Chromium: install Debian's `chromium` package (apt-get install -y "
                "chromium) to run the browser test of the report")


def run_chromium(binary: str, page: Path, profile: Path, *extra: str) -> str:
    cmd = [binary, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", "--disable-dev-shm-usage", f"--user-data-dir={profile}",
           "--virtual-time-budget=5000", *extra, page.as_uri()]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    if out.returncode != 0:
        raise AssertionError(f"chromium failed ({out.returncode}): {out.stderr[-2000:]}")
    return out.stdout


def test_page_renders_in_headless_chromium(tmp_path):
    binary = chromium()
    res = make_results(tmp_path)
    html = build(res)
    n_img = html.count("<img ")
    probe = res / "report" / "probe.html"
    probe.write_text(html.replace("</body>", PROBE + "</body>"))
    dom = run_chromium(binary, probe, tmp_path / "profile", "--dump-dom")
    m = re.search(r'<p id="probe">images (\d+)/(\d+) svg (\d+)</p>', dom)
    assert m, "the probe script did not run: " + dom[-500:]
    assert int(m.group(2)) == n_img and int(m.group(1)) == n_img, m.group(0)
    assert int(m.group(3)) == 10
    for key in ("reg_a", "reg_b", "complete", "baseline_sfm"):
        assert f'id="t1-{key}"' in dom
    assert "Complete A+B (proposed, Eq. 6)" in dom
    shot = tmp_path / "shot.png"
    run_chromium(binary, res / "report" / "index.html", tmp_path / "profile2",
                 f"--screenshot={shot}", "--window-size=1280,2400", "--hide-scrollbars")
    img = cv2.imread(str(shot))
    assert img is not None and img.shape[1] == 1280
    assert img.std() > 10, "the screenshot is blank"
    keep = os.environ.get("PLENOCAL_REPORT_SCREENSHOT")
    if keep:
        shutil.copy(shot, keep)


def test_the_refinements_track_source_is_said_in_words_for_each_setting():
    from plenocal.report.html import track_source

    assert track_source({"tracks": "views", "carry_every": 3}) == (
        "from the matches of every view (refine.tracks: views)")
    assert track_source({"tracks": "central", "carry_every": 1}) == (
        "from the central views' matches carried into all of each shot's other views "
        "(refine.tracks: central, carry_every: 1)")
    both = track_source({"tracks": "both", "carry_every": 3})
    assert "every 3rd of each shot's other views" in both
    assert "and from the matches of every view" in both
    assert both.endswith("(refine.tracks: both, carry_every: 3)")


def test_a_difference_that_rounds_to_zero_reads_0_00_not_minus():
    assert _hundredths(-0.001) == "0.00"
    assert _hundredths(0.004) == "0.00"
    assert _hundredths(-0.006) == "-0.01"
    assert _hundredths(0.114) == "0.11"


def test_the_shot_means_are_laid_out_as_the_array():
    html = shot_means_table({"x00_y00": 30.0, "x01_y00": 31.0, "x00_y01": 29.5,
                             "hand00": 28.25})
    rows = re.findall(r"<tr>(.*?)</tr>", html)
    assert rows[0] == ("<th class=l>mean PSNR [dB]</th><th>x00</th><th>x01</th>")
    assert rows[1] == "<th class=l>y00</th><td>30.00</td><td>31.00</td>"
    assert rows[2] == "<th class=l>y01</th><td>29.50</td><td></td>"  # no x01_y01
    assert "hand-held" in rows[3] and "hand00 28.25" in rows[3]


def test_exp3_stride_and_identical_syntheses_are_said(tmp_path):
    """Exp. 3 on every 2nd view row and column: the views it did not synthesise are blank
    in its heat maps, not hatched as its inputs are, and the caption and the mean say so;
    two syntheses of the same bytes (for the central view Exp. 3's central inputs are Exp.
    1's) are shown once in Fig. 10, labelled by both; each heat map's hatch pattern has an
    id of its own."""
    res = make_results(tmp_path)
    path = res / "eval" / "synthesis_exp3.json"
    doc = typed.read_synthesis(path)
    odd = ("0_1", "1_0", "1_2", "2_1")  # the views a stride of 2 leaves out of a 3 x 3 set
    sparse = tuple(dataclasses.replace(t, psnr_db={k: v for k, v in t.psnr_db.items()
                                                   if not k.endswith(odd)})
                   for t in doc.tables)
    typed.write_synthesis(path, dataclasses.replace(
        doc, tables=sparse, setup=dataclasses.replace(doc.setup, view_stride=2)))
    e1 = typed.read_synthesis(res / "eval" / "synthesis_exp1.json")
    central = next(i for i in doc.images if i.run == "central")
    (res / "eval" / central.path).write_bytes((res / "eval" / e1.images[0].path).read_bytes())
    html = build(res)
    by = sections(html)
    assert "blank: views not synthesised (every 2nd view row and column" in by["exp3"]
    assert "(every 2nd view row and column)" in by["exp3"]  # the means' cards
    assert 'fill="#fafafa"' in by["exp3"] and 'fill="url(#hatch-exp3-complete-central)"' in by[
        "exp3"]
    ids = re.findall(r'id="([^"]+)"', html)
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    assert 'alt="Exp. 1 (checks A) = Exp. 3 (checks A+B), central inputs"' in by["fig10"]
    assert 'alt="Exp. 3 (checks A+B), central inputs"' not in by["fig10"]


def test_fig10_zooms_are_the_views_own_pixels(tmp_path):
    """Fig. 10's zooms are lossless (PNG) crops of the files, shown at an integer
    magnification: every pixel a block of one size, no JPEG block or ringing to read as
    detail."""
    import base64

    res = make_results(tmp_path)
    fig10 = sections(build(res))["fig10"]
    zooms = re.findall(r'<div class="crops"><p class=note>zoom x=(\d+), y=(\d+), (\d+) x (\d+) px'
                       r'</p>(.*?)</div>', fig10, flags=re.S)
    assert zooms
    for x, y, w, h, figs in zooms:
        x, y, w, h = int(x), int(y), int(w), int(h)
        imgs = re.findall(r'<img class="px" src="data:image/(\w+);base64,([^"]+)" '
                          r'width="(\d+)" height="(\d+)" alt="([^"]*)"', figs)
        assert imgs
        for kind, _data, dw, dh, alt in imgs:
            assert kind == "png" and (int(dw), int(dh)) == (2 * w, 2 * h), alt
        kind, data, _, _, alt = imgs[0]
        assert alt.startswith("captured")
        shown = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8),
                             cv2.IMREAD_UNCHANGED)
        cam_view = re.search(r'href="\.\./(views/[^"]+\.png)"', figs).group(1)
        src = cv2.imread(str(res / cam_view), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(shown, src[y:y + h, x:x + w])
