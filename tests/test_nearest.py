"""plenocal.convert.nearest: the k nearest points within a reach, against brute force."""

from __future__ import annotations

import numpy as np
import pytest

from plenocal.convert.nearest import nearest_within


def brute(points: np.ndarray, queries: np.ndarray, k: int, reach: float):
    """Every distance, sorted by (squared distance, index), cut at k and at the reach."""
    n = len(points)
    dist = np.full((len(queries), k), np.inf)
    idx = np.full((len(queries), k), n)
    for q, p in enumerate(queries):
        d2 = ((points - p) ** 2).sum(axis=1)
        order = np.lexsort((np.arange(n), d2))
        order = order[d2[order] < reach * reach][:k]
        dist[q, :len(order)] = np.sqrt(d2[order])
        idx[q, :len(order)] = order
    return dist, idx


def hex_lattice(nx: int, ny: int, turn: float = 0.1) -> np.ndarray:
    j, i = np.mgrid[0:ny, 0:nx]
    p = np.stack([(i + 0.5 * (j % 2)).ravel(), (j * np.sqrt(3) / 2).ravel()], 1)
    c, s = np.cos(turn), np.sin(turn)
    return p @ np.array([[c, -s], [s, c]]).T + 3.7


@pytest.mark.parametrize("seed", range(6))
def test_the_same_neighbours_as_brute_force_on_lattices_with_holes(seed):
    """Lens centres on a turned hexagonal lattice, some jittered, a share of them
    confident and a hole cut out: the same distances and indices as brute force (ties,
    which an unjittered lattice has in every ring, lower index first), for reaches that
    cut the search short and one that does not."""
    rng = np.random.default_rng(seed)
    P = hex_lattice(int(rng.integers(8, 60)), int(rng.integers(8, 50)))
    if seed % 2:
        P = P + rng.normal(0.0, 0.02, P.shape)
    ok = rng.random(len(P)) < (0.15, 0.5, 0.9)[seed % 3]
    cx, cy = P[rng.integers(len(P))]
    ok &= np.hypot(P[:, 0] - cx, P[:, 1] - cy) > (0.0, 6.0)[seed % 2]
    for reach in (2.5, 24.0, 1e6):
        k = int(min(12, ok.sum()))
        want = brute(P[ok], P[~ok], k, reach)
        got = nearest_within(P[ok], P[~ok], k, reach)
        np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got[1], want[1])


def test_hand_computed_case_reach_ties_and_too_few():
    """Points 0 (0,0), 1 (1,0), 2 (0,1), 3 (3,0), 4 (0,-1) and a query at (-1,0): distances
    1, 2, sqrt 2, 4, sqrt 2. The tie at sqrt 2 comes lower index first; a reach of exactly 2
    leaves point 1 out (strictly nearer), a reach of 1 leaves nothing; where fewer than k
    are near enough, the rest are inf and n = 5."""
    P = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [3.0, 0.0], [0.0, -1.0]])
    Q = np.array([[-1.0, 0.0]])
    r2 = np.sqrt(2.0)
    d, i = nearest_within(P, Q, 3, 2.0)
    np.testing.assert_allclose(d[0], [1.0, r2, r2])
    assert list(i[0]) == [0, 2, 4]
    d, i = nearest_within(P, Q, 4, 2.0)
    assert list(i[0]) == [0, 2, 4, 5] and np.isinf(d[0, 3])
    d, i = nearest_within(P, Q, 6, 10.0)
    np.testing.assert_allclose(d[0, :5], [1.0, r2, r2, 2.0, 4.0])
    assert list(i[0]) == [0, 2, 4, 1, 3, 5] and np.isinf(d[0, 5])
    d, i = nearest_within(P, Q, 2, 1.0)
    assert np.isinf(d).all() and (i == 5).all()


def test_points_on_a_line_and_empty_inputs():
    """Points with no area (all on one line) and empty point or query sets."""
    P = np.stack([np.linspace(0.0, 500.0, 2001), np.zeros(2001)], 1)
    Q = np.array([[250.1, 0.3], [-3.0, 0.0]])
    want = brute(P, Q, 4, 24.0)
    got = nearest_within(P, Q, 4, 24.0)
    np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got[1], want[1])
    d, i = nearest_within(np.zeros((0, 2)), Q, 3, 24.0)
    assert d.shape == (2, 3) and np.isinf(d).all() and (i == 0).all()
    d, i = nearest_within(P, np.zeros((0, 2)), 3, 24.0)
    assert d.shape == (0, 3)
    with pytest.raises(ValueError, match="k must be"):
        nearest_within(P, Q, 0, 24.0)


def test_small_chunks_give_the_same_neighbours(monkeypatch):
    """Queries split over many chunks of candidates (CHUNK_PAIRS lowered to 50, a chunk of
    one query where it has more): the same result as in one chunk."""
    import plenocal.convert.nearest as nearest  # noqa: PLC0415

    rng = np.random.default_rng(7)
    P = hex_lattice(40, 30) + rng.normal(0.0, 0.01, (1200, 2))
    ok = rng.random(len(P)) < 0.4
    whole = nearest_within(P[ok], P[~ok], 12, 24.0)
    monkeypatch.setattr(nearest, "CHUNK_PAIRS", 50)
    parts = nearest_within(P[ok], P[~ok], 12, 24.0)
    np.testing.assert_array_equal(parts[0], whole[0])
    np.testing.assert_array_equal(parts[1], whole[1])
    want = brute(P[ok], P[~ok], 12, 24.0)
    np.testing.assert_array_equal(parts[1], want[1])


def test_an_infinite_reach_with_more_neighbours_asked_than_points_ends():
    """k larger than the number of points and no reach: every point, then inf and n."""
    P = np.array([[0.0, 0.0], [5.0, 1.0], [2.0, 7.0]])
    d, i = nearest_within(P, np.array([[1.0, 1.0]]), 5, np.inf)
    assert list(i[0]) == [0, 1, 2, 3, 3] and np.isinf(d[0, 3:]).all()
    np.testing.assert_allclose(d[0, :3], [np.sqrt(2.0), 4.0, np.sqrt(37.0)])
