"""Issue 34, kept from coming back: every config number set to NaN and to infinity, one at
a time, is refused before any job with its key named; every camera.yaml key misspelt, one
at a time, is refused with the key it was meant to be. (The third sweep, every file of the
tiny run deleted and made again, is tests/test_workflow_faults.py.)"""

from __future__ import annotations

import copy
import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from conftest import ROOT, tiny_workflow

from plenocal.calib.reg_b import datasheet
from plenocal.calib.reg_b.datasheet import DatasheetError, check_datasheet
from plenocal.config import ConfigError, load_schema, validate_config

SCHEMA = load_schema(ROOT / "config.schema.yaml")
# the default config with every default filled in: each list of numbers is there to change
DEFAULT = validate_config(yaml.safe_load((ROOT / "config.yaml").read_text()))
DATASET = "synthetic"  # the default config's dataset: every datasets.<name> key under it


def _resolve(node: dict) -> dict:
    while "$ref" in node:
        node = SCHEMA["$defs"][node["$ref"].rsplit("/", 1)[-1]]
    return node


def _is_number(node: dict) -> bool:
    types = node.get("type", [])
    types = [types] if isinstance(types, str) else types
    return bool({"number", "integer"} & set(types))


def numeric_keys(node: dict = SCHEMA, path: tuple = ()) -> Iterator[tuple]:
    """Every key of the config schema that holds a number (a list of numbers: its first
    item, index 0), whether or not the default config gives it."""
    node = _resolve(node)
    if _is_number(node):
        yield path
    items = node.get("items")
    if isinstance(items, dict) and _is_number(_resolve(items)):
        yield (*path, 0)
    for i, item in enumerate(node.get("prefixItems", [])):
        if _is_number(_resolve(item)):
            yield (*path, i)
    for key, sub in node.get("properties", {}).items():
        yield from numeric_keys(sub, (*path, key))
    if path == ("datasets",):
        yield from numeric_keys(node["additionalProperties"], (*path, DATASET))


NUMERIC_KEYS = sorted(set(numeric_keys()), key=str)


def _dotted(path: tuple) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def _set(cfg: dict, path: tuple, value: float) -> None:
    """``value`` at ``path`` of ``cfg``, the blocks on the way created (a list: its first
    item replaced, the others kept)."""
    node = cfg
    for part in path[:-2]:
        node = node.setdefault(part, {})
    parent, last = path[-2], path[-1]
    if isinstance(last, int):
        seq = list(node.get(parent) or [1.0] * (last + 1))
        seq[last] = value
        node[parent] = seq
    else:
        node.setdefault(parent, {})[last] = value


def test_the_sweep_covers_the_keys_of_the_issue():
    """The schema walk finds the numbers the issue probed, and many more."""
    dotted = {_dotted(p) for p in NUMERIC_KEYS}
    for key in ("datasets.synthetic.simulate.array.step_m",
                "datasets.synthetic.simulate.handheld.max_offset_m",
                "datasets.synthetic.simulate.sensor.noise_std",
                "datasets.synthetic.simulate.sensor.pixel_size_um",
                "datasets.synthetic.simulate.mla.focal_ratios[0]", "convert.upsample",
                "convert.view_spacing_px", "sfm.reprojection.max_error_px",
                "datasets.synthetic.views"):
        assert key in dotted, key
    assert len(NUMERIC_KEYS) > 80


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_every_config_number_must_be_finite(value: float):
    """Each number of the schema, one at a time, set to NaN / +-inf: refused, naming it."""
    passed = []
    for path in NUMERIC_KEYS:
        cfg = copy.deepcopy(DEFAULT)
        _set(cfg, path, value)
        try:
            validate_config(cfg)
        except ConfigError as err:
            msg = str(err)
            assert f"config: {_dotted(path)} = {value!r}: must be a finite number" in msg, msg
        else:
            passed.append(_dotted(path))
    assert not passed, f"accepted {value}: {passed}"


