"""The distance band of D2_r (descriptors.closest) and the bounded closest-triangle queries
(descriptors.tree) against brute force over every triangle."""

import numpy as np
import pytest
import trimesh

from reassemble.descriptors.closest import MeshDistance
from reassemble.descriptors.voxelize import make_grid


def brute_force_distance(points: np.ndarray, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n,) distance from each point to the nearest of all triangles: the minimum over the
    triangle's plane (where the foot falls inside) and its three edges, vectorized over
    triangles, in float64."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = np.empty(len(points))
    for s in range(0, len(points), 256):
        p = points[s:s + 256, None, :]  # (k, 1, 3) against (f, 3)
        h = np.einsum("kfj,fj->kf", p - a, n)
        foot = p - h[..., None] * n
        # inside: the foot is on the inner side of all three edges
        inside = np.ones(h.shape, bool)
        for u, v in ((a, b), (b, c), (c, a)):
            inside &= np.einsum("kfj,fj->kf", np.cross(v - u, foot - u), n) >= 0
        best = np.where(inside, np.abs(h), np.inf)
        for u, v in ((a, b), (b, c), (c, a)):
            e = v - u
            t = np.clip(np.einsum("kfj,fj->kf", p - u, e) / np.einsum("fj,fj->f", e, e), 0.0, 1.0)
            best = np.minimum(best, np.linalg.norm(p - (u + t[..., None] * e), axis=2))
        out[s:s + 256] = best.min(axis=1)
    return out


def shapes():
    box = trimesh.creation.box(extents=(1.0, 0.6, 0.8))  # 12 large triangles, sharp edges
    V, F = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, 0.3)
    yield "box", V, F
    sphere = trimesh.creation.icosphere(subdivisions=2)
    yield "sphere", sphere.vertices, sphere.faces
    torus = trimesh.creation.torus(major_radius=0.5, minor_radius=0.18, major_sections=32, minor_sections=12)
    yield "torus", torus.vertices, torus.faces  # a concave inner side and a medial axis in the hole
    # a U: two thin parallel walls 0.12 apart, concave pockets at the bottom
    u = trimesh.boolean.union([trimesh.creation.box(extents=(0.05, 0.5, 0.5), transform=trimesh.transformations.translation_matrix((x, 0, 0)))
                                  for x in (-0.085, 0.085)] +
                              [trimesh.creation.box(extents=(0.22, 0.5, 0.05), transform=trimesh.transformations.translation_matrix((0, 0, -0.25)))],
                              engine="manifold")
    yield "walls", u.vertices, u.faces


# the brute force is the cost: the smooth shapes (10-13 s each) run with the slow tests
@pytest.mark.parametrize("name,V,F", [pytest.param(*s, marks=pytest.mark.slow) if s[0] in ("sphere", "torus") else s
                                      for s in shapes()], ids=[s[0] for s in shapes()])
def test_band_equals_brute_force(name, V, F):
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    h = 0.05
    exact, limit = 0.15, 0.25
    grid = make_grid(V.min(axis=0), V.max(axis=0), h=h, margin=limit + 2 * h)
    where, dist2 = MeshDistance(V, F).band(grid.origin, h, grid.shape, limit, exact)
    assert len(np.unique(where)) == len(where)
    def at(idx):
        return grid.origin + h * np.column_stack(np.unravel_index(idx, grid.shape))

    # the voxels not found are all beyond the limit (a sample of them)
    rest = np.setdiff1d(np.arange(grid.size), where)
    rest = np.random.default_rng(0).choice(rest, min(len(rest), 3000), replace=False)
    assert brute_force_distance(at(rest), V, F).min() > limit
    got, truth = np.sqrt(dist2), brute_force_distance(at(where), V, F)
    err = got - truth
    assert err.min() > -1e-9 * h  # a distance to some triangle: never below the true one
    zone = truth <= exact
    assert err[zone].max() < 1e-9 * h


@pytest.mark.parametrize("name,V,F", [s for s in shapes() if s[0] in ("box", "walls")], ids=["box", "walls"])
def test_tree_query_equals_brute_force(name, V, F):
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    distance = MeshDistance(V, F)
    lo, hi = V.min(axis=0) - 0.3, V.max(axis=0) + 0.3
    points = np.random.default_rng(1).uniform(lo, hi, (4000, 3))
    truth = brute_force_distance(points, V, F)
    tri, dist2 = distance.tree.closest(points, np.inf)
    assert np.abs(np.sqrt(dist2) - truth).max() < 1e-12
    assert np.all(tri >= 0)
    # the triangle it names is at that distance
    named = [brute_force_distance(points[s:s + 1], V, F[tri[s]:tri[s] + 1])[0] for s in range(0, 4000, 20)]
    assert np.abs(np.array(named) - truth[::20]).max() < 1e-12
    # bounded: the distance where it is nearer than the bound, else the bound and no triangle
    bound = 0.1
    got = distance.nearest(points, bound)
    near = truth < bound
    assert np.abs(got[near] - truth[near]).max() < 1e-12
    assert np.all(got[~near] == bound)
    tri3, _ = distance.tree.closest(points, bound**2)
    assert np.all((tri3 >= 0) == near)
