"""Analytic test shapes: closed, outward, vertices on the surface, exact curvatures."""

import numpy as np
import pytest

from data_synth.shapes import (
    box_mesh,
    is_closed_manifold,
    project_to_torus,
    signed_volume,
    sphere_mesh,
    torus_curvatures,
    torus_mesh,
    torus_sdf,
)


@pytest.mark.parametrize("R, a, target", [(1.0, 0.45, 3000), (2.0, 0.5, 5000)])
def test_torus_mesh_closed_oriented_on_surface(R, a, target):
    v, f = torus_mesh(R, a, target_vertices=target)
    assert v.dtype == np.float64 and f.dtype == np.int64
    assert 0.8 * target < len(v) < 1.2 * target
    assert is_closed_manifold(f)
    assert len(v) - 3 * len(f) // 2 + len(f) == 0  # Euler characteristic of a torus
    exact = 2 * np.pi**2 * R * a * a
    assert 0.98 * exact < signed_volume(v, f) < exact  # positive: outward; inscribed: a bit less
    assert np.abs(torus_sdf(v, R, a)).max() < 1e-12
    # outward: each face normal points away from the tube's core circle
    t = v[f]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    c = t.mean(axis=1)
    core = np.column_stack([c[:, :2] * (R / np.hypot(c[:, 0], c[:, 1]))[:, None], np.zeros(len(c))])
    assert np.all(np.einsum("ij,ij->i", n, c - core) > 0)


def test_torus_curvatures_at_the_equators_and_top():
    R, a = 1.0, 0.45
    pts = np.array([[R + a, 0, 0], [0, -(R - a), 0], [R, 0, a], [0, R, -a]])
    H, K2 = torus_curvatures(pts, R, a)
    k1 = 1 / a
    k2 = np.array([1 / (R + a), -1 / (R - a), 0.0, 0.0])  # outer equator: kappa2 = 1/(R + a)
    np.testing.assert_allclose(H, (k1 + k2) / 2, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(K2, (k1 - k2) ** 2, rtol=1e-12)


def test_torus_gauss_bonnet_and_projection():
    R, a = 1.0, 0.45
    v, f = torus_mesh(R, a, target_vertices=20000)
    c = project_to_torus(v[f].mean(axis=1), R, a)
    H, K2 = torus_curvatures(c, R, a)
    K = H * H - K2 / 4  # kappa1 kappa2
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    assert abs((K * area).sum()) < 1e-2  # ∫ K dA = 2 pi chi = 0 for a torus
    rng = np.random.default_rng(0)
    p = v[rng.choice(len(v), 50)]
    normal = p - np.column_stack([p[:, :2] * (R / np.hypot(p[:, 0], p[:, 1]))[:, None], np.zeros(len(p))])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    off = p + rng.uniform(-0.1, 0.1, (len(p), 1)) * normal
    np.testing.assert_allclose(project_to_torus(off, R, a), p, atol=1e-12)


def test_sphere_and_box():
    v, f = sphere_mesh(3)
    assert len(v) == 642 and is_closed_manifold(f)
    assert np.abs(np.linalg.norm(v, axis=1) - 1).max() < 1e-15
    assert 0.98 * 4 * np.pi / 3 < signed_volume(v, f) < 4 * np.pi / 3
    v, f = box_mesh([2.0, 3.0, 4.0])
    assert is_closed_manifold(f)
    assert signed_volume(v, f) == pytest.approx(24.0)
    np.testing.assert_allclose(v.max(axis=0), [1.0, 1.5, 2.0])
