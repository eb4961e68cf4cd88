"""Label-free comparison of assemblies: the true one closes its breaks, a wrong one does not."""

import dataclasses

import numpy as np
import pytest

from reassemble.arbiter import assembly_contact, better
from reassemble.assembly import Assembly
from reassemble.geometry import face_areas, make_transform
from reassemble.pipeline import read_puzzle, reference_size
from reassemble.registration import RegistrationParams
from reassemble.synth import FRACTURE


def _truth(puzzles):
    p = read_puzzle(puzzles.puzzle("torus", 3, 0) / "ground_truth.json")
    names = sorted(p.meshes)
    meshes = [(np.asarray(p.meshes[n].vertices), np.asarray(p.meshes[n].faces)) for n in names]
    T = np.stack([np.asarray(p.ground_truth["fragments"][n]["transform"], float) for n in names])
    fracture = sum(face_areas(v, f)[p.labels[n] == FRACTURE].sum() for n, (v, f) in zip(names, meshes))
    return meshes, T, fracture


def test_the_true_assembly_has_the_most_contact(puzzles):
    meshes, T, fracture = _truth(puzzles)
    size, params = reference_size(meshes), RegistrationParams()
    n = len(meshes)
    true = Assembly(T, np.zeros(n, int), np.ones(n, bool), np.ones(n))
    # one fragment turned 15 degrees about its centre: its breaks open on one side, cut in on the other
    c = meshes[1][0].mean(axis=0)
    angle = np.radians(15.0)
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    turn = make_transform(R, c - R @ c)
    wrong = T.copy()
    wrong[1] = T[1] @ turn
    # the same poses with one fragment left out of the group
    left_out = Assembly(T, np.array([0, 1, 0]), np.array([True, False, True]), np.ones(n))
    (contact, penetration), moved, alone = assembly_contact(
        [true, Assembly(wrong, np.zeros(n, int), np.ones(n, bool), np.ones(n)), left_out], meshes, size=size,
        params=[params] * 3)
    # each break is counted once, from one side of its pair: half the fracture area
    assert 0.8 * fracture / 2 < contact < 1.2 * fracture / 2, (contact, fracture)
    assert penetration < 0.02 * contact
    assert better(moved, (contact, penetration), penetration_weight=params.penetration_weight)
    assert not better((contact, penetration), moved, penetration_weight=params.penetration_weight)
    assert alone[0] < contact and not better((contact, penetration), alone,
                                             penetration_weight=params.penetration_weight)


def test_each_assembly_is_scored_at_its_own_gap(puzzles):
    """A run that found its breaks a gap apart (material lost) and placed fragments badly must
    not judge a right, closed assembly at its gap: there a closed break touches nowhere."""
    meshes, T, _ = _truth(puzzles)
    size, closed = reference_size(meshes), RegistrationParams()
    gapped = dataclasses.replace(closed, gap=0.08)
    n = len(meshes)
    true = Assembly(T, np.zeros(n, int), np.ones(n, bool), np.ones(n))
    half = Assembly(T, np.array([0, 0, 1]), np.array([True, True, False]), np.ones(n))
    (c_half, p_half), (c_true, p_true) = assembly_contact([half, true], meshes, size=size, params=[gapped, closed])
    assert better((c_half, p_half), (c_true, p_true), penetration_weight=closed.penetration_weight)
    (at_other_gap, _), = assembly_contact([true], meshes, size=size, params=[gapped])
    assert at_other_gap < 0.1 * c_true
    with pytest.raises(ValueError, match="2 assemblies but 1"):
        assembly_contact([half, true], meshes, size=size, params=[closed])
