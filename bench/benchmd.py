"""BENCHMARKS.md is written by several bench scripts: each replaces its own sections
(``## <heading>`` up to the next ``## ``) and keeps the others; or, with
``keep_history``, puts its new text at the top of its section and keeps the earlier runs
and the hand-written paragraphs about them below it."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

TITLE = "# Benchmarks"
INTRO = ("Written by the scripts in `bench/` (each replaces its own sections). Timings on "
         "these machines are noisy: compare the figures of one run (ratios).")


class Lines(list):
    """Lines printed as they come and kept for a section."""

    def say(self, *parts: object) -> None:
        text = " ".join(str(p) for p in parts)
        print(text, flush=True)
        self.append(text)

    def head(self, *columns: str) -> None:
        """A Markdown table's header and its left-aligned separator row."""
        self.say("| " + " | ".join(columns) + " |")
        self.say("|" + "---|" * len(columns))


def binary_problem(path: Path) -> str | None:
    """Why ``path`` cannot be run as a program (a folder, no such file, not executable), or
    None: the benches that run another tool check it before any work."""
    if not path.is_file():
        return "a folder" if path.is_dir() else "no such file"
    if not os.access(path, os.X_OK):
        return "not executable"
    return None


def positive_int(text: str) -> int:
    """An ``argparse`` type: a whole number of at least 1 (rounds, repeats, draws, a stride):
    0 went on to fail far from the option (an empty list's median, a slice step of 0)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: give 1 or more")
    return value


def add_keep_history(parser) -> None:
    """``--keep-history`` on a bench script's ``argparse`` parser (its value goes to
    :func:`update_sections`' ``keep_history``)."""
    parser.add_argument("--keep-history", action="store_true",
                        help="put the new figures first in their section of --out and keep "
                             "the earlier runs and their notes below (default: replace the "
                             "section)")


def update_sections(path: str | Path, sections: dict[str, list[str]],
                    keep_history: bool = False) -> None:
    """Replace (or append) the ``## heading`` sections of ``path`` with ``sections``;
    with ``keep_history``, the new lines go first in the section and its earlier body
    follows them (the runs before, newest first, as the file keeps them by hand).

    Every other section is kept where it stands, two of one heading included: a file
    read into a dict by heading lost the first of two sections that a person had given
    the same heading (BENCHMARKS.md's hand-kept "Full run: earlier runs"). Where a
    heading of ``sections`` stands more than once, its first section is replaced and the
    others are kept. The text outside the replaced sections is written back byte for
    byte (a rewrite once joined the sections again with one blank line each, and so
    changed the blank lines of sections it did not own)."""
    path = Path(path)
    text = path.read_text() if path.exists() else ""
    if not text.strip():
        text = f"{TITLE}\n\n{INTRO}\n"
    # the raw text of each section, so that those not replaced are written back byte for
    # byte (their blank lines, two before a heading included): the preamble, then each
    # "heading\nbody" with the "\n## " that precedes it taken off
    preamble, *raw = text.split("\n## ")
    todo = dict(sections)
    for i, block in enumerate(raw):
        heading, _, body = block.partition("\n")
        if heading.strip() not in todo:
            continue
        core = body.rstrip("\n")
        trail = body[len(core):] or "\n"  # the blank lines before the next heading
        earlier = core.split("\n") if keep_history else []
        while earlier and not earlier[0].strip():
            earlier = earlier[1:]
        lines = ["", *todo.pop(heading.strip()), *([""] if earlier else []), *earlier]
        raw[i] = f"{heading.strip()}\n" + "\n".join(lines) + trail
    out = "\n## ".join([preamble, *raw])
    if todo:
        out = out.rstrip("\n") + "\n" + "".join(
            f"\n## {heading}\n" + "\n".join(["", *lines]) + "\n"
            for heading, lines in todo.items())
    path.write_text(out)
