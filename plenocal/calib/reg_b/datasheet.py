"""The camera datasheet ``camera.yaml``: its JSON schema and a loader that names the file,
the key and the remedy for every bad value.

``camera.yaml`` gives what registration B (Section II-C of the paper, Eqs. 1-4) reads
from the datasheet: the pixel size p, the sensor size, the main lens's focus distance
X_o, the microlens pitch D, F-number(s) and the paper's k (or the MLA-sensor distance
s), the array step and the measured nearest / farthest object distances (the inverse
check of Eqs. 2-3). Every length is in millimetres (the unit is in the key name).

Besides types, the schema holds a plausible range per field, so that a value written in
the wrong unit (a pixel size of 5.5 "mm" meant as micrometres, a pitch of 130) stops
the run at the start instead of giving an absurd rig after conversion and SfM. The
checks a schema cannot express (NaN, near < far, a focus distance beyond the focal
length) follow in :func:`check_datasheet`. :func:`read_datasheet` gives the checked file as
the typed :class:`Datasheet` that registration B computes with.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from plenocal.io import yamlfile


class DatasheetError(ValueError):
    """A bad ``camera.yaml``; the message names the file, the key and the remedy."""


def _mm(lo: float, hi: float, what: str) -> dict:
    return {"type": "number", "exclusiveMinimum": 0, "x-range": [lo, hi], "description": what}


#: The schema of camera.yaml. ``x-range`` is the plausible range of a field in its unit
#: (a value outside it is almost surely in another unit); ``x-unit`` names that unit.
SCHEMA: dict = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "camera.yaml: datasheet of the plenoptic camera (lengths in millimetres)",
    "type": "object",
    "required": ["pixel_size_mm", "sensor_width_px", "sensor_height_px", "main_lens", "mla"],
    "additionalProperties": False,
    "properties": {
        "pixel_size_mm": _mm(0.0005, 0.05, "sensor pixel pitch p (0.5-50 um)"),
        "sensor_width_px": {"type": "integer", "minimum": 64, "maximum": 65536},
        "sensor_height_px": {"type": "integer", "minimum": 64, "maximum": 65536},
        "main_lens": {
            "type": "object",
            "required": ["focus_distance_mm"],
            "additionalProperties": False,
            "properties": {
                "focus_distance_mm": _mm(5.0, 1.0e6, "X_o, where the main lens is focused"),
                "focal_length_mm": _mm(1.0, 2000.0, "nominal focal length (information)"),
            },
        },
        "mla": {
            "type": "object",
            "required": ["pitch_mm", "f_numbers", "k"],
            "additionalProperties": False,
            "properties": {
                "pitch_mm": _mm(0.005, 2.0, "physical microlens pitch D (5 um - 2 mm)"),
                "f_numbers": {
                    "description": "microlens F-number(s); the paper uses the middle one",
                    "oneOf": [
                        {"type": "number", "exclusiveMinimum": 0, "x-range": [0.5, 64.0]},
                        {"type": "array", "minItems": 1,
                         "items": {"type": "number", "exclusiveMinimum": 0,
                                   "x-range": [0.5, 64.0]}},
                    ],
                },
                "k": {"type": "number", "exclusiveMinimum": 0, "x-range": [0.0, 1000.0],
                      "description": "the paper's k: s = k f / (k - 1) behind a Keplerian "
                                     "MLA (k > 1), s = k f / (k + 1) behind a Galilean one "
                                     "(any k > 0: the sharp virtual plane k f behind it)"},
                "sensor_distance_mm": _mm(0.01, 20.0, "s, MLA-sensor distance (optional)"),
            },
        },
        "array": {
            "type": "object",
            "additionalProperties": False,
            "properties": {"step_mm": _mm(0.01, 1.0e4, "stage step between array shots")},
        },
        "scene": {
            "type": "object",
            "additionalProperties": False,
            "properties": {
                "near_mm": _mm(1.0, 1.0e7, "measured nearest object distance X_n"),
                "far_mm": _mm(1.0, 1.0e7, "measured farthest object distance X_f"),
            },
        },
    },
}

_UNIT = {"mm": "millimetres", "px": "pixels"}
#: a length unit (as written in a key's name or after a number) in millimetres
_LENGTH_MM = {"nm": 1e-6, "um": 1e-3, "\u00b5m": 1e-3, "\u03bcm": 1e-3, "mm": 1.0, "cm": 10.0,
              "m": 1000.0}
#: mla.sensor_distance_mm may differ this much (relative) from what mla.k gives
SENSOR_DISTANCE_TOLERANCE = 0.01
_NUMBER_WITH_UNIT = re.compile(
    r"\s*([-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?)\s*([A-Za-z\u00b5\u03bc]*)\s*")


def _dotted(path) -> str:
    parts = [str(p) for p in path]
    return ".".join(parts) if parts else "<top level>"


def _unit_hint(key: str) -> str:
    last = key.rsplit(".", 1)[-1]
    unit = last.rsplit("_", 1)[-1] if "_" in last else ""
    return f" in {_UNIT[unit]}" if unit in _UNIT else ""


def _unit_of(key: str) -> str:
    """The unit suffix of a key's name (``pixel_size_um`` -> ``um``), or ''."""
    last = key.rsplit(".", 1)[-1]
    return last.rsplit("_", 1)[-1] if "_" in last else ""


