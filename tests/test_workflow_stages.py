"""Every stage name of the README's stage table, and every name of its table of a stage's
jobs of one kind (view_features, ...), works in `--until` and `--forcerun` (issue 35): dry
runs on a copy of the complete tiny run.

The README is the reference: its table names each stage (in brackets) and the stage's
rules (`<k>`: a job's number). For each stage, `--forceall --until <stage>` plans every job
of the stage's rules and nothing that is not the stage or before it; `--forcerun <stage>`
on the complete run plans every job of the stage and of every rule after it, and nothing
before it. "Before" and "after" come from Snakemake's own rule graph of the default run."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import ROOT, clone, snakemake, snakemake_each

pytestmark = pytest.mark.workflow

#: the stages issue 35 asks for by name
ASKED = {"convert", "reg_a", "reg_b", "depth", "scale", "merge", "refine", "verify", "report"}


#: the README's tables of typed names: the stages, and a stage's jobs of one kind
TABLES = ("| stage (its name in `--until`, `--forcerun`) | rules |",
          "| jobs (their name in `--until`, `--forcerun`) | rules |")


def readme_stages() -> tuple[dict[str, list[str]], list[str]]:
    """({typed name: [rule-name regex]}, [every rule regex of the tables])."""
    text = (ROOT / "README.md").read_text()
    rows = []
    for table in TABLES:
        start = text.index(table)
        for line in text[start:].splitlines()[2:]:
            if not line.startswith("|"):
                break
            rows.append(line.split("|")[1:3])
    stages, every = {}, []
    for stage_col, rules_col in rows:
        rules = []
        for tok in re.findall(r"`([^`]+)`", rules_col):
            tok = re.sub(r"(\d)\.\.(\d)", r"[\1-\2]", tok)
            rules.append(tok.replace("<k>", r"\d+").replace("<i>", r"\d+"))
        every += rules
        names = re.findall(r"`(\w+)`", stage_col)
        if len(names) == 1:
            stages[names[0]] = rules
        else:  # "scale / merge": each the rule of its own name
            for name in names:
                assert name in rules, (name, rules)
                stages[name] = [re.escape(name)]
    return stages, every


def scheduled(proc) -> set[str]:
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    return set(re.findall(r"^(?:local)?rule (\w+):", out, flags=re.M)) - {"all"}


def rule_graph(work: Path) -> dict[str, set[str]]:
    """{rule: the rules that read its outputs} of the default run."""
    proc = snakemake(work, "-n", "--forceall", "--rulegraph", "--quiet", "all")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    label = dict(re.findall(r'^\s*(\d+)\[label = "(\w+)"', proc.stdout, flags=re.M))
    graph = {name: set() for name in label.values()}
    for a, b in re.findall(r"^\s*(\d+) -> (\d+)", proc.stdout, flags=re.M):
        graph[label[a]].add(label[b])
    graph.pop("all", None)
    for after in graph.values():
        after.discard("all")
    return graph


def closure(graph: dict[str, set[str]], start: set[str]) -> set[str]:
    seen, todo = set(), list(start)
    while todo:
        for nxt in graph.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


@pytest.fixture(scope="module")
def work(tiny_complete_run: Path, tmp_path_factory) -> Path:
    return clone(tiny_complete_run, tmp_path_factory.mktemp("stages") / "w")


def test_readme_names_every_rule(work: Path):
    """Each rule belongs to a row of the table, each name of the table to a rule."""
    stages, every = readme_stages()
    assert ASKED <= set(stages), sorted(ASKED - set(stages))
    rules = {ln.split()[0] for ln in snakemake(work, "--list-rules").stdout.splitlines()
             if ln.strip()}
    for pattern in every:
        assert any(re.fullmatch(pattern, r) for r in rules), pattern
    unlisted = {r for r in rules - {"all"} - set(stages)
                if not any(re.fullmatch(p, r) for p in every)}
    assert not unlisted, sorted(unlisted)


def test_until_and_forcerun_take_every_stage(work: Path):
    stages, _ = readme_stages()
    graph = rule_graph(work)
    reversed_graph: dict[str, set[str]] = {r: set() for r in graph}
    for rule, after in graph.items():
        for b in after:
            reversed_graph[b].add(rule)
    # every dry run first, two at a time (one core each)
    calls = [args for stage in stages for args in (("-n", "--forceall", "--until", stage),
                                                   ("-n", "--forcerun", stage))]
    procs = iter(snakemake_each(work, calls))
    for stage, patterns in stages.items():
        until, forcerun = next(procs), next(procs)
        members = {r for r in graph if any(re.fullmatch(p, r) for p in patterns)}
        assert members, stage
        after = closure(graph, members) - members
        before = closure(reversed_graph, members) - members

        # the stage's own rule, where it is not one of its rules, runs nothing
        alias = {stage} - members
        planned = scheduled(until) - alias
        assert members <= planned, (stage, sorted(members - planned))
        assert planned <= members | before, (stage, sorted(planned - members - before))

        planned = scheduled(forcerun) - alias
        assert members | after <= planned, (stage, sorted((members | after) - planned))
        assert planned <= members | after, (stage, sorted(planned - members - after))
    # the complete run is left as it was
    proc = snakemake(work, "-n")
    assert "Nothing to be done" in proc.stdout + proc.stderr
