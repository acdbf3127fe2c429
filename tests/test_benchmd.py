"""bench/benchmd.py: each bench script replaces its own sections of BENCHMARKS.md and
keeps every other one, where it stands, two sections of one heading included."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import benchmd  # noqa: E402


def _headings(text: str) -> list[str]:
    return [line[3:] for line in text.splitlines() if line.startswith("## ")]


def test_a_section_is_replaced_in_place_and_the_others_kept(tmp_path):
    md = tmp_path / "BENCHMARKS.md"
    md.write_text("# Benchmarks\n\n## A\n\nold a\n\n## B\n\nb stays\n")
    benchmd.update_sections(md, {"A": ["new a"], "C": ["c"]})
    text = md.read_text()
    assert _headings(text) == ["A", "B", "C"]
    assert "new a" in text and "old a" not in text and "b stays" in text


def test_two_sections_of_one_heading_are_both_kept(tmp_path):
    # a dict by heading kept the second body only: the first was lost on every write
    md = tmp_path / "BENCHMARKS.md"
    md.write_text("# Benchmarks\n\n## Full run\n\nnew\n\n## Earlier\n\nfirst kept\n\n"
                  "## Mid\n\nm\n\n## Earlier\n\nsecond kept\n")
    benchmd.update_sections(md, {"Full run": ["newer"]})
    text = md.read_text()
    assert _headings(text) == ["Full run", "Earlier", "Mid", "Earlier"]
    assert "first kept" in text and "second kept" in text and "newer" in text
    assert text.index("first kept") < text.index("m\n") < text.index("second kept")
