"""The evaluation results that the report reads (plenocal.artifacts.results): each written
and read by one definition, with a format version that the reader checks, and with what
it holds (experiment, camera sets, metric) in fields of the file."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plenocal.artifacts.results import (
    Check,
    ConvertQuality,
    DepthQuality,
    GroundTruthErrors,
    PsnrStats,
    PsnrTable,
    ReprojectionTable,
    SynthesisResult,
    SynthesisSetup,
    SynthImage,
    read_convert_quality,
    read_gt_errors,
    read_reprojection_table,
    read_synthesis,
    write_convert_quality,
    write_gt_errors,
    write_reprojection_table,
    write_synthesis,
)
from plenocal.convert.quality import summarise
from plenocal.io.files import read_json, write_json
from plenocal.verify.synthesis import psnr_tables


def _refuses_other_versions(path, read, name: str, remedy: str) -> None:
    """``read`` refuses the file at ``path`` as another version, as the unversioned layout
    of before, and without one of its keys, naming the file and the remedy."""
    doc = read_json(path)
    v = doc["version"]
    write_json(path, {**doc, "version": v + 1})
    with pytest.raises(ValueError, match=rf"{path.name}: not a {name} of version {v} "
                                         rf"\(format '{doc['format']}', version {v + 1}\); "
                                         rf"{remedy}"):
        read(path)
    write_json(path, {k: v for k, v in doc.items() if k not in ("format", "version")})
    with pytest.raises(ValueError, match=r"\(format None, version None\)"):
        read(path)
    key = sorted(k for k in doc if k not in ("format", "version"))[0]
    write_json(path, {k: v for k, v in doc.items() if k != key})
    with pytest.raises(ValueError, match=rf"without key '{key}'; the file is damaged"):
        read(path)
    path.unlink()
    with pytest.raises(FileNotFoundError, match=remedy):
        read(path)


def test_table1_round_trip_and_versions(tmp_path):
    rows = {"reg_a": {"mean_px": 0.61, "median_px": 0.48, "num_images": 10},
            "reg_b": {"mean_px": 0.4, "sets": {"x00_y00": {"mean_px": 0.4}}},
            "complete": {"mean_px": 0.7, "num_array_images": 54, "num_handheld_images": 9},
            "baseline_sfm": {"mean_px": 0.8, "num_registered": 63}}
    path = tmp_path / "reprojection.json"
    write_reprojection_table(path, ReprojectionTable(rows))
    doc = read_json(path)
    assert (doc["format"], doc["version"], doc["metric"]) == (
        "plenocal.table1", 1, "reprojection_error_px")
    back = read_reprojection_table(path)
    assert back == ReprojectionTable(rows)
    with pytest.raises(ValueError, match="unknown rows"):
        ReprojectionTable({"merged": {"mean_px": 0.7}})
    _refuses_other_versions(path, read_reprojection_table,
                            r"Table I \(reprojection.json\)", "run rule reprojection")


def test_gt_errors_round_trip_and_versions(tmp_path):
    errors = GroundTruthErrors(
        n_views=3,
        checks=(Check("a_focal_pct", "registration A: focal length error", 0.25, 0.5, "%",
                      True),
                Check("scale_pct", "scale r error (Eq. 5)", None, 1.0, "%", None)),
        targets={"a_focal_pct": {"limit": 0.5, "unit": "%", "what": "focal"}},
        registration_a={"focal_px": 120.3, "focal_px_truth": 120.0})
    path = tmp_path / "gt_errors.json"
    write_gt_errors(path, errors)
    doc = read_json(path)
    assert doc["checks"][0]["pass"] is True and "scale" not in doc
    assert read_gt_errors(path) == errors
    _refuses_other_versions(path, read_gt_errors, "gt_errors.json", "run rule gt_errors")


def _errors(psnr: dict[str, float]) -> dict[str, dict]:
    """A run's errors per ring (plenocal.verify.scores) for targets of one pixel whose
    PSNR is the given one, to rounding."""
    return {t: {"shape": [1, 1], "sse": np.array([10.0 ** (-db / 10)])}
            for t, db in psnr.items()}


def _rounded(tables: list[PsnrTable]) -> tuple[PsnrTable, ...]:
    return tuple(replace(t, psnr_db={k: round(v, 9) for k, v in t.psnr_db.items()})
                 for t in tables)


def test_synthesis_round_trip_db_lost_and_versions(tmp_path):
    inputs = ["x00_y00/1_1", "x02_y00/1_1"]
    runs = {("dibr", "estimated", "ground_truth"): {"inputs": inputs, "errors": _errors({
                "x01_y00/1_1": 30.5, "x01_y01/1_1": 31.0})},
            ("dibr", "estimated", "complete"): {"inputs": inputs, "errors": _errors({
                "x01_y00/1_1": 30.0, "x01_y01/1_1": 30.0})},
            ("dibr", "true", "complete"): {"inputs": inputs,
                                           "errors": _errors({"x01_y00/1_1": 33.0})}}
    tables = _rounded(psnr_tables(1, runs, ["dibr"], 0))
    # ordered by renderer, depth, cameras: the complete calibration before the truth
    assert [(t.depth, t.cameras) for t in tables] == [
        ("estimated", "complete"), ("estimated", "ground_truth"), ("true", "complete")]
    assert tables[1].psnr_db == {"x01_y00/1_1": 30.5, "x01_y01/1_1": 31.0}
    quality = DepthQuality(pixels=900, valid_share=0.96, within_share=0.9,
                           within_of_valid=0.9375, median_rel_error=0.0031, tolerance=0.01)
    result = SynthesisResult(experiment=1, renderer="dibr", tables=tables,
                             setup=SynthesisSetup(near_m=0.4, far_m=0.8, psnr_border_px=8,
                                                  depth_method="sgm",
                                                  depth_quality={"x00_y00/1_1": quality}),
                             images=(SynthImage("synth/exp1/a.png", "x01_y01/1_1",
                                                "complete", ""),))
    path = tmp_path / "synthesis_exp1.json"
    write_synthesis(path, result)
    doc = read_json(path)
    assert (doc["format"], doc["version"]) == ("plenocal.synthesis", 2)
    assert (doc["experiment"], doc["metric"], doc["renderer"]) == (1, "psnr_db", "dibr")
    # version 2: what the tables hold is not repeated
    assert sorted(doc) == ["experiment", "format", "images", "metric", "renderer", "setup",
                           "tables", "version"]
    back = read_synthesis(path)
    assert back == result
    ((ours, truth, lost, n),) = back.db_lost()  # the true depth has no ground-truth twin
    assert (ours.cameras, truth.cameras, n) == ("complete", "ground_truth", 2)
    assert lost == pytest.approx(0.75)
    with pytest.raises(ValueError, match="no experiment 4"):
        SynthesisResult(experiment=4, renderer="dibr", tables=(), setup=result.setup)
    with pytest.raises(ValueError, match="cameras 'truth'"):
        PsnrTable("dibr", "estimated", "truth", "", (), {})
    _refuses_other_versions(path, read_synthesis, "synthesis result",
                            "rerun rule synthesis_exp<k>")


def _result(exp: int, renderer: str, tables: list[PsnrTable]) -> SynthesisResult:
    return SynthesisResult(experiment=exp, renderer=renderer, tables=tuple(tables),
                           setup=SynthesisSetup(near_m=0.4, far_m=0.8, psnr_border_px=8,
                                                depth_method="sgm", depth_quality={},
                                                view_stride=1 if exp == 3 else None))


def test_synthesis_figures_are_derived_from_the_tables():
    """The means per renderer, depth and camera set and the dB lost (what version 1
    repeated in ``summary``), computed from the PSNR tables, against a hand-computed
    case: Exp. 2's sets count together, Exp. 3's two input choices apart."""
    def t(renderer, depth, cameras, run, psnr):
        return PsnrTable(renderer, depth, cameras, run, (), psnr)

    two = _result(2, "dibr", [
        t("dibr", "estimated", "complete", "x00_y00", {"x00_y00/0_0": 30.0, "x00_y00/2_2": 32.0}),
        t("dibr", "estimated", "complete", "x01_y00", {"x01_y00/0_0": 34.0}),
        t("dibr", "estimated", "ground_truth", "x00_y00",
          {"x00_y00/0_0": 31.0, "x00_y00/2_2": 33.0}),
        t("dibr", "estimated", "ground_truth", "x01_y00", {"x01_y00/0_0": 35.5})])
    assert two.renderers == ("dibr",)
    assert two.psnr_stats("dibr", "estimated", "complete") == {
        "": PsnrStats(mean_db=32.0, min_db=30.0, max_db=34.0, count=3)}
    (gt,) = two.psnr_stats("dibr", "estimated", "ground_truth").values()
    assert (gt.mean_db, gt.count) == (pytest.approx((31.0 + 33.0 + 35.5) / 3), 3)
    lost = two.mean_db_lost("dibr", ("estimated", "complete"), ("estimated", "ground_truth"))
    assert lost == {"": pytest.approx(99.5 / 3 - 32.0)}  # 1.1667 dB
    assert two.mean_db_lost("dibr", ("estimated", "complete"), ("true", "complete")) == {}
    assert two.psnr_stats("rvs", "estimated", "complete") == {}

    three = _result(3, "rvs", [
        t("dibr", "estimated", "complete", "central", {"x01_y00/0_0": 28.0}),
        t("rvs", "estimated", "complete", "central", {"x01_y00/0_0": 29.0, "x01_y00/0_1": 31.0}),
        t("rvs", "estimated", "complete", "lateral", {"x01_y00/0_0": 27.0}),
        t("rvs", "true", "complete", "central", {"x01_y00/0_0": 30.0, "x01_y00/0_1": 33.0})])
    assert three.renderers == ("rvs", "dibr")  # the primary one first
    stats = three.psnr_stats("rvs", "estimated", "complete")
    assert list(stats) == ["central", "lateral"]
    assert (stats["central"].mean_db, stats["central"].min_db, stats["central"].max_db) == (
        30.0, 29.0, 31.0)
    assert stats["lateral"] == PsnrStats(27.0, 27.0, 27.0, 1)
    # to depth: the true depth's mean minus the estimated depth's, where both were run
    assert three.mean_db_lost("rvs", ("estimated", "complete"), ("true", "complete")) == {
        "central": 1.5}
    assert three.psnr_stats("dibr", "estimated", "complete") == {
        "central": PsnrStats(28.0, 28.0, 28.0, 1)}


def test_psnr_tables_name_the_runs_of_experiments_2_and_3():
    two = {("rvs", "estimated", "complete"): {"sets": {
        "x01_y00": {"inputs": ["x01_y00/0_1"], "errors": _errors({"x01_y00/0_0": 36.0})},
        "x00_y00": {"inputs": ["x00_y00/0_1"], "errors": _errors({"x00_y00/0_0": 35.0})}}}}
    assert [(t.renderer, t.run) for t in psnr_tables(2, two, ["rvs"], 0)] == [
        ("rvs", "x00_y00"), ("rvs", "x01_y00")]
    part = {"inputs": ["x00_y00/1_1"], "errors": _errors({"x01_y00/0_0": 29.0})}
    three = {(r, "estimated", "complete"): {"central": part, "lateral": part, "view_stride": 1}
             for r in ("rvs", "dibr")}
    tables = psnr_tables(3, three, ["rvs", "dibr"], 0)
    assert [(t.renderer, t.run) for t in tables] == [
        ("rvs", "central"), ("rvs", "lateral"), ("dibr", "central"), ("dibr", "lateral")]
    assert _rounded(tables)[0].psnr_db == {"x01_y00/0_0": 29.0}


def test_convert_quality_round_trip_and_versions(tmp_path):
    per = {"x00_y00": {"1_1": {"psnr_db": 35.5, "ssim": 0.98},
                       "0_0": {"psnr_db": 33.25, "ssim": 0.97}},
           "hand00": {"1_1": {"psnr_db": 34.0, "ssim": 0.96}}}
    quality = ConvertQuality.from_dict(summarise(per, "1_1") | {"border_px": 6})
    assert quality.views == 3 and quality.worst_view == "x00_y00/0_0"
    path = tmp_path / "quality.json"
    write_convert_quality(path, quality)
    assert read_json(path)["views"] == 3
    back = read_convert_quality(path)
    # (write_json keeps 12 significant digits: the means come back to that)
    assert back.per_view == quality.per_view and back.worst_view == quality.worst_view
    assert back.mean_ssim == pytest.approx(quality.mean_ssim, rel=1e-11)
    write_convert_quality(tmp_path / "again.json", back)
    assert (tmp_path / "again.json").read_bytes() == path.read_bytes()
    _refuses_other_versions(path, read_convert_quality, r"converter quality \(quality.json\)",
                            "run rule convert_quality")
