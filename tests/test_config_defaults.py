"""config.schema.yaml is the one source of the settings' defaults (issue 16).

Three checks: the partial-block filler agrees with the workflow's validation; every
config reader called with an empty block reads the schema's defaults - shown with a
schema whose defaults are all changed, so a default written again in the package (a
``.get(key, literal)``, a dataclass literal) reads the old value and fails; and no
``.get("<schema key>", default)`` nor literal dataclass default of a schema key is left
in the package's source."""

from __future__ import annotations

import ast
import copy
from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from plenocal import config as config_module
from plenocal.config import (
    ConfigError,
    settings_from,
    stage_defaults,
    validate_config,
    with_defaults,
)

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("convert", "sfm", "rig", "depth", "scale", "verify")


def _validated(schema_path: Path | None = None) -> dict:
    """A config of one simulated dataset with nothing set: every value the schema's."""
    return validate_config({"datasets": {"s": {"simulate": {}}}}, schema_path)


def test_with_defaults_fills_as_the_workflow_validation():
    cfg = _validated()
    for stage in STAGES:
        assert with_defaults(stage, {}) == with_defaults(stage, None) == cfg[stage], stage
        assert stage_defaults(stage) == cfg[stage]
    assert stage_defaults("simulate") == cfg["datasets"]["s"]["simulate"]
    assert stage_defaults("depth.sgm") == cfg["depth"]["sgm"]
    assert stage_defaults("convert.blend") == cfg["convert"]["blend"]
    # a partial block keeps what it sets, at any depth, and gets the rest
    part = {"window": 9, "sgm": {"p1": 0.1}, "colmap": {}}
    full = with_defaults("depth", part)
    assert full == validate_config({"datasets": {"s": {}}, "depth": copy.deepcopy(part)})["depth"]
    assert (full["window"], full["sgm"]["p1"]) == (9, 0.1)
    assert full["sgm"]["p2"] == cfg["depth"]["sgm"]["p2"]
    assert part == {"window": 9, "sgm": {"p1": 0.1}, "colmap": {}}  # the caller's: untouched
    # a dataset without simulate stays a real capture (a $ref's own default is not used)
    assert "simulate" not in with_defaults("dataset", {})
    with pytest.raises(ConfigError, match=r"no config block 'depth\.window'.*depth\.sgm"):
        with_defaults("depth.window", {})
    with pytest.raises(ConfigError, match="no config block 'verfiy'"):
        stage_defaults("verfiy")


def _changed(value, sub: dict):
    """Another value the schema allows for ``sub`` (``value`` its default), or ``value``."""
    enum = sub.get("enum")
    if enum and len(enum) > 1:
        return enum[(enum.index(value) + 1) % len(enum)]
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):  # +-2: stays odd where the schema wants odd
        high = sub.get("maximum")
        return value + 2 if high is None or value + 2 <= high else value - 2
    if isinstance(value, float):
        if value == 0.0:
            return 0.5
        low = sub.get("exclusiveMinimum", sub.get("minimum"))
        return value * 0.75 if low is None or value * 0.75 > low else value * 1.25
    return value


def _changed_schema(schema: dict) -> dict:
    """``schema`` with every scalar default changed (objects: their properties')."""
    out = copy.deepcopy(schema)

    def walk(node):
        if isinstance(node, dict):
            for sub in node.get("properties", {}).values():
                if isinstance(sub, dict) and "default" in sub and not isinstance(
                        sub["default"], (dict, list)):
                    sub["default"] = _changed(sub["default"], sub)
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(out)

    def keep_order(node):
        """The cross-key rules of validate_config kept: wide_slots <= wider_slots, and
        the rvs renderer only with a binary (none here: the renderer stays dibr)."""
        if isinstance(node, dict):
            props = node.get("properties", {})
            if "wide_slots" in props and "wider_slots" in props:
                wide, wider = props["wide_slots"], props["wider_slots"]
                if wide["default"] > wider["default"]:
                    wide["default"] = wider["default"] - 1
            if "renderer" in props and "rvs_binary" in props:
                props["renderer"]["default"] = "dibr"
            for v in node.values():
                keep_order(v)

    keep_order(out)
    return out


