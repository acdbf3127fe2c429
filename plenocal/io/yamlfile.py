"""YAML files read strictly: a key given twice in one mapping is refused, naming the key and
both lines, where PyYAML (and Snakemake's ``configfile:``) would keep the last one without
a word. Used for ``camera.yaml`` (:mod:`plenocal.calib.reg_b.datasheet`) and the workflow's
config files (``rules/common.smk``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

#: the tag of YAML's merge key ``<<``
MERGE_TAG = "tag:yaml.org,2002:merge"


class DuplicateKeyError(ValueError):
    """A key given twice in one mapping of a YAML file; the message names the file, the
    key's dotted path and both lines."""


def _dotted(path: tuple) -> str:
    return ".".join(str(p) for p in path)


def _check_duplicates(node: yaml.Node, path: tuple, source: str | Path) -> None:
    if isinstance(node, yaml.MappingNode):
        seen: dict[tuple[str, str], int] = {}
        for key_node, value_node in node.value:
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            # merge keys (<<: *anchor), which YAML merges each of, and keys of other types
            # (1 and '1') are not one key given twice
            ident = (key_node.tag, key)
            if key is not None and key_node.tag != MERGE_TAG:
                line = key_node.start_mark.line + 1
                if ident in seen:
                    raise DuplicateKeyError(
                        f"{source}: {_dotted((*path, key))}: given twice (lines {seen[ident]} "
                        f"and {line}); YAML would keep the last one without a word: delete "
                        "one of them")
                seen[ident] = line
            _check_duplicates(value_node, (*path, key), source)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _check_duplicates(item, (*path, i), source)


def load_yaml_unique(text: str, source: str | Path = "<string>") -> Any:
    """YAML ``text`` parsed safely, refusing a key given twice in one mapping:
    :class:`DuplicateKeyError` naming ``source``, the key and both lines."""
    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_duplicates(node, (), source)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def check_unique_keys(paths: list[str | Path]) -> None:
    """Every YAML (or JSON) file of ``paths`` that exists parsed with
    :func:`load_yaml_unique`: :class:`DuplicateKeyError` for the first key given twice.
    A file that does not parse is left to its reader, whose message it keeps."""
    for p in paths:
        path = Path(p)
        if not path.is_file():
            continue
        try:
            load_yaml_unique(path.read_text(encoding="utf-8"), path)
        except (yaml.YAMLError, UnicodeDecodeError):
            continue