def _number_hint(key: str, text: str) -> str:
    """What to write instead of the string ``text`` in the number field ``key``: the value
    converted into the key's unit where the text gives a number and a length unit."""
    unit = _unit_of(key)
    where = f" in {_UNIT[unit]}" if unit in _UNIT else ""
    head = f"must be a plain number{where} (the unit is in the key name)"
    m = _NUMBER_WITH_UNIT.fullmatch(text)
    if m is None:
        return f"{head}; write the number without quotes or unit"
    value, written = float(m.group(1)), m.group(2)
    if not written or written == unit or (unit == "px" and written in ("pixels", "pixel")):
        return f"{head}: write {value:g} for {key}, without quotes or unit"
    if unit == "mm" and written in _LENGTH_MM:
        return (f"{head}: write {value * _LENGTH_MM[written]:g} for {key} ({text.strip()!r} "
                "in millimetres)")
    return f"{head}; {written!r} is not a unit this key can be converted from"


def _key_paths(schema: Mapping, path: tuple = ()) -> list[tuple[str, ...]]:
    """Every key path the schema knows, in its order (mappings before their keys)."""
    out = []
    for k, sub in schema.get("properties", {}).items():
        out.append((*path, k))
        out.extend(_key_paths(sub, (*path, k)))
    return out


def _nearest_key(key: str, here: list[str], path: tuple) -> tuple[str, ...] | None:
    """The known key that an unknown ``key`` (in the mapping at ``path``, whose keys are
    ``here``) was most likely meant to be: a close spelling at the same level, else a close
    spelling anywhere (a key put under the wrong mapping, e.g. a top-level ``k``)."""
    def close(word: str, candidates: list[str]) -> str | None:
        lower = {c.lower(): c for c in candidates}
        hit = difflib.get_close_matches(word.lower(), list(lower), n=1, cutoff=0.6)
        return lower[hit[0]] if hit else None

    same = close(key, here)
    if same is not None:
        return (*path, same)
    everywhere = [p for p in _key_paths(SCHEMA) if p[:-1] != path]
    leaf = close(key, [p[-1] for p in everywhere])
    return next((p for p in everywhere if p[-1] == leaf), None) if leaf else None


