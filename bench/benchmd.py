"""BENCHMARKS.md is written by several bench scripts: each replaces its own sections
(``## <heading>`` up to the next ``## ``) and keeps the others."""

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


def update_sections(path: str | Path, sections: dict[str, list[str]]) -> None:
    """Replace (or append) the ``## heading`` sections of ``path`` with ``sections``."""
    path = Path(path)
    old = path.read_text().split("\n## ") if path.exists() else [TITLE]
    kept = {}
    for block in old[1:]:
        heading, _, body = block.partition("\n")
        kept[heading.strip()] = body.rstrip("\n").split("\n")
    for heading, lines in sections.items():
        kept[heading] = ["", *lines]
    out = [TITLE, "", INTRO]
    for heading, body in kept.items():
        out += ["", f"## {heading}", *body]
    path.write_text("\n".join(out).rstrip("\n") + "\n")
