"""The README's shape: it opens with the two commands (the main job, the tests; `.ci/run`
runs the second verbatim), then a list of contents that names every section in order."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEXT = (ROOT / "README.md").read_text()


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_the_readme_starts_with_the_two_commands_and_ci_runs_the_second():
    blocks = re.findall(r"```bash\n(.*?)```", TEXT, flags=re.S)
    first_heading = TEXT.index("\n## ")
    assert TEXT.index("```bash") < first_heading
    opening = [b.strip() for b in blocks if TEXT.index(b) < first_heading]
    assert len(opening) == 2 and all("\n" not in b for b in opening), opening
    assert "snakemake -j2" in opening[0]
    assert opening[1] in (ROOT / ".ci" / "run").read_text()


def test_the_contents_list_names_every_section_in_order():
    headings = re.findall(r"^## (.+)$", TEXT, flags=re.M)
    contents = TEXT[TEXT.index("Contents:"):TEXT.index("\n## ")]
    listed = re.findall(r"^- \[([^\]]+)\]\(#([^)]+)\)$", contents, flags=re.M)
    assert [h for h, _ in listed] == headings
    assert [a for _, a in listed] == [_anchor(h) for h in headings]


def test_every_section_the_code_points_to_is_in_the_readme():
    """The report, the errors and the config's descriptions send the user to a README
    section by its name (README, 'MLA kinds'); a renamed section must not strand them."""
    pattern = re.compile(r"""README,? ['"]([^'"]+)['"]""")
    files = [*ROOT.glob("plenocal/**/*.py"), *ROOT.glob("scripts/*.py"),
             *ROOT.glob("rules/*.smk"), ROOT / "config.schema.yaml"]
    refs = {(m.group(1).strip(), f.relative_to(ROOT).as_posix())
            for f in files for m in pattern.finditer(f.read_text())}
    assert len(refs) >= 5  # the pattern finds the pointers
    missing = sorted((name, where) for name, where in refs if name not in TEXT)
    assert not missing, missing
