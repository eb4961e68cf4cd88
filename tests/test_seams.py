"""Seam continuity: along a true contact the object's own surface runs on across the break."""

import numpy as np
import pytest

from reassemble.features import FractureSurface
from reassemble.geometry import face_areas, face_normals, make_scene, make_transform, sample_surface, transform_points
from reassemble.registration import RegistrationParams, contact_score, seam_continuity, touching_samples


def _half_bar(side: float, thickness: float = 0.3):
    """Half of a 1 x 0.6 x ``thickness`` bar cut at x = 0 (the x >= 0 half for side +1): (vertices, faces, fracture)."""
    import trimesh

    half = trimesh.creation.box(extents=[0.5, 0.6, thickness],
                                transform=make_transform(np.eye(3), [0.25 * side, 0, 0]))
    half = half.subdivide().subdivide().subdivide()
    v, f = np.asarray(half.vertices, float), np.asarray(half.faces)
    return v, f, np.abs(v[f][:, :, 0]).max(axis=1) < 1e-9  # the faces on the cut


def _surface(v, f, fracture, rng, n=4000) -> FractureSurface:
    area = face_areas(v, f)
    samples, which = sample_surface(v, f[fracture], n, rng=rng)
    surface, on = sample_surface(v, f, n, rng=rng)
    empty = np.zeros((0, 3))
    return FractureSurface(empty, empty, np.zeros((0, 2)), samples, face_normals(v, f[fracture])[which],
                           float(area[fracture].sum()) / n, surface, float(area.sum()) / n,
                           float(area[fracture].sum()), float(area.sum()),
                           surface_normals=face_normals(v, f)[on], surface_original=~fracture[on])


@pytest.fixture(scope="module")
def halves():
    rng = np.random.default_rng(0)
    (va, fa, ka), (vb, fb, kb) = _half_bar(1.0), _half_bar(-1.0)
    return (_surface(va, fa, ka, rng), make_scene(va, fa)), (_surface(vb, fb, kb, rng), make_scene(vb, fb))


def _continuity(halves, T, params):
    (a, scene_a), (b, scene_b) = halves
    touch, _ = touching_samples(a, b, T, target_scene=scene_b, tol=0.01, normal_angle=params.normal_angle)
    return seam_continuity(a, b, T, transform_points(T, a.samples[touch]), source_scene=scene_a, target_scene=scene_b,
                           tol=0.01, params=params)


def test_the_true_placement_continues_the_surface_and_a_turned_one_does_not(halves):
    params = RegistrationParams()
    assert _continuity(halves, np.eye(4), params) > 0.9
    # turned about the break's normal, the cap still lies on its mate over most of it, but
    # every wall now meets the other half's at 30 degrees
    turned = make_transform(np.array([[1, 0, 0], [0, np.cos(0.52), -np.sin(0.52)], [0, np.sin(0.52), np.cos(0.52)]]),
                            np.zeros(3))
    assert _continuity(halves, turned, params) < 0.3


def test_a_discontinuous_seam_lowers_the_score_not_the_contact(halves):
    (a, scene_a), (b, scene_b) = halves
    turned = make_transform(np.array([[1, 0, 0], [0, np.cos(0.52), -np.sin(0.52)], [0, np.sin(0.52), np.cos(0.52)]]),
                            np.zeros(3))
    on, off = RegistrationParams(), RegistrationParams(seam_angle=0.0)
    kw = dict(source_scene=scene_a, target_scene=scene_b, tol=0.01)
    s_on, c_on, _ = contact_score(a, b, turned, params=on, **kw)
    s_off, c_off, _ = contact_score(a, b, turned, params=off, **kw)
    assert c_on == c_off > 0
    assert s_on < 0.3 * s_off
    # the true placement keeps nearly all of its score
    assert contact_score(a, b, np.eye(4), params=on, **kw)[0] > 0.9 * contact_score(a, b, np.eye(4), params=off, **kw)[0]


def test_no_labelled_normals_is_no_evidence(halves):
    import dataclasses

    (a, scene_a), (b, scene_b) = halves
    bare = dataclasses.replace(a, surface_normals=None)
    assert seam_continuity(bare, b, np.eye(4), a.samples, source_scene=scene_a, target_scene=scene_b, tol=0.01,
                           params=RegistrationParams()) == 1.0


def test_the_score_is_a_share_of_the_smaller_break_however_thin_the_part(halves):
    import dataclasses

    (a, scene_a), (b, scene_b) = halves
    params = RegistrationParams()
    kw = dict(source_scene=scene_a, target_scene=scene_b, tol=0.01, params=params)
    score, contact, _ = contact_score(a, b, np.eye(4), **kw)
    assert score == pytest.approx(contact * _continuity(halves, np.eye(4), params) / min(a.fracture_area, b.fracture_area))
    assert score > 0.85  # the true mate closes nearly all of the break
    # a plate a sixth as thick: its break is 4 % of its surface, and its mate closes it as well
    rng = np.random.default_rng(1)
    (va, fa, ka), (vb, fb, kb) = _half_bar(1.0, 0.05), _half_bar(-1.0, 0.05)
    pa, pb = _surface(va, fa, ka, rng), _surface(vb, fb, kb, rng)
    assert pa.fracture_area < 0.05 * pa.area
    thin, _, _ = contact_score(pa, pb, np.eye(4), source_scene=make_scene(va, fa), target_scene=make_scene(vb, fb),
                               tol=0.01, params=params)
    assert thin > 0.8 and thin > params.min_score
    # a break the segmentation barely found counts as break_floor of the whole surface
    missed = dataclasses.replace(b, fracture_area=1e-6)
    floored, _, _ = contact_score(a, missed, np.eye(4), **kw)
    assert floored == pytest.approx(score * b.fracture_area / (params.break_floor * b.area))
