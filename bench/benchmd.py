"""BENCHMARKS.md is written by several bench scripts: each replaces its own sections
(``## <heading>`` up to the next ``## ``) and keeps the others; or, with
``keep_history``, puts its new text at the top of its section and keeps the earlier runs
and the hand-written paragraphs about them below it."""

from __future__ import annotations

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
    others are kept."""
    path = Path(path)
    old = path.read_text().split("\n## ") if path.exists() else [TITLE]
    blocks: list[tuple[str, list[str]]] = []
    for block in old[1:]:
        heading, _, body = block.partition("\n")
        blocks.append((heading.strip(), body.rstrip("\n").split("\n")))
    todo = dict(sections)
    for i, (heading, body) in enumerate(blocks):
        if heading in todo:
            earlier = body if keep_history else []
            while earlier and not earlier[0].strip():
                earlier = earlier[1:]
            blocks[i] = (heading, ["", *todo.pop(heading), *([""] if earlier else []),
                                   *earlier])
    blocks += [(heading, ["", *lines]) for heading, lines in todo.items()]
    out = [TITLE, "", INTRO]
    for heading, body in blocks:
        out += ["", f"## {heading}", *body]
    path.write_text("\n".join(out).rstrip("\n") + "\n")
