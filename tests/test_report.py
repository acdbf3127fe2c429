"""The report page: built from a small fake results tree (realistic JSON structures and
small images), it shows Table I with the paper's values, the ground-truth checks, the
PSNR heat maps with the dB lost, the camera array, the Fig. 10 crops and the previews;
absent sources give a "not produced" line naming their rule; the bytes are
deterministic; and a headless Chromium renders it with every image decoded."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from plenocal.camera import PinholeCamera, intrinsics, pose, write_cameras
from plenocal.io import write_image, write_json
from plenocal.report.html import build_report
from plenocal.report.sources import layout, psnr_sets, table1_rows
from plenocal.verify.gt_errors import gt_errors

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
    write_json(res / "eval" / "reprojection.json", {
        "reg_a": stats(0.61, 0.48, 10, array=6, hand=4),
        "reg_b": {"sets": {c: stats(0.40 + 0.01 * i, 0.30, 9) for i, c in enumerate(CAMS)}},
        "complete": stats(0.702, 0.55, 63),
        "baseline_sfm": stats(0.812, 0.60, 63),
        "sfm_scratch": dict(stats(0.9, 0.7, 63), num_registered=58),
    })
    sfm = {c: np.linalg.inv(pose(np.eye(3), [0.1, 0, 0])) @ truth[f"{c}/1_1"].cam_to_world
           for c in CAMS}
    for M in sfm.values():
        M[:3, 3] /= 0.02
    rig = {"model": "exact", "n_views": N, "width": W, "height": H, "focal_px": 120.0,
           "views": {v: {"K": truth[f"x00_y00/{v}"].K,
                         "cam_to_central": pose(np.eye(3), [(int(v[2]) - 1) * 2e-4,
                                                            (int(v[0]) - 1) * 2e-4, 0])}
                     for v in VIEWS},
           "exact": {"B": 0.2}, "check": {"verdict": "pass"}}
    write_json(res / "reg_b" / "rig.json", rig)
    write_json(res / "merge" / "scale.json", {"r": 0.0201, "r_used": 0.0201,
                                              "estimator": "mean",
                                              "spread": {"relative": 0.004, "n_shots": 7}})
    write_json(res / "eval" / "gt_errors.json", gt_errors(
        truth, reg_a={"focal_px": 120.3, "poses": sfm}, rig=rig, r=0.0201, calib=calib))
    corners = ["x00_y00", "x02_y00", "x00_y01", "x02_y01"]
    exp1 = {"inputs": [f"{c}/1_1" for c in corners]}
    for name, off in (("calibrated", 0.0), ("ground_truth", 0.3)):
        exp1[name] = {f"{c}/1_1": {"psnr": 28.0 + 0.5 * i + off}
                      for i, c in enumerate(CAMS) if c not in corners}
    write_json(res / "eval" / "synthesis_exp1.json", exp1)
    sides = ["0_1", "1_0", "1_2", "2_1"]
    exp2 = {"cam": CENTRE_CAM, "inputs": sides,
            "calibrated": {v: 36.0 + 0.2 * i for i, v in enumerate(VIEWS) if v not in sides}}
    write_json(res / "eval" / "synthesis_exp2.json", exp2)
    exp3 = {}
    for variant, inputs in (("central", ["1_1"]), ("lateral", ["0_0"])):
        exp3[variant] = {"inputs": [f"{c}/{v}" for c in corners for v in inputs]}
        for name, off in (("calibrated", 0.0), ("ground_truth", 0.2)):
            exp3[variant][name] = {f"{c}/{v}": 29.0 + 0.1 * j + off
                                   for j, (c, v) in enumerate((c, v) for c in CAMS
                                                              for v in VIEWS)
                                   if f"{c}/{v}" not in exp3[variant]["inputs"]}
    write_json(res / "eval" / "synthesis_exp3.json", exp3)
    write_json(res / "convert" / "quality.json", {
        c: {v: {"psnr": 33.0 + 0.1 * k, "ssim": 0.95} for k, v in enumerate(VIEWS)}
        for c in CAMS})
    cap = texture(1)
    write_image(res / "views" / CENTRE_CAM / "1_1.png", cap)
    for k, exp in enumerate(("exp1", "exp2", "exp3_lateral")):
        noisy = np.clip(cap.astype(int) + np.random.default_rng(k).integers(-20, 20, cap.shape),
                        0, 255).astype(np.uint8)
        write_image(res / "eval" / "synth" / f"{exp}_{CENTRE_CAM}_1_1.png", noisy)
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


def test_table1_rows_pair_measurements_with_the_paper():
    doc = {"reg_a": stats(0.61, 0.48, 10, array=6, hand=4),
           "reg_b": {"sets": {"a": stats(0.4, 0.3, 9), "b": stats(0.5, 0.4, 9)}},
           "complete": stats(0.7, 0.5, 63)}
    rows = {r.key: r for r in table1_rows(doc)}
    assert rows["reg_a"].images == "6 + 4" and rows["reg_a"].paper_mean_px == 0.663
    assert rows["reg_b"].mean_px == pytest.approx(0.45) and rows["reg_b"].images == "9 per set"
    assert rows["reg_b"].paper_mean_px == 0.450
    assert rows["complete"].paper_mean_px == 0.714
    assert rows["baseline_sfm"].mean_px is None and rows["baseline_sfm"].paper_mean_px == 0.770
    assert "sfm_scratch" not in rows


def test_psnr_layouts_follow_figs_7_to_9(tmp_path):
    res = make_results(tmp_path)
    exp1 = json.loads((res / "eval" / "synthesis_exp1.json").read_text())
    sets = {s.name: s for s in psnr_sets(exp1, "1_1")}
    assert sorted(sets) == ["calibrated", "ground_truth"]
    g = layout(sets["calibrated"], N, COLS, ROWS)
    assert g.kind == "shots" and g.values.shape == (ROWS, COLS)
    assert g.marks[0, 0] == "input" and math.isnan(g.values[0, 0])
    assert g.values[0, 1] == pytest.approx(28.5)  # x01_y00 is CAMS[1]
    assert g.outside == {"hand00/1_1": pytest.approx(31.0)}
    exp2 = json.loads((res / "eval" / "synthesis_exp2.json").read_text())
    g2 = layout(psnr_sets(exp2, "1_1")[0], N, COLS, ROWS)
    assert g2.kind == "set" and g2.values.shape == (N, N) and g2.marks[0, 1] == "input"
    exp3 = json.loads((res / "eval" / "synthesis_exp3.json").read_text())
    names = sorted(s.name for s in psnr_sets(exp3, "1_1"))
    assert names == ["central/calibrated", "central/ground_truth", "lateral/calibrated",
                     "lateral/ground_truth"]
    g3 = layout(psnr_sets(exp3, "1_1")[0], N, COLS, ROWS)
    assert g3.kind == "views" and g3.values.shape == (ROWS * N, COLS * N)
    assert g3.marks[1, 1] == "input"  # x00_y00/1_1 in the central experiment


def test_page_content_and_determinism(tmp_path):
    res = make_results(tmp_path)
    html = build(res)
    for key in ("reg_a", "reg_b", "complete", "baseline_sfm", "sfm_scratch"):
        assert f'id="t1-{key}"' in html
    for paper in ("0.663", "0.450", "0.714", "0.770"):
        assert f"<td>{paper}</td>" in html
    assert "0.702 / 0.812 = <b>0.865</b>" in html  # complete / baseline, target 0.9
    assert re.search(r'id="gt-a_focal_pct".*?0\.2500.*?pass', html)
    assert "0.30 dB lost to calibration (vs ground-truth cameras, 3 views)" in html
    assert "0.20 dB lost to calibration (vs ground-truth cameras, 59 views)" in html
    assert html.count("<svg") >= 2 + 2 + 1 + 4  # array x2, exp1 x2, exp2, exp3 x4
    assert 'href="../eval/reprojection.json"' in html
    assert 'href="../views/x01_y01/patch_size.png"' in html
    assert "depth/b/hand00.png" in html and "made by rule <code>depth</code>" in html
    assert not re.search(r'(src|href)="(https?:)?//', html), "the page must not fetch"
    assert "Not produced" not in html.split('id="depth"')[0]
    n_img = html.count("<img ")
    assert n_img == 1 + 3 + 2 * 4 + len(CAMS) + 2 * len(CAMS) - 1
    assert len(html) < 600_000
    first = (res / "report" / "index.html").read_bytes()
    build(res)
    assert (res / "report" / "index.html").read_bytes() == first


def test_absent_sources_are_named_with_their_rules(tmp_path):
    res = tmp_path / "results" / "fake"
    res.mkdir(parents=True)
    html = build(res)
    for rel, rule in (("eval/reprojection.json", "reprojection"),
                      ("eval/gt_errors.json", "gt_errors"),
                      ("eval/synthesis_exp1.json", "synthesis_exp1"),
                      ("eval/synthesis_exp3.json", "synthesis_exp3"),
                      ("calibration/cameras.json", "merge"),
                      ("convert/quality.json", "convert_quality")):
        assert f"<code>{rel}</code> is absent (made by rule <code>{rule}</code>" in html
    assert "<img " not in html


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
    assert int(m.group(3)) >= 9
    for key in ("reg_a", "reg_b", "complete", "baseline_sfm"):
        assert f'id="t1-{key}"' in dom
    assert "Complete A+B (proposed)" in dom
    shot = tmp_path / "shot.png"
    run_chromium(binary, res / "report" / "index.html", tmp_path / "profile2",
                 f"--screenshot={shot}", "--window-size=1280,2400", "--hide-scrollbars")
    img = cv2.imread(str(shot))
    assert img is not None and img.shape[1] == 1280
    assert img.std() > 10, "the screenshot is blank"
    keep = os.environ.get("PLENOCAL_REPORT_SCREENSHOT")
    if keep:
        shutil.copy(shot, keep)