def _check_unknown_keys(doc: Any, schema: Mapping, path: tuple, source: str | Path) -> None:
    """Refuse a key the schema does not know, naming the nearest known one: a typo
    (``scene: {near: 470}`` for ``near_mm``) would otherwise leave the value unread and
    its check (Eqs. 2-3) silently skipped."""
    if not isinstance(doc, Mapping) or "properties" not in schema:
        return
    props = schema["properties"]
    for key, value in doc.items():
        if key in props:
            _check_unknown_keys(value, props[key], (*path, key), source)
            continue
        dotted = _dotted((*path, key))
        if not isinstance(key, str):
            kind = {bool: "a boolean", type(None): "null"}.get(type(key), "a number")
            raise DatasheetError(f"{source}: {dotted}: YAML reads the key {key!r} as {kind}; "
                                 "keys are names (see plenocal/calib/reg_b/datasheet.py SCHEMA)")
        where = _dotted(path) if path else "the top level"
        takes = f"{where} takes {', '.join(props)}"
        near = _nearest_key(key, list(props), path)
        if near is None:
            raise DatasheetError(f"{source}: {dotted}: unknown key ({takes}; every key: "
                                 "plenocal/calib/reg_b/datasheet.py SCHEMA)")
        hint = ""
        unit, want = _unit_of(key), _unit_of(near[-1])
        if (unit != want and unit in _LENGTH_MM and want == "mm"
                and isinstance(value, int | float) and not isinstance(value, bool)):
            hint = f"{value:g} {unit} is {_dotted(near)}: {value * _LENGTH_MM[unit]:g}; "
        raise DatasheetError(f"{source}: {dotted}: unknown key - did you mean "
                             f"{_dotted(near)}? ({hint}{takes})")


def _middle_f_number(mla: Mapping) -> float:
    """The middle of ``mla.f_numbers`` (one number or a list), the paper's."""
    from plenocal.optics import middle_f_number  # noqa: PLC0415

    fns = mla["f_numbers"]
    return middle_f_number(fns if isinstance(fns, list) else [fns])


def _check_sensor_distance(doc: Mapping, source: str | Path) -> None:
    """``mla.sensor_distance_mm`` and ``mla.k`` must agree: registration B takes ``s``
    where it is given and ignores ``k``, so a contradiction would pass unnoticed. ``k``
    gives ``s = k f / (k - 1)`` (Keplerian, ``s > f``) or ``k f / (k + 1)`` (Galilean,
    ``s < f``), ``f = F_n D`` with the middle F-number (the paper's)."""
    mla = doc["mla"]
    s = mla.get("sensor_distance_mm")
    if s is None:
        return
    F_n, D, k = _middle_f_number(mla), mla["pitch_mm"], mla["k"]
    f = F_n * D
    galilei = k * f / (k + 1.0)
    if s > f and k <= 1:
        raise _fail(source, "mla.k", k,
                    f"must be > 1 with mla.sensor_distance_mm = {s:g} mm: s beyond f = F_n D "
                    f"= {f:.4g} mm is a Keplerian MLA's, s = k f / (k - 1); k <= 1 is a "
                    f"Galilean one's (k f / (k + 1) = {galilei:.4g} mm)")
    kepler = k * f / (k - 1.0) if k > 1 else None  # k <= 1: Galilean only
    s_k = kepler if s > f else galilei
    if abs(s - s_k) > SENSOR_DISTANCE_TOLERANCE * s_k:
        either = ("" if kepler is None
                  else f"s = k f / (k - 1) = {kepler:.4g} mm (Keplerian MLA) or ")
        raise _fail(source, "mla.sensor_distance_mm", s,
                    f"contradicts mla.k = {k:g}: with f = F_n D = {F_n:g} x {D:g} = {f:.4g} mm, "
                    f"k gives {either}"
                    f"k f / (k + 1) = {galilei:.4g} mm (Galilean), {100 * (s / s_k - 1):+.1f} % "
                    "off; registration B would take sensor_distance_mm and ignore k: correct "
                    "one of them, or give only one")


def _fail(source: str | Path, key: str, value: Any, why: str) -> DatasheetError:
    return DatasheetError(f"{source}: {key} = {value!r}: {why}")


