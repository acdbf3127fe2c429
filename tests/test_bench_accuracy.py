"""bench/bench_accuracy.py's config changes (--set): dotted keys with YAML values over
config.yaml, the clones' label, and the errors for what it cannot take."""

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import bench_accuracy as ba  # noqa: E402


def test_set_items_nest_their_dotted_keys_with_yaml_values():
    got = ba.parse_changes(["refine.tracks=both", "refine.align.radius_px=4",
                            "refine.enabled=true"])
    assert got == {"refine": {"tracks": "both", "align": {"radius_px": 4}, "enabled": True}}
    assert ba.variant_label(["refine.tracks=both", "sfm.sift=colmap"]) == (
        "tracks-both_sift-colmap")


def test_a_capture_config_takes_the_changes_over_the_geometry_and_seed():
    cfg = ba.capture_config("small", 34, ba.parse_changes(["refine.tracks=both"]))
    assert cfg["refine"]["tracks"] == "both"
    sim = cfg["datasets"][ba.DATASET]["simulate"]
    assert sim["seed"] == 34 and sim["array"]["cols"] == 3
    # without changes, config.yaml's own refine block (or none) is left as it is
    assert ba.capture_config("small", 34).get("refine") == (
        ba.capture_config("small", 34, {}).get("refine"))


@pytest.mark.parametrize("item", ["refine.tracks", "=both", "refine..tracks=x",
                                  "datasets.synthetic.simulate.seed=3"])
def test_a_set_item_it_cannot_take_is_refused_by_name(item):
    with pytest.raises(ValueError, match="--set"):
        ba.parse_changes([item])


def test_a_clone_links_the_images_and_copies_the_rest_with_their_times(tmp_path):
    src, dest = tmp_path / "cap", tmp_path / "cap-x"
    files = ["data/synthetic/a.png", f"results/{ba.DATASET}/views/s/0_0.png",
             f"results/{ba.DATASET}/calibration/cameras.json"]
    for i, f in enumerate(files):
        (src / f).parent.mkdir(parents=True, exist_ok=True)
        (src / f).write_text(f"{i}")
        os.utime(src / f, ns=(10**18 + i, 10**18 + i))
    (src / ".snakemake" / "locks").mkdir(parents=True)
    ba.clone_capture(src, dest)
    for f in files:
        assert (dest / f).read_text() == (src / f).read_text()
        assert (dest / f).stat().st_mtime_ns == (src / f).stat().st_mtime_ns
    assert (dest / files[0]).stat().st_ino == (src / files[0]).stat().st_ino
    assert (dest / files[1]).stat().st_ino == (src / files[1]).stat().st_ino
    assert (dest / files[2]).stat().st_ino != (src / files[2]).stat().st_ino
    assert not (dest / ".snakemake" / "locks").exists()


def test_a_clone_that_fails_part_way_leaves_nothing(tmp_path, monkeypatch):
    src, dest = tmp_path / "cap", tmp_path / "cap-x"
    for i, f in enumerate(["results/a.json", "results/b.json", "results/c.json"]):
        (src / f).parent.mkdir(parents=True, exist_ok=True)
        (src / f).write_text(f"{i}")
    copy2, calls = ba.shutil.copy2, []

    def full_disk(a, b):
        calls.append(a)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return copy2(a, b)

    monkeypatch.setattr(ba.shutil, "copy2", full_disk)
    with pytest.raises(OSError):  # copytree copies the rest, then raises shutil.Error
        ba.clone_capture(src, dest)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap"]  # no clone, whole or half
    monkeypatch.setattr(ba.shutil, "copy2", copy2)
    ba.clone_capture(src, dest)  # the next run clones it whole
    assert (dest / "results" / "c.json").read_text() == "2"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap", "cap-x"]


