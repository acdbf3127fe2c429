"""Config validation: wrong types, unknown keys and impossible values stop the run
with a message that names the key and the reason; defaults are filled in."""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import pytest
import yaml

from plenocal.config import ConfigError, validate_config

ROOT = Path(__file__).resolve().parents[1]
BASE = yaml.safe_load((ROOT / "config.yaml").read_text())


def _cfg():
    return copy.deepcopy(BASE)


def test_default_config_valid_and_defaults_filled():
    c = validate_config(_cfg())
    sim = c["datasets"]["synthetic"]["simulate"]
    assert sim["render"]["samples"] >= 1
    assert c["convert"]["view_spacing_px"] is None
    assert c["sfm"]["seed"] == 0


def test_tiny_config_valid():
    validate_config(yaml.safe_load((ROOT / "tests" / "tiny" / "config.yaml").read_text()))


@pytest.mark.parametrize("path, value, key, why", [
    (("datasets", "synthetic", "views"), 4, "datasets.synthetic.views", "odd"),
    (("datasets", "synthetic", "views"), "five", "datasets.synthetic.views", "integer"),
    (("datasets", "synthetic", "views"), 1, "datasets.synthetic.views", "no baseline"),
    (("datasets", "synthetic", "mla"), "plenoptic", "datasets.synthetic.mla", "keplerian"),
    # just outside the focal length: virtual depths in the thousands
    (("datasets", "synthetic", "simulate", "main_lens", "focus_distance_m"), 0.036,
     "datasets.synthetic.simulate.main_lens.focus_distance_m", "virtual depths"),
    (("datasets", "synthetic", "simulate", "array", "step_m"), -0.01,
     "datasets.synthetic.simulate.array.step_m", "> 0"),
    (("datasets", "synthetic", "simulate", "main_lens", "focus_distance_m"), 0.03,
     "datasets.synthetic.simulate.main_lens.focus_distance_m", "focal length"),
    (("datasets", "synthetic", "simulate", "scene", "near_m"), 0.9,
     "datasets.synthetic.simulate.scene.near_m", "far_m"),
    (("datasets", "synthetic", "simulate", "scene", "near_m"), 0.36,
     "datasets.synthetic.simulate.scene.near_m", "virtual depth"),
    # simulated for nothing before: registration A refused the capture after the simulation
    (("datasets", "synthetic", "simulate", "handheld", "count"), 0,
     "datasets.synthetic.simulate.handheld.count", "needs hand-held shots"),
    (("sfm", "mapper"), "magic", "sfm.mapper", "one of"),
    (("convert", "tile_size"), 1.5, "convert.tile_size",
     "must be a whole number from 2 to 128, or auto"),
    # JSON schema's own words named its rules, not what to write ("0 is not valid under any
    # of the given schemas", "must be of type ['integer', 'string']")
    (("convert", "tile_size"), 6.0, "convert.tile_size", "write 6, not 6.0"),
    (("convert", "tile_size"), "big", "convert.tile_size",
     "must be a whole number from 2 to 128, or auto"),
    (("refine", "loss_scale_px"), 0, "refine.loss_scale_px", "must be a number > 0, or auto"),
    (("convert", "view_spacing_px"), "wide", "convert.view_spacing_px",
     "must be a number > 0, or null"),
    (("scale", "low_percentile"), 95, "scale.low_percentile", "high_percentile"),
])
def test_bad_values_name_key_and_reason(path, value, key, why):
    c = _cfg()
    node = c
    for p in path[:-1]:
        node = node.setdefault(p, {})  # a block config.yaml leaves to its defaults
    node[path[-1]] = value
    with pytest.raises(ConfigError) as exc:
        validate_config(c)
    msg = str(exc.value)
    assert key in msg and why in msg, msg


def test_an_upper_bound_does_not_give_the_lower_ones_reason():
    """``views: 21`` said "must be <= 15: one view per shot has no baseline ...", the
    reason for the minimum."""
    c = _cfg()
    c["datasets"]["synthetic"]["views"] = 21
    with pytest.raises(ConfigError) as exc:
        validate_config(c)
    assert str(exc.value).endswith("datasets.synthetic.views = 21: must be <= 15")