def _non_finite(doc: Any, path: tuple = ()) -> tuple[tuple, float] | None:
    """The first NaN or infinity in ``doc`` (YAML's .nan / .inf), with its path."""
    if isinstance(doc, Mapping):
        for k in sorted(doc, key=str):
            hit = _non_finite(doc[k], (*path, k))
            if hit:
                return hit
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            hit = _non_finite(v, (*path, i))
            if hit:
                return hit
    elif isinstance(doc, float) and not math.isfinite(doc):
        return path, doc
    return None


def _schema_message(err: jsonschema.ValidationError) -> str:
    key = _dotted(err.absolute_path)
    v = err.validator
    if v == "required":
        missing = [m for m in err.validator_value if m not in (err.instance or {})]
        return (f"missing key {'.'.join([*map(str, err.absolute_path), missing[0]])!r}"
                if missing else err.message)
    if v == "type":
        want = err.validator_value
        if want in ("number", "integer") and isinstance(err.instance, str):
            return _number_hint(key, err.instance)
        if want == "object":
            return "must be a mapping of keys to values (key: value lines), not a " + (
                "list" if isinstance(err.instance, list) else type(err.instance).__name__)
        return f"must be of type {want}"
    if v == "oneOf" and key.endswith("f_numbers"):
        if isinstance(err.instance, list) and not err.instance:
            return "the F-number list is empty: give the microlens F-number(s), e.g. [2.8]"
        return "must be a number or a non-empty list of positive numbers (e.g. [2.8])"
    if v == "exclusiveMinimum" and key.endswith(".k"):
        return ("must be > 0: the MLA-sensor distance is s = k f / (k - 1) behind a "
                "Keplerian MLA (k > 1) and k f / (k + 1) behind a Galilean one (k > 0), f "
                "the microlens focal length; typical values are 3-10")
    if v in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        word = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=",
                "exclusiveMaximum": "<"}[v]
        return f"must be {word} {err.validator_value}"
    if v == "minItems":
        return "must not be empty"
    return err.message


def _check_ranges(doc: Any, schema: Mapping, path: tuple, source: str | Path) -> None:
    """Plausibility: every number within its field's ``x-range`` (a value outside is
    almost surely in another unit, e.g. micrometres in a ``_mm`` key)."""
    if "x-range" in schema and isinstance(doc, int | float) and not isinstance(doc, bool):
        lo, hi = schema["x-range"]
        if not lo <= doc <= hi:
            key = _dotted(path)
            unit = _unit_hint(key)
            guess = ""
            if key.endswith("_mm") and doc > hi and lo <= doc / 1000.0 <= hi:
                guess = f"; {doc} looks like micrometres: {doc / 1000.0:g} mm is plausible"
            what = schema.get("description", "see plenocal/calib/reg_b/datasheet.py")
            raise _fail(source, key, doc, f"outside the plausible range {lo:g}-{hi:g}{unit} "
                        f"({what}){guess}")
    if isinstance(doc, Mapping):
        for k, sub in schema.get("properties", {}).items():
            if k in doc:
                _check_ranges(doc[k], sub, (*path, k), source)
    for alt in schema.get("oneOf", []):
        if alt.get("type") == "array" and isinstance(doc, list):
            for i, v in enumerate(doc):
                _check_ranges(v, alt["items"], (*path, i), source)
        elif alt.get("type") == "number" and not isinstance(doc, list):
            _check_ranges(doc, alt, path, source)