def test_paired_rows_put_each_capture_beside_its_clone_with_the_worst_in_size():
    def cap(f, c, job=None):
        return {"focal_signed_pct": f, "focal_pct": abs(f), "centre_mm": c, "rot_deg": 0.01,
                "residual_scale_pct": 0.01, "scale_pct": 0.05, "refine_job": job}

    base = {"a-s1": cap(-0.15, 0.02, (50.0, 800.0)), "a-s2": cap(0.02, 0.03)}
    other = {"a-s1": cap(-0.05, 0.01, (90.0, 1600.0)), "a-s2": cap(0.12, 0.03)}
    lines = ba.paired_rows(base, other, "both")
    row = next(line for line in lines if line.startswith("| a-s1 "))
    assert "-0.150 -> -0.050" in row and "| 50 -> 90 | 800 -> 1600 |" in row
    assert "| - -> - | - -> - |" in next(line for line in lines if line.startswith("| a-s2 "))
    worst = next(line for line in lines if line.startswith("| **worst**"))
    assert "| 0.150 -> 0.120 |" in worst
    median = next(line for line in lines if line.startswith("| **median**"))
    assert "| 0.085 -> 0.085 |" in median
    assert lines[-1] == ("Captures past a target (2 pairs), as kept -> both: focal 1 -> 1; "
                         "centres 0 -> 0; rotation 0 -> 0; scale 0 -> 0.")


def test_the_scale_target_judges_the_written_calibration_not_the_merge():
    # the merge's r (the paper's Eq. 6 result) past 0.3 %, the written calibration's
    # scale within it: the capture is not past the scale target
    cap = {"focal_pct": 0.02, "focal_signed_pct": -0.02, "centre_mm": 0.01, "rot_deg": 0.004,
           "scale_pct": 0.34, "residual_scale_pct": 0.028}
    far = {**cap, "residual_scale_pct": 0.31}
    rows = ba.geometry_rows({"small-s1": cap, "small-s2": far})
    row = next(line for line in rows if line.startswith("| small "))
    assert row.endswith("| 0 / 0 / 0 / 1 |")
    assert "0.169 / 0.310" in row  # the written scale's median / worst, not the merge's


@pytest.mark.parametrize("geometry", sorted(ba.GEOMETRIES))
def test_every_geometry_gives_a_config_the_schema_takes(geometry):
    """A geometry's simulate block is a config the workflow accepts (a key misspelt or out of
    range is refused here, not after a capture's first minutes)."""
    from plenocal.config import validate_config  # noqa: PLC0415

    cfg = validate_config(ba.capture_config(geometry, 38))
    sim = cfg["datasets"][ba.DATASET]["simulate"]
    assert sim["seed"] == 38
    for key, value in ba.GEOMETRIES[geometry].get("array", {}).items():
        assert sim["array"][key] == value


def _shots(geometry: str) -> dict:
    """The simulated shots' poses of ``geometry`` at seed 49 (a scene centre given)."""
    import numpy as np  # noqa: PLC0415

    from plenocal.config import validate_config  # noqa: PLC0415
    from plenocal.simulate.dataset import make_shots  # noqa: PLC0415

    cfg = validate_config(ba.capture_config(geometry, 49))
    return make_shots(cfg["datasets"][ba.DATASET]["simulate"], np.array([0.01, 0.0, 0.5]))


@pytest.mark.parametrize(("geometry", "added"), [("small-6hand", 2), ("small-8hand", 4)])
def test_small_with_hand_held_shots_added(geometry, added):
    """``small-6hand`` and ``small-8hand`` pair with ``small`` (BENCHMARKS.md, "The small
    geometry with more hand-held shots"): the same seed gives the same array and first
    four hand-held poses, and two or four more (the same scene too; the array shots' noise
    is drawn anew)."""
    import numpy as np  # noqa: PLC0415

    small, more = _shots("small"), _shots(geometry)
    assert len(more) == len(small) + added
    for name, pose in small.items():
        np.testing.assert_array_equal(more[name], pose)


def test_small_turned_is_small_with_each_turn_doubled():
    """``small-turned`` pairs with ``small``: each hand-held shot turned about the same
    axis by twice the angle, from the same offset; the array shots the same."""
    import cv2  # noqa: PLC0415
    import numpy as np  # noqa: PLC0415

    small, turned = _shots("small"), _shots("small-turned")
    assert small.keys() == turned.keys()
    for name, pose in small.items():
        if not name.startswith("hand"):
            np.testing.assert_array_equal(turned[name], pose)
            continue
        # the rotation vectors (axis times angle): the same axis, twice the angle
        np.testing.assert_allclose(cv2.Rodrigues(turned[name][:3, :3])[0],
                                   2 * cv2.Rodrigues(pose[:3, :3])[0], rtol=1e-9, atol=1e-12)


