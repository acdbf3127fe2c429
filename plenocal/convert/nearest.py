"""The k nearest of a set of 2-D points to each query point, within a reach.

:func:`plenocal.convert.patchsize.fill_unreliable` takes each unconfident lens's patch
size from its nearest confident lenses. SciPy's ``cKDTree`` did this, but importing
``scipy.spatial`` cost every conversion 0.55 s (``scipy.sparse`` and SciPy's array-API
layer come with it), a sixth of a 4-MP frame's whole conversion. The points here are
lens centres on a lattice, evenly spread, so a grid of buckets finds the same
neighbours in numpy: each pass looks at the 5 x 5 buckets of side ``r / 2`` around each
query, which hold every point nearer than ``r``, and a query is settled once ``k``
points are that near (or ``r`` has reached the reach); the others go on with ``2 r``.
The result is exact, and points at the same squared distance (a lens lattice has six in
every ring) come lower index first; ``cKDTree`` ordered those by the last bit of the lens
centres, so where ``k`` cuts such a ring the two may take different members of it.
"""

from __future__ import annotations

import math

import numpy as np

#: candidate pairs examined at a time (a chunk's arrays: about 100 MB)
CHUNK_PAIRS = 2_000_000


def nearest_within(points: np.ndarray, queries: np.ndarray, k: int, reach: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest ``points`` (n, 2) to each of ``queries`` (m, 2) nearer than
    ``reach``: distances (m, k) ascending and indices into ``points`` (m, k); where fewer
    than ``k`` are that near, the rest are ``inf`` and ``n`` (``cKDTree.query``'s
    convention with ``distance_upper_bound``)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    queries = np.asarray(queries, dtype=np.float64).reshape(-1, 2)
    n, m = len(points), len(queries)
    if k < 1:
        raise ValueError(f"k must be at least 1, got {k}")
    dist = np.full((m, k), np.inf)
    idx = np.full((m, k), n, dtype=np.intp)
    if n == 0 or m == 0 or not reach > 0:
        return dist, idx
    lo = np.minimum(points.min(axis=0), queries.min(axis=0))
    hi = np.maximum(points.max(axis=0), queries.max(axis=0))
    area = max(float(np.prod(hi - lo)), 1e-12)
    # a first radius that holds about 1.5 k points where the points are spread evenly (at
    # least 1/512 of the extent: points along a line have no area, and the buckets must
    # stay few)
    r = min(reach, max(math.sqrt(1.5 * k * area / (math.pi * n)),
                       float((hi - lo).max()) / 512.0, 1e-9))
    span = float(np.hypot(*(hi - lo)))  # beyond it every point is nearer than r
    todo = np.arange(m)
    while len(todo):
        last = r >= reach or r > span  # (an infinite reach with k > n ends here too)
        settled = _pass(points, queries, todo, k, r, lo, hi, last, dist, idx)
        todo = todo[~settled]
        r = min(reach, 2.0 * r)
    return dist, idx


def _pass(points: np.ndarray, queries: np.ndarray, todo: np.ndarray, k: int, radius: float,
          lo: np.ndarray, hi: np.ndarray, last: bool, dist: np.ndarray, idx: np.ndarray
          ) -> np.ndarray:
    """One pass at ``radius`` (the reach where ``last``): buckets of half its side, the 5 x
    5 around each query's; writes the queries ``todo`` that are settled (``k`` points
    nearer than ``radius``; all of them where ``last``) into ``dist`` / ``idx``, and
    returns which of ``todo`` are."""
    cell = radius / 2.0
    ncx, ncy = (int(v) + 1 for v in np.floor((hi - lo) / cell))
    pc = np.floor((points - lo) / cell).astype(np.intp)
    bucket = np.minimum(pc[:, 1], ncy - 1) * ncx + np.minimum(pc[:, 0], ncx - 1)
    order = np.argsort(bucket, kind="stable")
    px, py = points[order, 0], points[order, 1]  # in bucket order
    starts = np.concatenate([[0], np.cumsum(np.bincount(bucket, minlength=ncx * ncy))])
    q = queries[todo]
    qc = np.floor((q - lo) / cell).astype(np.intp)
    qx, qy = np.minimum(qc[:, 0], ncx - 1), np.minimum(qc[:, 1], ncy - 1)
    x0, x1 = np.maximum(qx - 2, 0), np.minimum(qx + 2, ncx - 1)
    # five runs of buckets per query (rows qy - 2 .. qy + 2), each contiguous in `order`
    rows = np.arange(-2, 3)[None, :] + qy[:, None]
    inside = (rows >= 0) & (rows < ncy)
    rows = np.clip(rows, 0, ncy - 1) * ncx
    first = np.where(inside, starts[rows + x0[:, None]], 0)
    lengths = np.where(inside, starts[rows + x1[:, None] + 1], 0) - first
    per_query = lengths.sum(axis=1)
    settled = np.zeros(len(todo), bool)
    bound2 = radius * radius
    a = 0
    while a < len(todo):  # chunks of queries with at most CHUNK_PAIRS candidates
        b = min(len(todo), a + max(1, int(np.searchsorted(np.cumsum(per_query[a:]),
                                                          CHUNK_PAIRS, "right"))))
        L = lengths[a:b].ravel()
        owner = np.repeat(np.repeat(np.arange(b - a), lengths.shape[1]), L)
        pos = np.arange(int(L.sum())) + np.repeat(first[a:b].ravel() - (np.cumsum(L) - L), L)
        dx = px.take(pos) - q[a:b, 0].take(owner)
        dy = py.take(pos) - q[a:b, 1].take(owner)
        d2 = dx * dx + dy * dy
        keep = np.flatnonzero(d2 < bound2)  # strictly nearer, as cKDTree
        owner, pos, d2 = owner[keep], pos[keep], d2[keep]
        point = order[pos]
        s = np.lexsort((point, d2, owner))  # by query, distance, then index
        owner, point, d2 = owner[s], point[s], d2[s]
        found = np.bincount(owner, minlength=b - a)
        done = np.full(b - a, True) if last else found >= k
        settled[a:b] = done
        rank = np.arange(len(owner)) - np.repeat(np.cumsum(found) - found, found)
        w = np.flatnonzero((rank < k) & done[owner])
        out_rows = todo[a + owner[w]]
        dist[out_rows, rank[w]] = np.sqrt(d2[w])
        idx[out_rows, rank[w]] = point[w]
        a = b
    return settled