@pytest.mark.parametrize("path, value", [
    # issue 34: the probes that ran (NaN: every comparison is false, so no range refused it)
    (("datasets", "synthetic", "simulate", "array", "step_m"), math.nan),
    (("datasets", "synthetic", "simulate", "array", "step_m"), math.inf),
    (("datasets", "synthetic", "simulate", "handheld", "max_offset_m"), math.inf),
    (("datasets", "synthetic", "simulate", "sensor", "noise_std"), math.inf),
    (("datasets", "synthetic", "simulate", "sensor", "pixel_size_um"), math.inf),
    (("convert", "upsample"), math.inf),
    (("convert", "view_spacing_px"), math.inf),
    (("sfm", "reprojection", "max_error_px"), math.inf),
    (("sfm", "reprojection", "max_error_px"), -math.inf),
])
def test_non_finite_numbers_are_refused(path, value):
    """Each probe of issue 34 (every number: tests/test_faults.py)."""
    c = _cfg()
    node = c
    for p in path[:-1]:
        node = node.setdefault(p, {})
    node[path[-1]] = value
    with pytest.raises(ConfigError, match="finite") as exc:
        validate_config(c)
    assert ".".join(path) in str(exc.value)


def test_whole_numbers_and_dataset_names():
    """Issue 34: views: 3.0 passed the schema (JSON schema counts 3.0 as an integer) and
    failed in names.py with a TypeError; a dataset key 5 failed in common.smk with a
    TypeError; a dataset name "abc\\n" passed (the pattern's $ matches before a newline)."""
    c = _cfg()
    c["datasets"]["synthetic"]["views"] = 3.0
    with pytest.raises(ConfigError, match=r"datasets\.synthetic\.views.*write 3, not 3\.0"):
        validate_config(c)
    c = _cfg()
    c["datasets"][5] = {"views": 3}
    with pytest.raises(ConfigError, match=r"datasets\.5: .*quote it"):
        validate_config(c)
    for name in ("abc\n", "a b", "-x", "caf\u00e9"):
        c = _cfg()
        c["datasets"][name] = {"views": 3}
        with pytest.raises(ConfigError, match="dataset name") as exc:
            validate_config(c)
        assert repr(name) in str(exc.value)
    c = _cfg()
    c["convert"][True] = 1
    with pytest.raises(ConfigError, match="convert.True: YAML reads the key True as a boolean"):
        validate_config(c)


def test_unknown_key_is_named():
    c = _cfg()
    c["convert"]["tile"] = 6
    with pytest.raises(ConfigError, match=r"convert.*unknown key\(s\) tile"):
        validate_config(c)


def test_unknown_top_level_key():
    c = _cfg()
    c["colmap"] = {}
    with pytest.raises(ConfigError, match="unknown key"):
        validate_config(c)


def test_canonical_sorts_mappings_and_keeps_lists():
    from plenocal.config import canonical, canonicalize

    cfg = {"b": {"z": 1, "a": [{"y": 2, "x": 3}, 4]}, "a": None}
    out = canonical(cfg)
    assert list(out) == ["a", "b"]
    assert list(out["b"]) == ["a", "z"]
    assert [list(d) for d in out["b"]["a"][:1]] == [["x", "y"]]
    assert out["b"]["a"][1] == 4
    assert repr(canonical({"y": 1, "x": 2})) == repr(canonical({"x": 2, "y": 1}))
    same = canonicalize(cfg)
    assert same is cfg and list(cfg) == ["a", "b"]


def test_a_dataset_may_read_its_mla_kind_from_the_image_whatever_convert_mla_says():
    """datasets.<d>.mla: auto undoes a global convert.mla for one dataset (a real capture
    beside simulated ones); another word is refused, naming the key."""
    c = _cfg()
    c["convert"]["mla"] = "keplerian"
    c["datasets"]["synthetic"]["mla"] = "auto"
    assert validate_config(c)["datasets"]["synthetic"]["mla"] == "auto"
    c["datasets"]["synthetic"]["mla"] = "Auto"
    with pytest.raises(ConfigError, match=r"datasets\.synthetic\.mla"):
        validate_config(c)


