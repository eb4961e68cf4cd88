"""Surface mates: a smooth curved break labelled original on both sides is found by its two sides' fit."""

import numpy as np
import pytest

from reassemble.geometry import face_areas, face_normals, random_rotation
from reassemble.surface_mates import relabel_surface_mates, smooth_regions

from .conftest import labelled

CUT_CENTRE, CUT_RADIUS = np.array([0.2, 0.1, 3.1]), 3.0  # a gently curved cut: a sphere of radius 3


def _halves(rng):
    """A dented sphere cut by a large sphere into two, each moved to its own random pose:
    [(vertices, faces, (f,) bool true cut faces)] per piece."""
    import manifold3d as m3d

    ball = m3d.Manifold.sphere(1.0, 96) - m3d.Manifold.cube([0.6, 0.6, 0.6], True).translate([0.9, 0.0, -0.3])
    cutter = m3d.Manifold.sphere(CUT_RADIUS, 256).translate(CUT_CENTRE)
    out = []
    for part in (ball ^ cutter, ball - cutter):
        mesh = part.to_mesh()
        v, f = np.asarray(mesh.vert_properties)[:, :3].astype(float), np.asarray(mesh.tri_verts).astype(np.int64)
        # the cut's faces: on the cutting sphere (a polyhedron within 1e-3 of it), facing along its radius
        centres = v[f].mean(axis=1) - CUT_CENTRE
        radial = centres / np.linalg.norm(centres, axis=1, keepdims=True)
        cut = (np.abs(np.linalg.norm(centres, axis=1) - CUT_RADIUS) < 1e-3) \
            & (np.abs(np.einsum("ij,ij->i", face_normals(v, f), radial)) > 0.999)
        R = random_rotation(rng)
        out.append((v @ R.T + rng.normal(size=3), f, cut))
    return out


@pytest.fixture(scope="module")
def halves():
    return _halves(np.random.default_rng(5))


def test_the_cut_is_one_smooth_region(halves):
    for v, f, cut in halves:
        regions = smooth_regions(v, f, crease=30.0, min_area=0.05)
        area = face_areas(v, f)
        best = max(regions, key=lambda idx: area[np.intersect1d(idx, np.flatnonzero(cut))].sum())
        assert area[best].sum() == pytest.approx(area[cut].sum(), rel=0.02)


def test_a_smooth_break_missed_on_both_sides_is_labelled(halves):
    (va, fa, cut_a), (vb, fb, cut_b) = halves
    assert cut_a.any() and cut_b.any()
    segs = [labelled(va, fa, np.zeros(len(fa), bool)), labelled(vb, fb, np.zeros(len(fb), bool))]
    out, changed = relabel_surface_mates([(va, fa), (vb, fb)], segs, tol=0.006, min_area=0.05, min_overlap=0.9,
                                         rng=np.random.default_rng(0))
    assert changed == [0, 1]
    assert not segs[0].fracture.any() and not segs[1].fracture.any()  # not modified
    for s, (v, f, cut) in zip(out, halves):
        area = face_areas(v, f)
        assert area[s.fracture & cut].sum() > 0.98 * area[cut].sum()
        assert area[s.fracture & ~cut].sum() < 0.01 * area[cut].sum()  # the dented sphere stays original
        assert s.fracture_area == pytest.approx(area[s.fracture].sum()) and (s.region[s.fracture] >= 0).all()


def test_pieces_of_different_objects_have_no_mates(halves):
    import manifold3d as m3d

    (va, fa, _), _ = halves
    mesh = m3d.Manifold.sphere(0.8, 64).to_mesh()  # a whole sphere: its cap mates nothing
    vb, fb = np.asarray(mesh.vert_properties)[:, :3].astype(float), np.asarray(mesh.tri_verts).astype(np.int64)
    segs = [labelled(va, fa, np.zeros(len(fa), bool)), labelled(vb, fb, np.zeros(len(fb), bool))]
    out, changed = relabel_surface_mates([(va, fa), (vb, fb)], segs, tol=0.006, min_area=0.05, min_overlap=0.9,
                                         rng=np.random.default_rng(0))
    assert changed == [] and out[0] is segs[0] and out[1] is segs[1]
