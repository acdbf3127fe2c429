"""Rules rig_b, scale and merge end to end on hand-made inputs (a private Snakefile
that includes only rules/common.smk, rules/rig.smk and rules/merge.smk)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from plenocal.artifacts.reg_a import RegistrationA, write_reg_a
from plenocal.camera import PinholeCamera
from plenocal.io.files import write_json

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.mark.workflow
def test_rig_scale_merge_rules(tmp_path):
    import test_rig as T  # noqa: PLC0415

    opt = T.optics()
    _, conv, F_m = T.true_inputs(opt, 6.0, 3)
    (tmp_path / "Snakefile").write_text(
        'configfile: "config.yaml"\n'
        f'include: "{REPO}/rules/common.smk"\n'
        f'include: "{REPO}/rules/rig.smk"\n'
        f'include: "{REPO}/rules/merge.smk"\n'
        "rule all:\n    input: final_targets(),\n    default_target: True\n")
    shutil.copy(REPO / "config.schema.yaml", tmp_path / "config.schema.yaml")
    cfg = {"datasets": {"synthetic": {"views": 3, "simulate": {
        "array": {"cols": 2, "rows": 1}, "handheld": {"count": 1}}}},
        "rig": {"model": "exact"}, "scale": {}}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg))
    (tmp_path / "data/synthetic").mkdir(parents=True)
    # camera.yaml stands in for the simulator's, as its truth/ mark says (a simulated
    # dataset's folder holding a capture's files is refused: common.smk)
    (tmp_path / "data/synthetic/truth").mkdir()
    (tmp_path / "data/synthetic/truth/scene.json").write_text("{}")
    (tmp_path / "data/synthetic/camera.yaml").write_text(yaml.safe_dump({
        "pixel_size_mm": 0.0055, "sensor_width_px": 2048, "sensor_height_px": 1536,
        "main_lens": {"focus_distance_mm": 600.0, "focal_length_mm": 35.0},
        "mla": {"pitch_mm": 0.13, "f_numbers": [2.8], "k": 5.0},
        "array": {"step_mm": 10.0}, "scene": {"near_mm": 470.0, "far_mm": 740.0}}))
    res = tmp_path / "results/synthetic"
    cams = ["x00_y00", "x01_y00", "hand00"]
    poses = {}
    rng = np.random.default_rng(0)
    for i, c in enumerate(cams):
        write_json(res / f"views/{c}/disparity.json", {
            "format": "plenocal.disparity", "version": 1, "mla": "keplerian",
            "D_min": conv.d_min, "D_max": conv.d_max, "convention": "paper", "q_px": conv.q,
            "tile": 6, "D_px": conv.pitch_px, "safe_diameter_px": conv.safe_diameter_px,
            "width": 301, "height": 225, "n_views": 3})
        M = np.eye(4)
        M[0, 3] = i * 0.5
        poses[c] = M
        if c.startswith("x"):
            d = rng.uniform(0.4, 0.9, (225, 301)).astype(np.float32)
            (res / "depth/a").mkdir(parents=True, exist_ok=True)
            (res / "depth/b").mkdir(parents=True, exist_ok=True)
            np.save(res / f"depth/a/{c}.npy", d / 0.02)
            np.save(res / f"depth/b/{c}.npy", d)
    write_reg_a(res / "reg_a/reg_a.json", RegistrationA(
        focal_px=F_m, width=301, height=225, mapper="incremental",
        cameras={c: PinholeCamera(np.eye(3), M, 301, 225) for c, M in poses.items()}))
    env = dict(os.environ, PYTHONPATH=f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    out = subprocess.run(
        [sys.executable, "-m", "snakemake", "--workflow-profile", "none", "-s",
         str(tmp_path / "Snakefile"), "-d", str(tmp_path), "-j1", "-q"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    rig = json.loads((res / "reg_b/rig.json").read_text())
    assert rig["check"]["verdict"] == "pass" and len(rig["views"]) == 9
    scale = json.loads((res / "merge/scale.json").read_text())
    assert scale["r"] == pytest.approx(0.02, rel=1e-6)
    cal = json.loads((res / "calibration/eq6/cameras.json").read_text())
    assert len(cal["cameras"]) == 27
    # x01_y00 sits 0.5 SfM units = 1 cm right of x00_y00
    c0 = np.asarray(cal["cameras"]["x00_y00/1_1"]["cam_to_world"])
    c1 = np.asarray(cal["cameras"]["x01_y00/1_1"]["cam_to_world"])
    assert c1[0, 3] - c0[0, 3] == pytest.approx(0.01)
    mpeg = json.loads((res / "calibration/eq6/mpeg/cameras.json").read_text())
    assert len(mpeg["cameras"]) == 27
    assert (res / "calibration/eq6/colmap/images.bin").is_file()
