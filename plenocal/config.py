"""Configuration: JSON-schema validation with defaults, plus the checks a schema
cannot express (a focus distance inside the focal length, near beyond far, ...).

Errors name the key by its dotted path and say why, e.g.::

    config: datasets.synthetic.views = 4: must be an odd number
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from plenocal.calib.reg_b.datasheet import virtual_depth_problem

SCHEMA_PATH = Path(__file__).resolve().parent.parent / "config.schema.yaml"


class ConfigError(ValueError):
    """An invalid configuration; the message names the key and the reason."""


def load_schema(path: str | Path | None = None) -> dict:
    with open(path or SCHEMA_PATH) as fh:
        return yaml.safe_load(fh)


def _with_defaults(validator_class: type) -> type:
    validate_properties = validator_class.VALIDATORS["properties"]

    def set_defaults(validator: Any, properties: dict, instance: Any,
                     schema: dict) -> Iterator[Any]:
        if isinstance(instance, dict):
            for key, sub in properties.items():
                if key in instance:
                    continue
                if "default" in sub:
                    instance[key] = copy.deepcopy(sub["default"])
                elif "$ref" in sub and "default" in sub:
                    instance[key] = copy.deepcopy(sub["default"])
        yield from validate_properties(validator, properties, instance, schema)

    return jsonschema.validators.extend(validator_class, {"properties": set_defaults})


def _path(error: jsonschema.ValidationError) -> str:
    parts = [str(p) for p in error.absolute_path]
    return ".".join(parts) if parts else "<top level>"


def _reason(error: jsonschema.ValidationError) -> str:
    v = error.validator
    s = error.schema if isinstance(error.schema, dict) else {}
    if v == "not" and s.get("not", {}).get("multipleOf") == 2:
        return "must be an odd number"
    if v == "additionalProperties":
        extra = sorted(set(error.instance) - set(s.get("properties", {})))
        allowed = ", ".join(sorted(s.get("properties", {}))) or "none"
        return f"unknown key(s) {', '.join(extra)} (allowed: {allowed})"
    if v == "type":
        return f"must be of type {error.validator_value}"
    if v in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        word = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=",
                "exclusiveMaximum": "<"}[v]
        why = error.schema.get("x-why") if isinstance(error.schema, dict) else None
        return f"must be {word} {error.validator_value}" + (f": {why}" if why else "")
    if v == "enum":
        return f"must be one of {', '.join(map(str, error.validator_value))}"
    return error.message


def _fail(key: str, value: Any, why: str) -> ConfigError:
    return ConfigError(f"config: {key} = {value!r}: {why}")


def validate_config(config: dict, schema_path: str | Path | None = None) -> dict:
    """Validate ``config`` in place (defaults filled in) and return it."""
    schema = load_schema(schema_path)
    cls = _with_defaults(jsonschema.validators.validator_for(schema))
    validator = cls(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if errors:
        # the deepest error is the most specific one
        err = max(errors, key=lambda e: len(e.absolute_path))
        raise _fail(_path(err), err.instance if not isinstance(err.instance, dict) else "{...}",
                    _reason(err))
    _check_semantics(config)
    return config


def canonical(value: Any) -> Any:
    """``value`` with every mapping's keys in sorted order, recursively (lists keep their
    order: it means something there). The workflow passes config slices to its rules as
    ``params``, and Snakemake compares params by their text: without this, a config whose
    keys are merely reordered (a YAML tool that sorts keys, a user who moves ``seed``
    below ``array``) would rerun every rule, simulation included."""
    if isinstance(value, dict):
        return {k: canonical(value[k]) for k in sorted(value, key=str)}
    if isinstance(value, list):
        return [canonical(v) for v in value]
    return value


def canonicalize(config: dict) -> dict:
    """Put ``config`` into :func:`canonical` order in place (Snakemake's ``config`` object
    is shared by every rule file) and return it."""
    ordered = canonical(config)
    config.clear()
    config.update(ordered)
    return config


def _check_semantics(config: dict) -> None:
    for name, ds in config["datasets"].items():
        sim = ds.get("simulate")
        if sim is None:
            continue
        key = f"datasets.{name}.simulate"
        F_m = sim["main_lens"]["focal_length_mm"] / 1000.0
        X_o = sim["main_lens"]["focus_distance_m"]
        if X_o <= F_m:
            raise _fail(f"{key}.main_lens.focus_distance_m", X_o,
                        f"must exceed the focal length ({F_m} m): a focus distance inside "
                        "the focal length forms no real image")
        near, far = sim["scene"]["near_m"], sim["scene"]["far_m"]
        if not near < far:
            raise _fail(f"{key}.scene.near_m", near, f"must be less than far_m ({far})")
        from plenocal.simulate.optics_setup import optics_from_config  # noqa: PLC0415

        optics = optics_from_config(sim)
        # the smallest |v| of the scene: at the near plane, or (Galilean, v < 0) the far one
        v_near = float(-optics.virtual_depth(far) if optics.galilean
                       else optics.virtual_depth(near))
        if v_near < 1.5:
            raise _fail(f"{key}.scene.near_m", near,
                        f"virtual depth {v_near:.2f} at the near plane: below 1.5 a point is "
                        "seen by too few microlenses to be matched (raise mla.k, the focal "
                        "length or near_m)")
        why = virtual_depth_problem(optics, near, far)
        if why:
            raise _fail(f"{key}.main_lens.focus_distance_m", X_o, why)
    c = config["convert"]
    if c.get("view_spacing_px") is not None and c["view_spacing_px"] <= 0:
        raise _fail("convert.view_spacing_px", c["view_spacing_px"], "must be > 0")
    s = config["scale"]
    if not s["low_percentile"] < s["high_percentile"]:
        raise _fail("scale.low_percentile", s["low_percentile"],
                    f"must be less than scale.high_percentile ({s['high_percentile']})")