def check_datasheet(doc: Any, source: str | Path = "camera.yaml") -> dict:
    """Validate a parsed ``camera.yaml``; raise :class:`DatasheetError` naming the key."""
    if not isinstance(doc, Mapping):
        kind = "empty" if doc is None else f"a {type(doc).__name__}"
        raise DatasheetError(f"{source}: the file is {kind}; it must be a mapping of keys "
                             "to values (pixel_size_mm: ..., mla: {...}; see README, "
                             "'Bringing a real capture')")
    _check_unknown_keys(doc, SCHEMA, (), source)
    bad = _non_finite(doc)
    if bad:
        raise _fail(source, _dotted(bad[0]), bad[1], "must be a finite number")
    validator = jsonschema.Draft202012Validator(SCHEMA)
    errors = list(validator.iter_errors(doc))
    if errors:
        # the deepest error is the most specific; ties in file order
        err = max(errors, key=lambda e: len(e.absolute_path))
        if err.validator == "required":
            raise DatasheetError(f"{source}: {_schema_message(err)} (the datasheet must give "
                                 "it; see plenocal/calib/reg_b/datasheet.py SCHEMA for every key)")
        shown = err.instance if not isinstance(err.instance, Mapping) else "{...}"
        raise _fail(source, _dotted(err.absolute_path), shown, _schema_message(err))
    _check_ranges(doc, SCHEMA, (), source)
    _check_sensor_distance(doc, source)
    ml, scene = doc["main_lens"], doc.get("scene") or {}
    F, X_o = ml.get("focal_length_mm"), ml["focus_distance_mm"]
    if F is not None and X_o <= F:
        raise _fail(source, "main_lens.focus_distance_mm", X_o,
                    f"must exceed the focal length ({F} mm): a focus distance inside the "
                    "focal length forms no real image")
    near, far = scene.get("near_mm"), scene.get("far_mm")
    if near is not None and far is not None and not near < far:
        raise _fail(source, "scene.near_mm", near, f"must be less than scene.far_mm ({far})")
    if F is not None and near is not None and far is not None:
        optics = _optics(doc, mla_kind(doc))
        why = virtual_depth_problem(optics, near / 1000.0, far / 1000.0)
        if why:
            raise _fail(source, "main_lens.focus_distance_mm", X_o, why)
    return dict(doc)


#: calib.xml's micro-image pitch may differ this much (relative) from the one camera.yaml's
#: optics give (:func:`check_micro_image_pitch`)
MICRO_IMAGE_PITCH_TOLERANCE = 0.05
#: without main_lens.focal_length_mm the micro images' spread (L + s) / L is unknown: up to
#: this much more is taken (s / L: a 1 mm MLA-sensor distance behind a 10 mm lens)
MICRO_IMAGE_SPREAD_MAX = 0.10


def check_micro_image_pitch(doc: Mapping, diameter_px: float,
                            source: str | Path = "camera.yaml",
                            calib_source: str | Path = "calib.xml") -> None:
    """camera.yaml's microlens pitch and pixel size against calib.xml's micro-image pitch
    ``diameter_px`` (a checked datasheet, :func:`check_datasheet`). The micro images lie
    ``D (L + s) / (L p)`` pixels apart
    (:attr:`plenocal.optics.PlenopticOptics.micro_image_pitch_px`); where the main lens's
    focal length is not given, ``D / p`` to :data:`MICRO_IMAGE_SPREAD_MAX` more.
    :data:`MICRO_IMAGE_PITCH_TOLERANCE` either way is taken.
    Registration B builds the rig from ``mla.pitch_mm`` and the converter reads the
    diameter from calib.xml, so a pitch in the wrong unit that the plausible range lets
    through (0.013 for 13 um against 0.13 mm) or another camera's calib.xml would give a rig
    of the wrong size without a word. Raises :class:`DatasheetError` naming both files."""
    D, p = doc["mla"]["pitch_mm"], doc["pixel_size_mm"]
    if doc["main_lens"].get("focal_length_mm") is not None:
        lo = hi = _optics(doc, mla_kind(doc)).micro_image_pitch_px
        how = "D (L + s) / (L p)"
    else:
        lo, hi = D / p, (1.0 + MICRO_IMAGE_SPREAD_MAX) * D / p
        how = (f"D / p, or up to {100 * MICRO_IMAGE_SPREAD_MAX:.0f} % more "
               "(main_lens.focal_length_mm not given)")
    tol = MICRO_IMAGE_PITCH_TOLERANCE
    if (1.0 - tol) * lo <= diameter_px <= (1.0 + tol) * hi:
        return
    expected = lo if diameter_px < lo else hi
    apart = f"{lo:.2f}" if lo == hi else f"{lo:.2f} to {hi:.2f}"
    raise _fail(source, "mla.pitch_mm", D,
                f"with pixel_size_mm = {p:g} it puts the micro images {apart} px apart "
                f"({how}), but {calib_source} gives a diameter of {diameter_px:.2f} px "
                f"({100 * (diameter_px / expected - 1):+.1f} %, more than "
                f"{100 * tol:.0f} %): check both keys' units (millimetres), and that "
                f"{calib_source} is this camera's")