@pytest.mark.workflow
@pytest.mark.parametrize("key, text", [
    ("datasets.tiny.simulate.array.step_m", ".nan"),
    ("sfm.reprojection.max_error_px", ".inf"),
])
def test_non_finite_config_stops_before_any_job(tmp_path: Path, key: str, text: str):
    """Through Snakemake (a dry run is enough: the check is made while parsing)."""
    work = tiny_workflow(tmp_path)
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    node = cfg
    *parents, last = key.split(".")
    for part in parents:
        node = node.setdefault(part, {})
    node[last] = "__VALUE__"
    (work / "config.yaml").write_text(yaml.safe_dump(cfg).replace("__VALUE__", text))
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-j1", "--workflow-profile",
                           "none"], cwd=work, capture_output=True, text=True, timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0, out[-2000:]
    assert f"config: {key} = " in out and "must be a finite number" in out, out[-2000:]
    assert not (work / "results").exists() and not (work / "data").exists()


# --- camera.yaml ------------------------------------------------------------------------

#: what the simulator writes for the tiny config (tests/test_datasheet.py GOOD)
GOOD = {
    "pixel_size_mm": 0.0055, "sensor_width_px": 1280, "sensor_height_px": 960,
    "main_lens": {"focal_length_mm": 35.0, "focus_distance_mm": 600.0},
    "mla": {"pitch_mm": 0.13, "f_numbers": [2.8], "k": 5.0, "sensor_distance_mm": 0.455},
    "array": {"step_mm": 10.0}, "scene": {"near_mm": 470.0, "far_mm": 740.0},
}


def camera_keys(node: dict = datasheet.SCHEMA, path: tuple = ()) -> Iterator[tuple]:
    """Every key path of camera.yaml's schema (mappings and their keys)."""
    for key, sub in node.get("properties", {}).items():
        yield (*path, key)
        yield from camera_keys(sub, (*path, key))


CAMERA_KEYS = list(camera_keys())


def typos(key: str) -> dict[str, str]:
    """Ways to misspell ``key``: a letter doubled, dropped, swapped, upper case, a unit
    written out ("_mm" -> "_m", "_um"), the key run together."""
    out = {"doubled": key + key[-1], "upper": key.upper(), "plural": key + "s"}
    if len(key) > 2:
        out["dropped"] = key[:-1]
        out["swapped"] = key[1] + key[0] + key[2:]
    if key.endswith("_mm"):
        out["metres"] = key[:-3] + "_m"
        out["micrometres"] = key[:-3] + "_um"
        out["no unit"] = key[:-3]
    if "_" in key:
        out["run together"] = key.replace("_", "")
    return {k: v for k, v in out.items() if v != key}


def _renamed(doc: dict, path: tuple, new: str) -> dict:
    doc = copy.deepcopy(doc)
    node = doc
    for part in path[:-1]:
        node = node[part]
    node[new] = node.pop(path[-1])
    return doc


def test_the_camera_keys_are_all_swept():
    assert len(CAMERA_KEYS) == 16
    assert {p[0] for p in CAMERA_KEYS if len(p) == 1} == set(datasheet.SCHEMA["properties"])


@pytest.mark.parametrize("path", CAMERA_KEYS, ids=lambda p: ".".join(p))
def test_every_misspelt_camera_key_is_refused(path: tuple):
    """Each key of camera.yaml's schema (GOOD gives every one), misspelt each way, one at a
    time: refused, naming the misspelt key; the key it was meant to be is suggested (a
    unit in the name aside, where the message converts the value instead)."""
    check_datasheet(GOOD)
    for how, typo in typos(path[-1]).items():
        doc = _renamed(GOOD, path, typo)
        where = ".".join((*path[:-1], typo))
        with pytest.raises(DatasheetError) as exc:
            check_datasheet(doc, "camera.yaml")
        msg = str(exc.value)
        assert msg.startswith(f"camera.yaml: {where}: unknown key - did you mean "
                              f"{'.'.join(path)}?"), (how, msg)