def test_collecting_nothing_says_so_by_name_instead_of_a_traceback(tmp_path, monkeypatch,
                                                                    capsys):
    """--collect-only on seeds never run: a message naming the seeds and the folder, not
    max() of an empty sequence."""
    monkeypatch.setattr(ba, "OUT", tmp_path)
    monkeypatch.setattr(sys, "argv", ["bench_accuracy.py", "--collect-only", "--no-exp1",
                                      "--seeds", "12345", "--geometries", "default"])
    with pytest.raises(SystemExit, match=r"no capture measured: none of seeds 12345 of "
                                         r"default .*--collect-only"):
        ba.main()
    assert "default-s12345: not measured yet" in capsys.readouterr().err


def test_the_refined_focal_lengths_deviation_is_judged_against_its_error():
    """Hand-computed: errors +0.10 and -0.03 % over deviations 0.05 and 0.10 % are +2.0 and
    -0.3 deviations (RMS sqrt((4 + 0.09) / 2) = 1.43); a rejected refinement, one without a
    deviation and one turned off take no part."""
    def capture(err, sd, **refine):
        std = {} if sd is None else {"std": {"std_pct": sd}}
        return {"focal_signed_pct": err,
                "refine": {"enabled": True, "rejected": False, "gain": {},
                           "focal_px": {"refined": 1000.0, **std}, **refine}}

    results = {"a-s1": capture(0.10, 0.05), "b-s1": capture(-0.03, 0.10),
               "c-s1": capture(0.2, 0.01, rejected=True), "d-s1": capture(0.2, None),
               "e-s1": {"focal_signed_pct": 0.3, "refine": {"enabled": False}}}
    assert ba.sd_summary(results) == (
        "The refined focal length's error over its own standard deviation (`refine.json` "
        "`focal_px.std`): RMS 1.43, at most 2.00, 2 of 2 within 2.")
    rows = ba.refine_rows(results)
    assert rows[2].endswith("| 0.050 | +2.00 |") and rows[3].endswith("| 0.100 | -0.30 |")
    assert rows[4].endswith("| - | - |") and rows[5].endswith("| - | - |")
    assert rows[6].endswith("| Eq. 6 (refine off) | - | - |")
    assert ba.sd_summary({"d-s1": capture(0.2, None)}) is None


def test_table_i_ratios_say_where_the_naive_sfm_left_views_out():
    rows = ba.ratio_rows({
        "a": {"table_truth": 1.0, "table_complete": 1.01, "table_naive": 1.2,
              "naive_views": 700, "complete_views": 700},
        "b": {"table_truth": 1.0, "table_complete": 1.01, "table_naive": 1.1,
              "naive_views": 688, "complete_views": 700},
    })
    assert rows[2].endswith("| 0.8417 |")
    assert rows[3].endswith("| 0.9182 (naive: 688 of 700 views) |")


def test_a_missing_or_unmeasured_capture_is_named_with_the_remedy(tmp_path):
    # the benches that read kept captures stopped on the first file they opened, with a
    # camera file's remedy ("rerun the rule that wrote it") or a bare FileNotFoundError
    with pytest.raises(SystemExit, match="nosuch: not a kept capture of bench_accuracy.py "
                                         r"\(no such folder\): run bench/bench_accuracy.py"):
        ba.require_kept_capture(tmp_path / "nosuch")
    cap = tmp_path / "small-s1"
    (cap / "results" / ba.DATASET / "eval").mkdir(parents=True)
    with pytest.raises(SystemExit, match=r"\(no config.yaml\)"):
        ba.require_kept_capture(cap)
    (cap / "config.yaml").write_text("{}\n")
    with pytest.raises(SystemExit, match="no results/synthetic/eval/gt_errors.json yet: run "
                                         "bench/bench_accuracy.py for it$"):
        ba.require_kept_capture(cap)
    with pytest.raises(SystemExit, match="synthesis_exp1.json yet: .*without --no-exp1"):
        ba.require_kept_capture(cap, ("eval/synthesis_exp1.json",))
    (cap / "results" / ba.DATASET / "eval" / "gt_errors.json").write_text("{}\n")
    assert ba.require_kept_capture(cap) == cap
