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


def test_with_the_history_kept_the_new_run_goes_first_and_the_earlier_stay(tmp_path):
    # bench_real --tlct and bench_workflow rewrote their whole section, and every session
    # put the runs before, and what it wrote about them, back by hand
    md = tmp_path / "BENCHMARKS.md"
    md.write_text("# Benchmarks\n\n## Speed\n\n**At abc** notes\n\n| t |\n|---|\n| 1 |\n\n"
                  "### Earlier\n\nolder\n\n## B\n\nb\n")
    benchmd.update_sections(md, {"Speed": ["| t |", "|---|", "| 2 |"]}, keep_history=True)
    text = md.read_text()
    assert _headings(text) == ["Speed", "B"]
    assert text.index("| 2 |") < text.index("**At abc** notes") < text.index("| 1 |")
    assert "### Earlier\n\nolder\n\n## B" in text
    benchmd.update_sections(md, {"Speed": ["| 3 |"]})
    assert "| 3 |" in md.read_text() and "| 2 |" not in md.read_text()


def test_a_rewrite_leaves_the_rest_of_the_file_byte_for_byte(tmp_path):
    # the sections were joined again with one blank line each: a rewrite of one section
    # took a blank line out of another (two blank lines before a heading), and the preamble
    # was written anew
    md = tmp_path / "BENCHMARKS.md"
    before = ("# Benchmarks\n\nhand-written intro\n\n## A\n\nold a\n\n\n## B\n\nb\n\n\n\n"
              "## C\n\nc line\n  \n## D\n\nd\n")
    md.write_text(before)
    benchmd.update_sections(md, {})
    assert md.read_text() == before
    benchmd.update_sections(md, {"C": ["new c"]})
    assert md.read_text() == before.replace("c line\n  \n", "new c\n\n")
    benchmd.update_sections(md, {"D": ["new d"], "E": ["e"]})
    assert md.read_text() == (before.replace("c line\n  \n", "new c\n\n")
                              .replace("## D\n\nd\n", "## D\n\nnew d\n\n## E\n\ne\n"))
