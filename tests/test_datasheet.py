"""camera.yaml validation (plenocal.calib.reg_b.datasheet): every bad value is refused with
the file, the dotted key and the remedy; the simulator's own datasheet passes; read_datasheet
uses the same checks (no bad value reaches rig.json as null)."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import pytest
import yaml

from plenocal.calib.reg_b.datasheet import (
    DatasheetError,
    check_datasheet,
    check_micro_image_pitch,
    load_datasheet,
    read_datasheet,
)

# what the simulator writes for the tiny config (plenocal.simulate.dataset.datasheet)
GOOD = {
    "pixel_size_mm": 0.0055, "sensor_width_px": 1280, "sensor_height_px": 960,
    "main_lens": {"focal_length_mm": 35.0, "focus_distance_mm": 600.0},
    "mla": {"pitch_mm": 0.13, "f_numbers": [2.8], "k": 5.0, "sensor_distance_mm": 0.455},
    "array": {"step_mm": 10.0}, "scene": {"near_mm": 470.0, "far_mm": 740.0},
}


def _with(path: str, value):
    doc = copy.deepcopy(GOOD)
    node = doc
    parts = path.split(".")
    for p in parts[:-1]:
        node = node[p]
    node[parts[-1]] = value
    return doc


def test_simulator_datasheet_passes(tmp_path: Path):
    from plenocal.config import validate_config
    from plenocal.simulate.dataset import datasheet
    from plenocal.simulate.optics_setup import optics_from_config

    cfg = validate_config(yaml.safe_load(
        (Path(__file__).parent / "tiny" / "config.yaml").read_text()))
    sim = cfg["datasets"]["tiny"]["simulate"]
    doc = datasheet(sim, optics_from_config(sim))
    (tmp_path / "camera.yaml").write_text(yaml.safe_dump(doc))
    assert load_datasheet(tmp_path / "camera.yaml")["mla"]["k"] == doc["mla"]["k"]
    check_datasheet(GOOD)


@pytest.mark.parametrize("key, value, words", [
    ("pixel_size_mm", "5.5 um", ["pixel_size_mm", "plain number", "millimetres"]),
    ("pixel_size_mm", math.nan, ["pixel_size_mm", "finite"]),
    ("mla.k", 1.0, ["mla.k", "> 1"]),
    ("mla.k", 0.5, ["mla.k", "> 1"]),  # with GOOD's s > f: a Keplerian MLA's
    ("mla.k", 0.0, ["mla.k", "> 0"]),
    ("mla.f_numbers", [], ["mla.f_numbers", "empty"]),
    ("mla.f_numbers", [2.8, "f/4"], ["mla.f_numbers"]),
    ("mla", [0.13, 2.8, 5.0], ["mla", "mapping", "list"]),
    ("main_lens", None, ["main_lens", "mapping"]),
    # micrometres in a millimetre key: outside the plausible range, with the guess
    ("mla.pitch_mm", 130.0, ["mla.pitch_mm", "plausible", "micrometres", "0.13 mm"]),
    ("pixel_size_mm", 5.5, ["pixel_size_mm", "plausible", "micrometres"]),
    ("sensor_width_px", 1280.5, ["sensor_width_px", "integer"]),
    ("scene.near_mm", 800.0, ["scene.near_mm", "far_mm"]),
    ("main_lens.focus_distance_mm", 30.0, ["main_lens.focus_distance_mm", "focal length"]),
    # just outside the focal length: virtual depths in the thousands
    ("main_lens.focus_distance_mm", 36.0, ["main_lens.focus_distance_mm", "virtual depth"]),
    ("main_lens.focus_distance_mm", -600.0, ["main_lens.focus_distance_mm", "> 0"]),
])
def test_bad_value_names_file_key_and_remedy(tmp_path: Path, key, value, words):
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump(_with(key, value)))
    with pytest.raises(DatasheetError) as exc:
        load_datasheet(path)
    msg = str(exc.value)
    assert msg.startswith(str(path)), msg
    for w in words:
        assert w in msg, (w, msg)


def test_missing_key_and_not_a_mapping(tmp_path: Path):
    doc = copy.deepcopy(GOOD)
    del doc["mla"]["k"]
    with pytest.raises(DatasheetError, match=r"missing key 'mla\.k'"):
        check_datasheet(doc)
    path = tmp_path / "camera.yaml"
    path.write_text("- 0.0055\n- 1280\n")
    with pytest.raises(DatasheetError, match="must be a mapping"):
        load_datasheet(path)
    path.write_text("")
    with pytest.raises(DatasheetError, match="empty"):
        load_datasheet(path)


def test_yaml_nan_is_refused(tmp_path: Path):
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump(GOOD).replace("k: 5.0", "k: .nan"))
    with pytest.raises(DatasheetError, match=r"mla\.k = nan: must be a finite number"):
        load_datasheet(path)


def test_read_datasheet_uses_the_schema(tmp_path: Path):
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump(GOOD))
    ds = read_datasheet(path)
    assert ds.k == 5.0 and ds.f_numbers == (2.8,) and ds.sensor_distance == 0.455
    path.write_text(yaml.safe_dump(_with("array.step_mm", "10 mm")))
    with pytest.raises(DatasheetError, match=r"array\.step_mm"):
        read_datasheet(path)


@pytest.mark.parametrize("mutate, key, nearest", [
    # issue 34: each of these passed, the first one hiding the report's only warning (the
    # Eqs. 2-3 check, "skipped" without near_mm / far_mm)
    (lambda d: d.update(scene={"near": 470, "far": 740}), "scene.far", "scene.far_mm"),
    (lambda d: d.update(array={"step": 10}), "array.step", "array.step_mm"),
    (lambda d: d["mla"].update(sensor_distance=0.455), "mla.sensor_distance",
     "mla.sensor_distance_mm"),
    (lambda d: d.update(pixel_size_um=5.5), "pixel_size_um", "pixel_size_mm"),
    (lambda d: d.update(k=5.0), "k", "mla.k"),  # under the wrong mapping
    (lambda d: d["main_lens"].update(Focus_Distance_mm=600), "main_lens.Focus_Distance_mm",
     "main_lens.focus_distance_mm"),
])
def test_unknown_keys_refused_with_the_nearest_known_key(tmp_path: Path, mutate, key, nearest):
    doc = copy.deepcopy(GOOD)
    mutate(doc)
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(DatasheetError) as exc:
        load_datasheet(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: {key}: unknown key - did you mean {nearest}?"), msg


def test_unknown_key_in_micrometres_gets_the_value_in_millimetres():
    doc = copy.deepcopy(GOOD)
    del doc["pixel_size_mm"]
    doc["pixel_size_um"] = 5.5
    with pytest.raises(DatasheetError, match=r"5\.5 um is pixel_size_mm: 0\.0055"):
        check_datasheet(doc)


def test_duplicate_keys_refused(tmp_path: Path):
    """Issue 34: PyYAML keeps the last of two equal keys without a word."""
    path = tmp_path / "camera.yaml"
    text = yaml.safe_dump(GOOD)
    path.write_text(text.replace("  k: 5.0\n", "  k: 5.0\n  k: 4.0\n"))
    with pytest.raises(DatasheetError, match=r"mla\.k: given twice \(lines \d+ and \d+\)"):
        load_datasheet(path)
    path.write_text(text + "pixel_size_mm: 0.006\n")
    with pytest.raises(DatasheetError, match=r"camera\.yaml: pixel_size_mm: given twice"):
        load_datasheet(path)


def test_sensor_distance_that_contradicts_k_refused():
    """Issue 34: registration B takes mla.sensor_distance_mm where given and ignores k."""
    with pytest.raises(DatasheetError, match=r"mla\.sensor_distance_mm = 0\.5: contradicts "
                       r"mla\.k = 5.*0\.455 mm"):
        check_datasheet(_with("mla.sensor_distance_mm", 0.5))
    check_datasheet(_with("mla.sensor_distance_mm", 0.4551))  # rounding passes
    # a Galilean camera's s (below f = 0.364 mm): k f / (k + 1)
    check_datasheet(_with("mla.sensor_distance_mm", 5 * 0.364 / 6))
    with pytest.raises(DatasheetError, match="Galilean"):
        check_datasheet(_with("mla.sensor_distance_mm", 0.33))
    doc = copy.deepcopy(GOOD)
    del doc["mla"]["sensor_distance_mm"]
    check_datasheet(doc)


@pytest.mark.parametrize("text, want", [("5.5 um", "0.0055"), ("5.5µm", "0.0055"),
                                        ("0.0055 mm", "0.0055"), ("0.0055", "0.0055")])
def test_unit_in_a_string_gets_the_value_to_write(text: str, want: str):
    """Issue 34: the hint for '5.5 um' said "write e.g. 5.5", itself out of range."""
    with pytest.raises(DatasheetError) as exc:
        check_datasheet(_with("pixel_size_mm", text))
    assert f"write {want} for pixel_size_mm" in str(exc.value)
    check_datasheet(_with("pixel_size_mm", float(want)))


def test_micro_image_pitch_against_calib_xml():
    """calib.xml's diameter against camera.yaml's pitch and pixel size: the micro images lie
    D (L + s) / (L p) px apart, here 0.13 / 0.0055 x (L + 0.455) / L with L = F + e + t
    (the optics' own figure, 23.912 px: the default camera's calib.xml), 5 % either way
    taken; without the focal length D / p = 23.636 px to 10 % more."""
    doc = check_datasheet(copy.deepcopy(GOOD))
    for d in (23.912, 0.951 * 23.912, 1.049 * 23.912):
        check_micro_image_pitch(doc, d)
    with pytest.raises(DatasheetError) as err:
        check_micro_image_pitch(doc, 1.06 * 23.912, "data/c/camera.yaml", "data/c/calib.xml")
    msg = str(err.value)
    for part in ("data/c/camera.yaml: mla.pitch_mm = 0.13", "23.91 px apart",
                 "data/c/calib.xml gives a diameter of 25.35 px (+6.0 %", "units"):
        assert part in msg, msg
    # the pitch in the wrong unit that the plausible range lets through: 13 um as 0.013 mm
    slip = copy.deepcopy(doc)
    slip["mla"]["pitch_mm"] = 0.013
    with pytest.raises(DatasheetError, match=r"mla.pitch_mm = 0.013: .* 2.37 px apart"):
        check_micro_image_pitch(slip, 23.912)
    no_f = copy.deepcopy(doc)
    del no_f["main_lens"]["focal_length_mm"]
    lo, hi = 0.13 / 0.0055, 1.1 * 0.13 / 0.0055
    for d in (0.951 * lo, lo, hi, 1.049 * hi):
        check_micro_image_pitch(no_f, d)
    for d in (0.949 * lo, 1.051 * hi):
        with pytest.raises(DatasheetError, match="23.64 to 26.00 px apart"):
            check_micro_image_pitch(no_f, d)


def test_a_missing_datasheet_says_what_it_needs_and_where_a_template_comes_from(tmp_path):
    """No camera.yaml: the message lists the required keys (from the schema) and how to get
    the simulator's as a template."""
    with pytest.raises(FileNotFoundError) as exc:
        load_datasheet(tmp_path / "camera.yaml")
    text = str(exc.value)
    for words in ("camera datasheet not found", "pixel_size_mm", "mla: pitch_mm, f_numbers, k",
                  "--until simulate_setup", "data/synthetic/camera.yaml"):
        assert words in text, (words, text)


def test_a_galilean_mla_may_have_k_up_to_1():
    """s = k f / (k + 1) behind a Galilean MLA holds for any k > 0: k = 0.8 (the sharp
    virtual plane 0.8 f behind the MLA) is read, with its s or without; the paper model
    refuses it for a Keplerian MLA, naming the key."""
    from plenocal.calib.reg_b import paper_model
    from plenocal.calib.reg_b.datasheet import mla_kind

    f = 2.8 * 0.13
    doc = _with("mla.k", 0.8)
    doc["mla"]["sensor_distance_mm"] = 0.8 * f / 1.8
    assert mla_kind(doc) == "galilean"
    check_datasheet(doc)
    del doc["mla"]["sensor_distance_mm"]
    assert mla_kind(doc) == "galilean"
    check_datasheet(doc)
    assert mla_kind(GOOD) == "keplerian"
    assert paper_model.sensor_distance(0.8, f, "galilean") == pytest.approx(0.8 * f / 1.8)
    with pytest.raises(ValueError, match="mla.k = 0.8"):
        paper_model.sensor_distance(0.8, f, "keplerian")
