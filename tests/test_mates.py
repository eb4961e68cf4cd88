"""Planar mates: a planar break face labelled original is found by its labelled mate."""

import numpy as np
import pytest

from reassemble.geometry import face_areas, face_normals, random_rotation
from reassemble.mates import relabel_planar_mates

from .conftest import labelled


def _halves(rng):
    """A dented sphere cut by a plane off its centre, each half moved to its own random pose:
    [(vertices, faces, (f,) bool true cut faces)] per half."""
    import manifold3d as m3d

    ball = m3d.Manifold.sphere(1.0, 96) - m3d.Manifold.cube([0.6, 0.6, 0.6], True).translate([0.9, 0.0, 0.3])
    out = []
    for part in ball.split_by_plane([0.3, 0.2, 1.0], 0.25):
        mesh = part.to_mesh()
        v, f = np.asarray(mesh.vert_properties)[:, :3].astype(float), np.asarray(mesh.tri_verts).astype(np.int64)
        n = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
        centres = v[f].mean(axis=1)
        cut = (np.abs(centres @ n - 0.25) < 1e-6) & (np.abs(face_normals(v, f) @ n) > 0.999)
        R = random_rotation(rng)
        out.append((v @ R.T + rng.normal(size=3), f, cut))
    return out


@pytest.fixture(scope="module")
def halves():
    return _halves(np.random.default_rng(3))


def test_the_missed_side_of_a_planar_break_is_labelled(halves):
    (va, fa, cut_a), (vb, fb, cut_b) = halves
    assert cut_a.any() and cut_b.any()
    segs = [labelled(va, fa, cut_a), labelled(vb, fb, np.zeros(len(fb), bool))]  # b's face missed
    given = [s.fracture.copy() for s in segs]
    out, changed = relabel_planar_mates([(va, fa), (vb, fb)], segs, tol=0.005, min_area=0.1, min_overlap=0.9,
                                        rng=np.random.default_rng(0))
    assert changed == [1]
    assert out[0] is segs[0] and all(np.array_equal(s.fracture, g) for s, g in zip(segs, given))  # not modified
    area = face_areas(vb, fb)
    found = out[1].fracture
    assert area[found & cut_b].sum() > 0.98 * area[cut_b].sum()
    assert area[found & ~cut_b].sum() < 0.01 * area[cut_b].sum()  # the dented sphere stays original
    assert out[1].fracture_area == pytest.approx(area[found].sum()) and (out[1].region[found] >= 0).all()


def test_a_set_whose_breaks_are_labelled_is_left_as_it_is(halves):
    (va, fa, cut_a), (vb, fb, cut_b) = halves
    segs = [labelled(va, fa, cut_a), labelled(vb, fb, cut_b)]
    out, changed = relabel_planar_mates([(va, fa), (vb, fb)], segs, tol=0.005, min_area=0.1, min_overlap=0.9,
                                        rng=np.random.default_rng(0))
    assert changed == [] and all(o is s for o, s in zip(out, segs))


def test_a_plane_that_does_not_match_the_outline_is_not_a_mate(halves):
    """A prism's end face of about the break's area and second moments (a triangle beside
    a disc), labelled original, is not its mate: the outlines differ."""
    import manifold3d as m3d

    (va, fa, cut_a), _ = halves
    # the break: a disc of radius 0.97 less a dent; the triangle's circumradius 1.45
    box = m3d.Manifold.cylinder(0.5, 1.45, 1.45, 3).to_mesh()
    vb, fb = np.asarray(box.vert_properties)[:, :3].astype(float), np.asarray(box.tri_verts).astype(np.int64)
    segs = [labelled(va, fa, cut_a), labelled(vb, fb, np.zeros(len(fb), bool))]
    _, changed = relabel_planar_mates([(va, fa), (vb, fb)], segs, tol=0.005, min_area=0.1, min_overlap=0.9,
                                      rng=np.random.default_rng(0))
    assert changed == []