def test_readers_of_an_empty_block_read_the_schema(tmp_path, monkeypatch):
    """Each config reader, given an empty block, builds what it builds from the whole
    block - under a schema whose defaults all differ from today's, which the readers take
    from the schema alone."""
    from plenocal.convert.shot import ConvertSettings  # noqa: PLC0415
    from plenocal.depth import colmap_options, planesweep_options  # noqa: PLC0415
    from plenocal.depth.sgm import sgm_options  # noqa: PLC0415
    from plenocal.verify.synthesis import dibr_options, synthesis_config  # noqa: PLC0415

    schema = _changed_schema(config_module.load_schema())
    path = tmp_path / "schema.yaml"
    path.write_text(yaml.safe_dump(schema))
    today = _validated()
    changed = {k: v for k, v in validate_config({"datasets": {"s": {}}}, path).items()
               if k in STAGES}
    readers = {
        "convert": ConvertSettings.from_config,
        "depth": planesweep_options,
        "depth.colmap": lambda d: colmap_options(d),
        "depth.sgm": lambda d: sgm_options(d["sgm"] if "sgm" in d else d),
        "verify": dibr_options,
    }
    for stage, read in readers.items():
        block = stage.split(".")[0]
        # the changed defaults change what each reader builds (else the test shows nothing)
        assert read(changed[block]) != read(today[block]), stage
    monkeypatch.setattr(config_module, "_package_schema", lambda: schema)
    for stage, read in readers.items():
        block = stage.split(".")[0]
        assert read({}) == read(changed[block]), stage
    assert sgm_options(None) == sgm_options(changed["depth"]["sgm"])
    assert synthesis_config({}) == {**changed["verify"], "depth": changed["depth"]}
    assert synthesis_config({"threads": 2, "depth": {"window": 3}})["depth"]["window"] == 3


def test_dataclass_defaults_are_the_schema_defaults():
    """The settings dataclasses built without arguments equal the ones the workflow's
    validated config builds (a script, the CLI and the rule alike)."""
    from plenocal.convert.shot import ConvertSettings  # noqa: PLC0415
    from plenocal.depth import colmap_options, planesweep_options  # noqa: PLC0415
    from plenocal.depth.colmap_mvs import ColmapOptions  # noqa: PLC0415
    from plenocal.depth.planesweep import PlaneSweepOptions  # noqa: PLC0415
    from plenocal.depth.sgm import SgmOptions, sgm_options  # noqa: PLC0415
    from plenocal.verify.dibr import DibrOptions  # noqa: PLC0415
    from plenocal.verify.synthesis import dibr_options  # noqa: PLC0415

    cfg = _validated()
    assert ConvertSettings() == ConvertSettings.from_config(cfg["convert"])
    assert PlaneSweepOptions() == planesweep_options(cfg["depth"])
    # a block's keys that are no field of the dataclass (sub-blocks, other stages') are left
    assert settings_from(PlaneSweepOptions, {"window": 9, "sgm": {}, "backend": "auto"}) == \
        PlaneSweepOptions(window=9)
    assert SgmOptions() == sgm_options(cfg["depth"]["sgm"])
    assert ColmapOptions() == colmap_options(cfg["depth"])
    assert DibrOptions() == dibr_options(cfg["verify"])
    # every field named after a key of its block is set from it
    for cls, block in ((PlaneSweepOptions, cfg["depth"]), (SgmOptions, cfg["depth"]["sgm"]),
                       (ColmapOptions, cfg["depth"]["colmap"]),
                       (DibrOptions, cfg["verify"]["dibr"])):
        shared = {f.name for f in fields(cls)} & set(block)
        assert shared and all(getattr(cls(), k) == block[k] for k in shared), cls