#: the smallest patch (micro-image pitch / virtual depth) a view can be rendered from
MIN_PATCH_PX = 1.0


def virtual_depth_problem(optics, near_m: float, far_m: float) -> str | None:
    """Why the scene cannot be converted with these optics, or None.

    A point at virtual depth v is repeated in micro images ``v`` apart, so each micro
    image contributes a patch of D_px / |v| pixels (the RLC conversion of Fig. 1 (a)):
    past D_px / MIN_PATCH_PX no view can be rendered. A focus distance just outside the
    focal length puts the image near infinity: virtual depths in the thousands."""
    d_px = float(optics.micro_image_pitch_px)
    vs = [float(optics.virtual_depth(z)) for z in (near_m, far_m)]
    worst = max(abs(v) for v in vs)
    limit = d_px / MIN_PATCH_PX
    if not math.isfinite(worst) or worst > limit:
        return (f"virtual depths {vs[0]:.4g} (near) to {vs[1]:.4g} (far): patches of "
                f"{d_px / worst:.3g} px in {d_px:.1f} px micro images, under "
                f"{MIN_PATCH_PX:g} px no view can be rendered (|v| <= {limit:.1f}); move the "
                "focus distance further from the focal length, or check its unit")
    return None


def mla_kind(doc: Mapping) -> str:
    """The MLA kind a checked datasheet implies, for its own checks (the workflow's kind is
    the converter's, ``disparity.json``): by ``mla.sensor_distance_mm`` against
    ``f = F_n D`` where given (``s > f``: Keplerian), Galilean where ``k <= 1`` (no Keplerian
    MLA has it), else Keplerian, the paper's."""
    mla = doc["mla"]
    s = mla.get("sensor_distance_mm")
    if s is not None:
        return "keplerian" if s > _middle_f_number(mla) * mla["pitch_mm"] else "galilean"
    return "galilean" if mla["k"] <= 1 else "keplerian"


def _optics(doc: Mapping, kind: str):
    """The thin-lens optics the datasheet describes (metres), for the checks above."""
    from plenocal.optics import PlenopticOptics  # noqa: PLC0415

    mla, ml = doc["mla"], doc["main_lens"]
    return PlenopticOptics(
        focal_length=ml["focal_length_mm"] / 1000.0, focus_distance=ml["focus_distance_mm"]
        / 1000.0, mla_pitch=mla["pitch_mm"] / 1000.0, mla_f_number=_middle_f_number(mla),
        k=mla["k"], pixel_size=doc["pixel_size_mm"] / 1000.0, width=doc["sensor_width_px"],
        height=doc["sensor_height_px"], kind=kind)


def load_datasheet(path: str | Path) -> dict:
    """Read and validate ``camera.yaml`` (see :data:`SCHEMA`)."""
    path = Path(path)
    if not path.is_file():
        keys = ", ".join(f"{k}: {', '.join(v['required'])}" if "required" in v else k
                         for k, v in SCHEMA["properties"].items()
                         if k in SCHEMA.get("required", ()))
        raise FileNotFoundError(
            f"{path}: camera datasheet not found (camera.yaml is written by the simulator, "
            "or put next to a real capture's calib.xml; it needs " + keys + ". A template: "
            "`snakemake -j1 --until simulate_setup` writes data/synthetic/camera.yaml; "
            "README, 'Bringing a real capture')")
    try:
        doc = load_yaml_unique(path.read_text(), path)
    except yaml.YAMLError as exc:
        raise DatasheetError(f"{path}: not valid YAML: {exc}") from None
    return check_datasheet(doc, path)


