"""The conda environment of the rules pins exactly what pyproject.toml pins."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _pins(lines: list[str]) -> dict[str, str]:
    out = {}
    for line in lines:
        name, _, version = line.partition("==")
        assert version, f"not pinned exactly: {line!r}"
        out[name.strip().lower().replace("_", "-")] = version.strip()
    return out


def test_env_matches_pyproject():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    env = yaml.safe_load((ROOT / "envs" / "plenocal.yaml").read_text())
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict))
    assert _pins(pip) == _pins(project["dependencies"])
    python = next(d for d in env["dependencies"] if isinstance(d, str)
                  and d.startswith("python="))
    assert python == "python=" + project["requires-python"].removeprefix(">=")


def test_every_rule_uses_the_env():
    for smk in sorted((ROOT / "rules").glob("*.smk")):
        text = smk.read_text()
        assert text.count("script:") == text.count('"../envs/plenocal.yaml"'), smk.name


def test_executor_plugins_are_extras():
    """An installed executor plugin is imported by every Snakemake start (the SLURM one
    brings pandas and runs `scontrol`): a workstation's install must not carry one."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    base = _pins(project["dependencies"])
    assert not [n for n in base if n.startswith("snakemake-executor-plugin-")]
    assert "snakemake-executor-plugin-slurm" in _pins(project["optional-dependencies"]["slurm"])
    assert "plenocal[slurm]" in project["optional-dependencies"]["test"]