@pytest.mark.parametrize("change, key, why", [
    ({"verify": {"renderer": "rvs"}}, "verify.renderer", "needs verify.rvs_binary"),
    ({"verify": {"renderer": "rvs", "rvs_binary": "/nonexistent/RVS"}}, "verify.rvs_binary",
     "no such file"),
    ({"depth": {"min_depths": 100, "max_depths": 50}}, "depth.min_depths",
     r"must be at most depth\.max_depths \(50\)"),
    ({"depth": {"sgm": {"min_depths": 300}}}, "depth.sgm.min_depths",
     r"must be at most depth\.sgm\.max_depths \(256\)"),
    ({"convert": {"blend": {"wider_slots": 2}}}, "convert.blend.wider_slots",
     r"at least convert\.blend\.wide_slots \(4\)"),
    # reversed, D_min and D_max of every disparity.json swapped places without a word
    ({"convert": {"disparity_percentiles": [98, 2]}}, "convert.disparity_percentiles",
     r"the low percentile first, below the high one"),
    ({"convert": {"disparity_percentiles": [50, 50]}}, "convert.disparity_percentiles",
     r"the low percentile first"),
])
def test_settings_that_contradict_each_other_are_refused_before_any_job(change, key, why):
    """A renderer that cannot run (found only in a synthesis job, after the calibration)
    and bounds given the wrong way round are refused at start-up, naming the key."""
    c = _cfg()
    for block, values in change.items():
        for k, v in values.items():
            if isinstance(v, dict):
                c.setdefault(block, {}).setdefault(k, {}).update(v)
            else:
                c.setdefault(block, {})[k] = v
    with pytest.raises(ConfigError, match=rf"{re.escape(key)} = .*{why}"):
        validate_config(c)


@pytest.mark.parametrize("refine, key, why", [
    ({"rig": "hold", "scale": "merge"}, "refine.scale = 'merge'",
     "has no effect with refine.rig = hold"),
    ({"tracks": "central", "matches": "across"}, "refine.matches = 'across'",
     "has no effect with refine.tracks = central"),
    ({"tracks": "views", "carry_every": 1}, "refine.carry_every = 1",
     "has no effect with refine.tracks = views"),
    ({"focal": "hold", "final_iterations": 6}, "refine.final_iterations = 6",
     "has no effect with refine.focal = hold"),
    ({"tracks": "views", "central_contrast": 0.01}, "refine.central_contrast = 0.01",
     "has no effect with refine.tracks = views"),
])
def test_a_refine_key_the_others_leave_unused_is_refused(refine, key, why):
    """A refine key set where the other keys make the run ignore it stops the run naming
    both (before, the run went on without a word)."""
    c = _cfg()
    c["refine"] = refine
    with pytest.raises(ConfigError) as exc:
        validate_config(c)
    assert f"config: {key}: {why}" in str(exc.value), exc.value


@pytest.mark.parametrize("refine", [
    {"rig": "hold", "scale": "merge", "frames": "hold"},  # held frames keep Eq. 5's scale
    {"tracks": "views"}, {"tracks": "central", "carry_every": 1},
    {"enabled": False, "tracks": "views", "carry_every": 1},  # the paper's method alone
])
def test_refine_keys_in_use_pass(refine):
    c = _cfg()
    c["refine"] = refine
    validate_config(c)


def test_view_radius_without_the_grid_is_refused():
    """sfm.view_matching.view_radius sets which views of a shot the grid matches: under
    within_shot centre (the default) it was accepted and ignored (a README review's
    finding)."""
    c = _cfg()
    c.setdefault("sfm", {})["view_matching"] = {"view_radius": 2}
    with pytest.raises(ConfigError, match=r"sfm.view_matching.view_radius = 2: has no effect "
                       r"with sfm.view_matching.within_shot = centre"):
        validate_config(c)
    c["sfm"]["view_matching"] = {"view_radius": 2, "within_shot": "grid"}
    validate_config(c)