def load_yaml_unique(text: str, source: str | Path = "<string>") -> Any:
    """YAML ``text`` parsed safely, refusing a key given twice in one mapping (PyYAML keeps
    the last one silently): :class:`DatasheetError` naming the key and both lines
    (:func:`plenocal.io.yamlfile.load_yaml_unique`)."""
    try:
        return yamlfile.load_yaml_unique(text, source)
    except yamlfile.DuplicateKeyError as exc:
        raise DatasheetError(str(exc)) from None


# The checked datasheet, typed, as registration B computes with it


@dataclass(frozen=True)
class Datasheet:
    """What ``camera.yaml`` gives (millimetres)."""

    pixel_size: float  # p
    sensor_width: int
    sensor_height: int
    focus_distance: float  # X_o
    focal_length_nominal: float  # main lens, nominal (information only: F comes from F_m P)
    mla_pitch: float  # D, physical
    f_numbers: tuple[float, ...]
    k: float
    sensor_distance: float | None  # s, if the datasheet gives it
    array_step: float | None
    near: float | None  # measured X_n
    far: float | None  # measured X_f


def _need(doc: Mapping, path: str, source: str | Path):
    cur: object = doc
    for part in path.split("."):
        if not isinstance(cur, Mapping) or part not in cur:
            raise ValueError(f"{source}: missing key {path!r} (the datasheet must give it; "
                             "see read_datasheet in plenocal/calib/reg_b/datasheet.py for "
                             "the expected keys)")
        cur = cur[part]
    return cur


def _opt(doc: Mapping, path: str):
    cur: object = doc
    for part in path.split("."):
        if not isinstance(cur, Mapping) or part not in cur or cur[part] is None:
            return None
        cur = cur[part]
    return cur


def read_datasheet(path: str | Path) -> Datasheet:
    """Read ``camera.yaml``: pixel_size_mm, sensor_width_px, sensor_height_px,
    main_lens.{focus_distance_mm, focal_length_mm}, mla.{pitch_mm, f_numbers, k,
    sensor_distance_mm (optional)}, array.step_mm, scene.{near_mm, far_mm}. Without
    sensor_distance_mm, ``s`` follows from ``k`` by the MLA kind of the converter's
    disparity.json (:func:`plenocal.calib.reg_b.paper_model.sensor_distance`).

    Validated against :data:`SCHEMA` first: a bad value raises :class:`DatasheetError`
    naming the file and the key."""
    path = Path(path)
    doc = load_datasheet(path)
    fn = _need(doc, "mla.f_numbers", path)
    fns = tuple(float(x) for x in (fn if isinstance(fn, list | tuple) else [fn]))
    opt_f = lambda key: None if _opt(doc, key) is None else float(_opt(doc, key))  # noqa: E731
    return Datasheet(
        pixel_size=float(_need(doc, "pixel_size_mm", path)),
        sensor_width=int(_need(doc, "sensor_width_px", path)),
        sensor_height=int(_need(doc, "sensor_height_px", path)),
        focus_distance=float(_need(doc, "main_lens.focus_distance_mm", path)),
        focal_length_nominal=float(_opt(doc, "main_lens.focal_length_mm") or float("nan")),
        mla_pitch=float(_need(doc, "mla.pitch_mm", path)),
        f_numbers=fns,
        k=float(_need(doc, "mla.k", path)),
        sensor_distance=opt_f("mla.sensor_distance_mm"),
        array_step=opt_f("array.step_mm"),
        near=opt_f("scene.near_mm"),
        far=opt_f("scene.far_mm"),
    )