def _schema_keys_with_default() -> set[str]:
    keys: set[str] = set()

    def walk(node):
        if isinstance(node, dict):
            keys.update(k for k, v in node.get("properties", {}).items()
                        if isinstance(v, dict) and "default" in v)
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(config_module.load_schema())
    return keys


# fields and keyword arguments named like a schema key that are not that setting (owner,
# name): the optics model's neutral camera (optics_from_config passes both), a resolved
# MLA kind (the setting's default is auto), a result's optional section, COLMAP's camera
# model and its RANSAC threshold (not the triangulation filter), a figure's text scale,
# neighbour counts
NOT_SETTINGS = {("PlenopticOptics", "aperture_scale"), ("PlenopticOptics", "kind"),
                ("ViewLayout", "mla"), ("Conversion", "mla"), ("GroundTruthErrors", "scale"),
                ("estimate_patch_size", "mla"), ("make_layout", "mla"),
                ("extract_features", "model"), ("_verification_options", "max_error_px"),
                ("_label", "scale"), ("nearest_lenses", "k"), ("nearest_slots", "k")}
_LITERAL = (ast.Constant, ast.Tuple, ast.List, ast.UnaryOp)


def _written_defaults(tree: ast.AST, keys: set[str]) -> list[tuple[int, str]]:
    """(line, text) of every ``.get("<key>", default)``, and of every literal default of a
    dataclass field or keyword argument named ``<key>``, in ``tree``."""
    out = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get" and len(node.args) == 2
                and isinstance(node.args[0], ast.Constant) and node.args[0].value in keys):
            out.append((node.lineno, ast.unparse(node)))
        if isinstance(node, ast.ClassDef):
            for st in node.body:
                if (isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name)
                        and st.target.id in keys and isinstance(st.value, _LITERAL)
                        and (node.name, st.target.id) not in NOT_SETTINGS):
                    out.append((st.lineno, f"{node.name}.{ast.unparse(st)}"))
        if isinstance(node, ast.FunctionDef):
            a = node.args
            pos = a.posonlyargs + a.args
            pairs = list(zip(pos[len(pos) - len(a.defaults):], a.defaults, strict=True))
            pairs += [(x, d) for x, d in zip(a.kwonlyargs, a.kw_defaults, strict=True)
                      if d is not None]
            for arg, d in pairs:
                if (arg.arg in keys and isinstance(d, _LITERAL)
                        and not (isinstance(d, ast.Constant) and d.value is None)
                        and (node.name, arg.arg) not in NOT_SETTINGS):
                    out.append((node.lineno, f"{node.name}({arg.arg}={ast.unparse(d)})"))
    return out


def test_no_default_is_written_again_in_the_source():
    keys = _schema_keys_with_default()
    found = [f"{path.relative_to(ROOT)}:{line}: {text}"
             for base in ("plenocal", "scripts") for path in sorted((ROOT / base).rglob("*.py"))
             for line, text in _written_defaults(ast.parse(path.read_text()), keys)]
    assert not found, ("defaults written again - read them from the schema "
                       "(plenocal.config.with_defaults / stage_defaults):\n" + "\n".join(found))


def test_the_source_check_finds_each_kind():
    """The check above is not blind: each way of writing a default again is found."""
    src = """
class Options:
    window: int = 7
    mla: str = _D["mla"]
def f(cfg, seed: int = 0, *, max_num_features=8192, view_radius=None):
    return cfg.get("upsample", 1.5), cfg.get("unknown_key", 1)
"""
    found = [text for _, text in _written_defaults(ast.parse(src), _schema_keys_with_default())]
    assert found == ["Options.window: int = 7", "f(seed=0)", "f(max_num_features=8192)",
                     "cfg.get('upsample', 1.5)"]
