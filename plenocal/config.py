"""Configuration: JSON-schema validation with defaults, plus the checks a schema
cannot express (a focus distance inside the focal length, near beyond far, ...).

Errors name the key by its dotted path and say why, e.g.::

    config: datasets.synthetic.views = 4: must be an odd number

config.schema.yaml is the one source of every setting's default: :func:`validate_config`
fills the workflow's config from it, :func:`with_defaults` fills a partial block (of a
test, a benchmark, a library caller), and :func:`stage_defaults` gives a block's defaults
to the settings dataclasses. The package writes no default of its own.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import yaml

if TYPE_CHECKING:  # jsonschema is imported where a config is validated, not by every job
    import jsonschema

SCHEMA_PATH = Path(__file__).resolve().parent.parent / "config.schema.yaml"
# libyaml's parser where PyYAML has it (the same constructors, a tenth of the time: the
# settings dataclasses read their defaults from the schema when their module is imported)
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class ConfigError(ValueError):
    """An invalid configuration; the message names the key and the reason."""


def load_schema(path: str | Path | None = None) -> dict:
    with open(path or SCHEMA_PATH) as fh:
        return yaml.load(fh, Loader=_LOADER)  # a safe loader (C or Python)


@functools.lru_cache(maxsize=2)
def _parsed_schema(text: str) -> dict:
    """A schema's text, parsed once per process (read only: defaults are copied). Keyed
    by the text, not the path: the workflow validates against its own copy of
    config.schema.yaml, and the settings dataclasses read the package's, the same bytes
    in a checkout (the Snakefile's parse read it twice: issue 15, the no-op)."""
    return yaml.load(text, Loader=_LOADER)  # a safe loader (C or Python)


def _read_schema(path: str | Path) -> dict:
    return _parsed_schema(Path(path).read_text())


def _package_schema() -> dict:
    """config.schema.yaml of the package (read only)."""
    return _read_schema(SCHEMA_PATH)


def _resolve(schema: dict, root: dict) -> dict:
    """``schema`` with its local ``$ref`` (``#/$defs/<name>``) followed."""
    while "$ref" in schema:
        target: Any = root
        for part in schema["$ref"].removeprefix("#/").split("/"):
            target = target[part]
        schema = target
    return schema


def _fill_defaults(schema: dict, instance: Any, root: dict) -> None:
    """Fill ``instance`` in place with the ``default`` of every property it lacks, at every
    depth (a property's own ``default``, not its ``$ref`` target's: a dataset without
    ``simulate`` stays a real capture), as a validator that sets defaults would."""
    if not isinstance(instance, dict):
        return
    schema = _resolve(schema, root)
    props = schema.get("properties", {})
    for key, sub in props.items():
        if key not in instance and "default" in sub:
            instance[key] = copy.deepcopy(sub["default"])
        if key in instance:
            _fill_defaults(sub, instance[key], root)
    extra = schema.get("additionalProperties")
    if isinstance(extra, dict):
        for key, value in instance.items():
            if key not in props:
                _fill_defaults(extra, value, root)


def _block_schema(block: str) -> dict:
    """The schema of config block ``block``: a ``$defs`` name, then property names
    (``depth``, ``depth.sgm``, ``convert.blend``, ``simulate.sensor``)."""
    root = _package_schema()
    name, *rest = block.split(".")
    schema = root["$defs"].get(name, {})
    for part in rest:
        schema = _resolve(schema, root).get("properties", {}).get(part, {})
    schema = _resolve(schema, root)
    if "properties" not in schema:
        known = sorted(k for k, v in root["$defs"].items() if "properties" in v)
        raise ConfigError(f"{SCHEMA_PATH}: no config block {block!r} (blocks: "
                          f"{', '.join(known)}, and their sub-blocks as 'depth.sgm')")
    return schema


def with_defaults(block: str, cfg: Mapping[str, Any] | None) -> dict:
    """A copy of ``cfg``, a (partial) config block, with the schema's defaults filled in.

    ``block`` names the block in config.schema.yaml: its definition under ``$defs``
    (``convert``, ``sfm``, ``rig``, ``depth``, ``scale``, ``verify``, or ``simulate``, a
    dataset's), then, dotted, a sub-block (``depth.sgm``). Keys the schema does not know
    are kept and not checked (:func:`validate_config` checks a whole config). ``None``:
    the block's defaults."""
    out = copy.deepcopy(dict(cfg)) if cfg is not None else {}
    _fill_defaults(_block_schema(block), out, _package_schema())
    return out


def deep_update(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict:
    """A copy of ``base`` with ``over``'s keys set into it, nested blocks key by key (a
    block in ``over`` changes only the keys it names of ``base``'s block)."""
    out = copy.deepcopy(dict(base))
    for key, value in over.items():
        out[key] = (deep_update(out.get(key, {}), value) if isinstance(value, Mapping)
                    else copy.deepcopy(value))
    return out


def stage_defaults(block: str) -> dict:
    """The schema's defaults of config block ``block`` (see :func:`with_defaults`)."""
    return with_defaults(block, None)


_Settings = TypeVar("_Settings")


def settings_from(cls: type[_Settings], block: Mapping[str, Any]) -> _Settings:
    """The settings dataclass ``cls`` from the keys of a config block that name its fields
    (the others are ignored: one block may hold the settings of several dataclasses).
    Fill a partial block first (:func:`with_defaults`)."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in block.items() if k in names})


def _dotted(path: tuple) -> str:
    """A key path as the messages spell it: ``datasets.tiny.simulate.mla.focal_ratios[0]``."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top level>"


def _non_finite(value: Any, path: tuple = ()) -> tuple[tuple, float] | None:
    """The first NaN or infinity in ``value`` (YAML's ``.nan``, ``.inf``), with its key
    path; mappings in sorted key order, so the same config names the same key."""
    if isinstance(value, dict):
        for k in sorted(value, key=str):
            hit = _non_finite(value[k], (*path, k))
            if hit:
                return hit
    elif isinstance(value, list):
        for i, v in enumerate(value):
            hit = _non_finite(v, (*path, i))
            if hit:
                return hit
    elif isinstance(value, float) and not math.isfinite(value):
        return path, value
    return None


#: a dataset's name: a folder under data/ and results/, and part of every rule's paths
DATASET_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")


def _check_keys(value: Any, path: tuple = ()) -> None:
    """Every mapping key is text (YAML reads ``5:`` as a number, ``yes:`` as a boolean),
    and every dataset name is a plain name (checked whole: ``re.fullmatch``, where the
    schema's ``pattern`` is searched and its ``$`` also matches before a final newline)."""
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, str):
                kind = {bool: "a boolean", type(None): "null"}.get(type(k), "a number")
                raise ConfigError(
                    f"config: {_dotted((*path, str(k)))}: YAML reads the key {k!r} as {kind}, "
                    f"not as text; quote it (\"{k}\": ...) or rename it")
            if path == ("datasets",) and not DATASET_NAME.fullmatch(k):
                raise ConfigError(
                    f"config: datasets.{k!r}: a dataset name must be letters, digits, '-' and "
                    "'_', starting with a letter or digit (it names data/<name>/ and "
                    "results/<name>/); rename it")
            _check_keys(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_keys(v, (*path, i))


def _strict_validator(schema: dict) -> jsonschema.protocols.Validator:
    """The schema's validator, with ``integer`` meaning a whole number written as one:
    JSON schema counts 3.0 as an integer, and ``views: 3.0`` then failed in range()."""
    import jsonschema  # noqa: PLC0415 - see the TYPE_CHECKING import

    base = jsonschema.validators.validator_for(schema)
    checker = base.TYPE_CHECKER.redefine(
        "integer", lambda _, x: isinstance(x, int) and not isinstance(x, bool))
    return jsonschema.validators.extend(base, type_checker=checker)(schema)


def _path(error: jsonschema.ValidationError) -> str:
    parts = [str(p) for p in error.absolute_path]
    return ".".join(parts) if parts else "<top level>"


#: a pattern of named words only (``^auto$``, ``^(auto|file)$``): the words a string may be
_WORDS = re.compile(r"^\^\(?([A-Za-z0-9_]+(?:\|[A-Za-z0-9_]+)*)\)?\$$")
_BOUND = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=", "exclusiveMaximum": "<"}


def _bounds(schema: dict) -> str:
    if "minimum" in schema and "maximum" in schema:
        return f" from {schema['minimum']} to {schema['maximum']}"
    parts = [f"{word} {schema[k]}" for k, word in _BOUND.items() if k in schema]
    return f" {' and '.join(parts)}" if parts else ""


def _accepted(schema: dict, root: dict) -> list[str]:
    """What ``schema`` accepts, one short phrase per alternative ("a number > 0", "auto",
    "a whole number from 2 to 128", "null"), for an error that must say what to write
    rather than which of JSON schema's rules failed."""
    schema = _resolve(schema, root) if isinstance(schema, dict) else {}
    for key in ("oneOf", "anyOf"):
        if key in schema:
            return [a for sub in schema[key] for a in _accepted(sub, root)]
    if "const" in schema:
        return [str(schema["const"])]
    if "enum" in schema:
        return [str(x) for x in schema["enum"]]
    types = schema.get("type")
    out = []
    for t in [types] if isinstance(types, str) else (types or []):
        if t == "string":
            words = _WORDS.match(schema.get("pattern", ""))
            out += words.group(1).split("|") if words else ["a string"]
        elif t in ("integer", "number"):
            out.append(("a whole number" if t == "integer" else "a number") + _bounds(schema))
        elif t == "null":
            out.append("null")
        elif t == "boolean":
            out.append("true or false")
        elif t == "object":
            out.append("a mapping")
        elif t == "array":
            out.append("a list")
        else:
            out.append(f"a{'n' if t[0] in 'aeiou' else ''} {t}")
    return out


def _one_of(phrases: list[str]) -> str:
    return phrases[0] if len(phrases) == 1 else f"{', '.join(phrases[:-1])}, or {phrases[-1]}"


def _reason(error: jsonschema.ValidationError, root: dict | None = None) -> str:
    v = error.validator
    s = error.schema if isinstance(error.schema, dict) else {}
    accepted = _accepted(s, root or {}) if v in ("oneOf", "anyOf", "type", "pattern") else []
    if v in ("oneOf", "anyOf") and accepted:
        return f"must be {_one_of(accepted)}"
    if v == "pattern" and isinstance(s.get("type"), list) and accepted:
        return f"must be {_one_of(accepted)}"
    if v == "not" and s.get("not", {}).get("multipleOf") == 2:
        return "must be an odd number"
    if v == "additionalProperties":
        extra = sorted(map(str, set(error.instance) - set(s.get("properties", {}))))
        allowed = ", ".join(sorted(s.get("properties", {}))) or "none"
        return f"unknown key(s) {', '.join(extra)} (allowed: {allowed})"
    if v == "type":
        expected = error.validator_value
        if ("integer" in ([expected] if isinstance(expected, str) else expected)
                and isinstance(error.instance, float) and error.instance.is_integer()):
            return (f"must be a whole number: write {int(error.instance)}, not "
                    f"{error.instance!r}")
        if isinstance(expected, list) and accepted:
            return f"must be {_one_of(accepted)}"
        return f"must be of type {expected}"
    if v in _BOUND:
        word = _BOUND[v]
        # x-why: the reason for the lower bound (views: N >= 3), not for an upper one
        why = (error.schema.get("x-why") if isinstance(error.schema, dict)
               and v in ("minimum", "exclusiveMinimum") else None)
        return f"must be {word} {error.validator_value}" + (f": {why}" if why else "")
    if v == "enum":
        return f"must be one of {', '.join(map(str, error.validator_value))}"
    return error.message


def _fail(key: str, value: Any, why: str) -> ConfigError:
    return ConfigError(f"config: {key} = {value!r}: {why}")


def validate_config(config: dict, schema_path: str | Path | None = None) -> dict:
    """Validate ``config`` in place (defaults filled in) and return it."""
    schema = _read_schema(schema_path or SCHEMA_PATH)  # read only
    _check_keys(config)
    _fill_defaults(schema, config, schema)
    # before the schema: a comparison with NaN is always false, so no minimum or maximum
    # refuses it (step_m: .nan ran, and wrote null poses)
    bad = _non_finite(config)
    if bad:
        raise _fail(_dotted(bad[0]), bad[1], "must be a finite number (YAML reads .nan and "
                    ".inf as numbers; give the value, or leave the key out for its default)")
    validator = _strict_validator(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if errors:
        # the deepest error is the most specific one
        err = max(errors, key=lambda e: len(e.absolute_path))
        raise _fail(_path(err), err.instance if not isinstance(err.instance, dict) else "{...}",
                    _reason(err, schema))
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
    from plenocal.calib.reg_b.datasheet import virtual_depth_problem  # noqa: PLC0415

    for name, ds in config["datasets"].items():
        sim = ds.get("simulate")
        if sim is None:
            continue
        if ds.get("video") is not None:
            raise _fail(f"datasets.{name}.video", "{...}",
                        "only a real capture's shots are given as videos (the simulator "
                        "writes lenslet PNGs): remove the key, or the simulate block")
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
    if c["view_spacing_px"] is not None and c["view_spacing_px"] <= 0:
        raise _fail("convert.view_spacing_px", c["view_spacing_px"], "must be > 0")
    lo, hi = c["disparity_percentiles"]
    if not lo < hi:
        raise _fail("convert.disparity_percentiles", c["disparity_percentiles"],
                    "the low percentile first, below the high one (e.g. [2, 98]); "
                    "reversed, D_min and D_max swap places")
    b = c["blend"]
    if b["wider_slots"] < b["wide_slots"]:
        raise _fail("convert.blend.wider_slots", b["wider_slots"],
                    f"must be at least convert.blend.wide_slots ({b['wide_slots']}): the "
                    "views that reach farther blend at least as many lenses")
    s = config["scale"]
    if not s["low_percentile"] < s["high_percentile"]:
        raise _fail("scale.low_percentile", s["low_percentile"],
                    f"must be less than scale.high_percentile ({s['high_percentile']})")
    for key, block in (("depth", config["depth"]), ("depth.sgm", config["depth"]["sgm"])):
        if block["min_depths"] > block["max_depths"]:
            raise _fail(f"{key}.min_depths", block["min_depths"],
                        f"must be at most {key}.max_depths ({block['max_depths']})")
    v = config["verify"]
    if v["renderer"] == "rvs":
        if not v["rvs_binary"]:
            raise _fail("verify.renderer", "rvs", "needs verify.rvs_binary, the path of an "
                        "RVS 4.0 binary (README, 'MPEG exports and RVS'), or renderer: dibr")
        if not Path(v["rvs_binary"]).expanduser().is_file():
            raise _fail("verify.rvs_binary", v["rvs_binary"], "no such file: give the path "
                        "of an RVS 4.0 binary (README, 'MPEG exports and RVS')")
    _check_refine(config["refine"])
    m = config["sfm"]["view_matching"]
    if m["within_shot"] != "grid":
        _unused("sfm.view_matching", m, "view_radius", f"with sfm.view_matching.within_shot "
                f"= {m['within_shot']} (each view is matched with its shot's central view; "
                "view_radius sets which views grid matches)",
                "remove it, or set within_shot to grid")


def _unused(block: str, cfg: Mapping[str, Any], key: str, why: str, remedy: str) -> None:
    """Refuse ``block.key`` set away from its schema default where ``why`` says the other
    keys leave it nothing to do (the run would ignore it without a word)."""
    if cfg[key] != stage_defaults(block)[key]:
        raise _fail(f"{block}.{key}", cfg[key], f"has no effect {why}; {remedy}")


def _check_refine(r: Mapping[str, Any]) -> None:
    """refine: keys set away from their default where the other keys leave them nothing to
    do - the run would ignore them without a word (a config review's finding)."""
    if not r["enabled"]:
        return  # the paper's method alone: every other refine key is left unused, knowingly

    def unused(key: str, why: str, remedy: str) -> None:
        _unused("refine", r, key, why, remedy)

    if r["rig"] == "hold" and r["frames"] == "refine":
        unused("scale", "with refine.rig = hold, where the held rig's metric baselines give "
               "the result's scale", "remove it, or choose a refine.rig that keeps the "
               "merge's scale (scale, scale_pp, free)")
    if r["focal"] == "hold":
        unused("final_iterations", "with refine.focal = hold (the final pass follows the "
               "focal pass, which a held focal length does not run; max_iterations caps the "
               "one pass)", "remove it, or set refine.focal to refine")
    if r["tracks"] == "central":
        unused("matches", "with refine.tracks = central (the central views' own matches; "
               "refine.matches chooses among every view's, rule view_matches)",
               "remove it, or set refine.tracks to views or both")
    if r["tracks"] == "views":
        for key in ("carry_every", "central_contrast"):
            unused(key, "with refine.tracks = views (it sets how the central views' points "
                   "are found and carried, a track set views does not use)",
                   "remove it, or set refine.tracks to central or both")