def test_outlines_are_compared_only_with_the_nearest_similar_planes():
    from reassemble.mates import _nearest_similar, _Plane, _similar
    from reassemble.planes import PlanarPatch

    rng = np.random.default_rng(0)

    def plane(k, labelled):
        area, spread = rng.uniform(1.0, 2.0), rng.uniform(0.5, 1.0, 2)
        return _Plane(k % 7, labelled, PlanarPatch(np.zeros(3), np.array([0, 0, 1.0]), np.eye(3)[:2], spread, area,
                                                   np.zeros((3, 2))))

    planes = [plane(k, k % 3 == 0) for k in range(60)]
    found = dict(_nearest_similar(planes, count=1000))
    assert sorted(found) == [i for i, p in enumerate(planes) if p.labelled]
    for i, near in found.items():  # uncapped: exactly the similar planes of other fragments
        assert sorted(near) == [j for j, q in enumerate(planes)
                                if q.fragment != planes[i].fragment and _similar(planes[i].patch, q.patch)]
    capped = dict(_nearest_similar(planes, count=4))
    for i, near in capped.items():  # capped: the nearest of them, nearest first
        assert near == found[i][:4]
        key = lambda j: np.log([planes[j].patch.area, *planes[j].patch.spread])
        d = [np.sum((key(j) - key(i)) ** 2) for j in found[i]]
        assert d == sorted(d)


def test_the_pruned_search_decides_as_the_best_of_every_candidate(monkeypatch):
    """A labelled plane's unlabelled mate is taken exactly when it is the best of all its
    candidates and overlaps by min_overlap; labelled candidates are compared only when an
    unlabelled one qualifies."""
    from reassemble import mates
    from reassemble.planes import PlanarPatch

    rng = np.random.default_rng(1)

    def patch():
        return PlanarPatch(np.zeros(3), np.array([0, 0, 1.0]), np.eye(3)[:2], np.ones(2), 1.0, np.zeros((3, 2)))

    planes = [mates._Plane(k % 5, bool(rng.random() < 0.5), patch()) for k in range(40)]
    index = {id(p.patch): j for j, p in enumerate(planes)}
    table, seen = {}, []

    def overlap(p, q, *, spacing):
        seen.append(index[id(q)])
        return table[seen[-1]]

    monkeypatch.setattr(mates, "_outline_overlap", overlap)
    mates._start(planes, [1.0] * 5, 0.9)
    labelled = [k for k, p in enumerate(planes) if p.labelled]
    pruned = 0
    try:
        for _ in range(300):
            table = {j: float(rng.choice([0.5, 0.85, 0.9, 0.95, rng.random()])) for j in range(len(planes))}
            i = int(rng.choice(labelled))
            others = [j for j in range(len(planes)) if planes[j].fragment != planes[i].fragment]
            similar = [int(j) for j in rng.permutation(others)[:8]]
            seen.clear()
            got = mates._best_unlabelled_mate((i, similar))
            overlap_, j = max((table[j], j) for j in similar)
            assert got == ((overlap_, j) if not planes[j].labelled and overlap_ >= 0.9 else None)
            assert sorted(seen) == sorted(set(seen)) and set(seen) <= set(similar)
            if all(table[j] < 0.9 for j in similar if not planes[j].labelled):
                assert all(not planes[j].labelled for j in seen)  # no labelled outline compared
            pruned += len(seen) < len(similar)
    finally:
        mates.worker_state.clear()
    assert pruned > 100


def test_mates_compared_in_processes_are_those_compared_here(halves, monkeypatch):
    """Two labelled faces (the cut half and a moved copy of it) compared in two worker
    processes: the same labels as in this process."""
    from reassemble import mates

    (va, fa, cut_a), (vb, fb, cut_b) = halves
    meshes = [(va, fa), (vb, fb), (va + 5.0, fa)]
    segs = [labelled(va, fa, cut_a), labelled(vb, fb, np.zeros(len(fb), bool)),
            labelled(va + 5.0, fa, cut_a)]
    kw = dict(tol=0.005, min_area=0.1, min_overlap=0.9)
    here, changed = relabel_planar_mates(meshes, segs, rng=np.random.default_rng(0), **kw)
    monkeypatch.setattr(mates, "_PARALLEL_FROM", 2)
    there, changed2 = relabel_planar_mates(meshes, segs, rng=np.random.default_rng(0), jobs=2, **kw)
    assert changed == changed2 == [1]
    assert all(np.array_equal(a.fracture, b.fracture) for a, b in zip(here, there))
