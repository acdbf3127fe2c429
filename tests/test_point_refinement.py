"""Per-point refinement with fixed cameras (plenocal.verify.point_refinement): hand-made
cases and an independent dense solver; the comparison with COLMAP's own bundle adjustment
is in tests/test_reprojection.py."""

import numpy as np

from plenocal.camera import PinholeCamera, pose
from plenocal.verify.point_refinement import projection_matrices, refine_points

K = np.array([[500.0, 0.0, 320.0], [0.0, 480.0, 240.0], [0.0, 0.0, 1.0]])


def _rot_y(rad):
    c, s = np.cos(rad), np.sin(rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _cameras(n=5):
    """A row of cameras 5 cm apart, 1 m from the origin, each turned towards it."""
    out = []
    for i in range(n):
        x = 0.05 * (i - n // 2)
        out.append(PinholeCamera(K, pose(_rot_y(-np.arctan2(x, 1.0)),
                                         np.array([x, 0.02 * i, -1.0])), 640, 480))
    return out


def _problem(points, cams, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    point, image, uv = [], [], []
    for p, X in enumerate(points):
        for i, c in enumerate(cams):
            if (p + i) % 4 == 3:  # not every point in every image
                continue
            xy, _ = c.project(X)
            point.append(p)
            image.append(i)
            uv.append(xy + noise * rng.standard_normal(2))
    P = np.stack([projection_matrices(c.K, c.world_to_cam) for c in cams])
    return np.array(point), np.array(image), P, np.array(uv)


def _cost(X, point, image, P, uv):
    Xh = np.concatenate([X[point], np.ones((len(point), 1))], axis=1)
    p = np.einsum("nij,nj->ni", P[image], Xh)
    r = p[:, :2] / p[:, 2:] - uv
    return np.bincount(point, weights=(r * r).sum(axis=1), minlength=len(X))


def test_projection_matrix_projects_as_the_camera():
    c = _cameras()[1]
    X = np.array([0.1, -0.05, 0.2])
    p = projection_matrices(c.K, c.world_to_cam) @ np.append(X, 1.0)
    np.testing.assert_allclose(p[:2] / p[2], c.project(X)[0], rtol=0, atol=1e-9)


def test_exact_observations_give_back_the_points():
    """Noise-free observations: any start near the point converges onto it."""
    rng = np.random.default_rng(1)
    truth = rng.uniform(-0.1, 0.1, (40, 3))
    point, image, P, uv = _problem(truth, _cameras())
    start = truth + rng.normal(0, 0.01, truth.shape)
    X, it = refine_points(start, point, image, P, uv)
    np.testing.assert_allclose(X, truth, rtol=0, atol=1e-9)
    assert 1 <= it < 20
    assert _cost(X, point, image, P, uv).max() < 1e-12


def test_noisy_observations_reach_the_least_squares_point():
    """With pixel noise, every point ends at the minimum of its own cost: the same as an
    independent dense Gauss-Newton with a numerical Jacobian, point by point, and below the
    cost of the true point and of the start."""
    rng = np.random.default_rng(2)
    truth = rng.uniform(-0.1, 0.1, (25, 3))
    point, image, P, uv = _problem(truth, _cameras(), noise=0.5, seed=3)
    start = truth + rng.normal(0, 0.005, truth.shape)
    X, _ = refine_points(start, point, image, P, uv)
    got = _cost(X, point, image, P, uv)
    assert (got <= _cost(truth, point, image, P, uv) + 1e-12).all()
    assert (got <= _cost(start, point, image, P, uv) + 1e-12).all()
    for p in range(len(truth)):
        sel = point == p
        x = start[p].copy()

        def res(x, sel=sel):
            q = np.einsum("nij,j->ni", P[image[sel]], np.append(x, 1.0))
            return (q[:, :2] / q[:, 2:] - uv[sel]).ravel()

        for _ in range(30):
            J = np.stack([(res(x + e) - res(x - e)) / 2e-7 for e in np.eye(3) * 1e-7], axis=1)
            x = x - np.linalg.lstsq(J, res(x), rcond=None)[0]
        np.testing.assert_allclose(X[p], x, rtol=0, atol=1e-8)


def test_a_point_without_observations_stays_and_nothing_to_do():
    cams = _cameras()
    truth = np.array([[0.0, 0.0, 0.0], [0.05, 0.02, 0.01]])
    point, image, P, uv = _problem(truth[:1], cams)
    start = truth + 0.003
    X, _ = refine_points(start, point, image, P, uv)
    np.testing.assert_allclose(X[0], truth[0], atol=1e-9)
    np.testing.assert_array_equal(X[1], start[1])
    X0, it = refine_points(start, point[:0], image[:0], P, uv[:0])
    assert it == 0
    np.testing.assert_array_equal(X0, start)


def test_the_points_are_not_modified_in_place():
    truth = np.array([[0.0, 0.01, 0.02]])
    point, image, P, uv = _problem(truth, _cameras())
    start = truth + 0.01
    keep = start.copy()
    refine_points(start, point, image, P, uv)
    np.testing.assert_array_equal(start, keep)
