"""Rims: a break's outline is shared by its mates, and pins a smooth break that contact leaves free to slide."""

import dataclasses

import numpy as np
import pytest

from reassemble.assembly import refine
from reassemble.features import rim_points
from reassemble.geometry import make_transform, transform_points

from .test_seams import _half_bar, _surface


def _with_rim(v, f, fracture, rng):
    points, directions, _ = rim_points(v, f, fracture, radius=0.05)
    return dataclasses.replace(_surface(v, f, fracture, rng), rim=points, rim_directions=directions)


@pytest.fixture(scope="module")
def halves():
    rng = np.random.default_rng(1)
    return [_with_rim(*_half_bar(side), rng) for side in (1.0, -1.0)]


def test_rim_is_the_outline_of_the_break_with_directions_out_of_it():
    v, f, fracture = _half_bar(1.0)
    points, directions, lengths = rim_points(v, f, fracture, radius=0.05)
    # the cut is the 0.6 x 0.3 rectangle at x = 0: its outline is 1.8 long
    assert np.allclose(points[:, 0], 0.0)
    on_edge = np.isclose(np.abs(points[:, 1]), 0.3) | np.isclose(np.abs(points[:, 2]), 0.15)
    assert on_edge.all()
    assert 1.5 < lengths.sum() <= 1.8 + 1e-9  # corners whose direction is unclear are left out
    # across the outline, in the cut's plane, out of the rectangle
    assert np.allclose(directions[:, 0], 0.0, atol=1e-6)
    outward = np.where(np.isclose(np.abs(points[:, 1]), 0.3)[:, None], [[0, 1, 0]] * np.sign(points[:, 1:2]),
                       [[0, 0, 1]] * np.sign(points[:, 2:3]))
    assert np.median(np.einsum("ij,ij->i", directions, outward)) > 0.99
    assert np.einsum("ij,ij->i", directions, outward).min() > 0.5


def test_no_rim_without_a_labelled_break():
    v, f, fracture = _half_bar(1.0)
    for labels in (np.zeros_like(fracture), np.ones_like(fracture)):
        points, directions, lengths = rim_points(v, f, labels, radius=0.05)
        assert points.shape == directions.shape == (0, 3) and lengths.shape == (0,)


@pytest.mark.parametrize("slide", [(0.0, 0.03, 0.0), (0.0, 0.02, -0.02)])
def test_rims_pin_a_flat_break_that_contact_leaves_free(halves, slide):
    # the second half slid along the flat cut by 2-3 contact tolerances: contact alone
    # is as good there as at the truth; the shared outline is not
    start = np.stack([np.eye(4), make_transform(np.eye(3), np.array(slide))])
    probe = halves[1].surface
    for reach, worst in ((0.0, 0.9 * np.linalg.norm(slide)), (3.0, 0.002)):
        T = refine(start, halves, tol=0.01, anchor=0, rim_reach=reach)
        error = np.linalg.norm(transform_points(T[1], probe) - probe, axis=1).max()
        assert (error < worst) if reach else (error > worst), (reach, error)


@pytest.mark.parametrize("slide", [(0.0, 0.02, 0.0), (0.0, 0.015, -0.015)])
def test_pair_icp_aligns_the_rims_once_contact_has_settled(halves, slide):
    from reassemble.registration import icp

    source, target = halves
    start = make_transform(np.eye(3), np.array(slide))
    probe = source.surface
    for reach, worst in ((0.0, 0.9 * np.linalg.norm(slide)), (3.0, 0.002)):
        T = icp(source, target, start, tol=0.01, rim_reach=reach)
        error = np.linalg.norm(transform_points(T, probe) - probe, axis=1).max()
        assert (error < worst) if reach else (error > worst), (reach, error)


def test_a_stretch_of_mislabelled_rim_does_not_pull_the_fit(halves):
    from reassemble.registration import icp

    source, target = halves
    # a fifth of the target's rim labelled two tolerances out of place, all on one side (a
    # segmentation that ran past the break there): the offsets' median still says "in place"
    moved = target.rim.copy()
    stretch = target.rim[:, 1] > 0.29
    assert 0.1 < stretch.mean() < 0.35
    moved[stretch] += 0.02 * target.rim_directions[stretch]
    biased = dataclasses.replace(target, rim=moved)
    probe = source.surface
    T = icp(source, biased, np.eye(4), tol=0.01, rim_reach=3.0, rim_weight=1.0)
    assert np.linalg.norm(transform_points(T, probe) - probe, axis=1).max() < 0.004
