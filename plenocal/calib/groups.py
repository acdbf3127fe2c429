"""Groups of things that links tie together (union-find): the shots that matched pairs
(rule view_matches, :func:`plenocal.calib.reg_a.viewdb.nearest_shots`) or shared 3-D points
(rule refine, :func:`plenocal.calib.shot_ties.shot_groups`) tie into one group."""

from __future__ import annotations

from collections.abc import Iterable


class Groups:
    """Each item alone at first; :meth:`join` ties two items' groups into one."""

    def __init__(self, items: Iterable[str]) -> None:
        self._parent = {s: s for s in items}

    def root(self, s: str) -> str:
        """The representative of ``s``'s group."""
        parent = self._parent
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    def join(self, a: str, b: str) -> bool:
        """Tie ``a``'s and ``b``'s groups; whether they were apart."""
        ra, rb = self.root(a), self.root(b)
        if ra == rb:
            return False
        self._parent[ra] = rb
        return True

    def groups(self) -> list[list[str]]:
        """Every group, sorted, the groups by their first item."""
        out: dict[str, list[str]] = {}
        for s in sorted(self._parent):
            out.setdefault(self.root(s), []).append(s)
        return sorted(out.values())
