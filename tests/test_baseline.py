"""The Open3D-textbook baseline: recovers a whole shape's pose, deterministically."""

import subprocess
import sys

import numpy as np
import pytest

from reassemble.baseline import fpfh_assemble, fpfh_register
from reassemble.geometry import (
    invert_transform, make_transform, random_rotation, rotation_angle_deg, transform_points,
)
from reassemble.files import load_mesh, resolve_mesh_path


@pytest.fixture(scope="module")
def cow():
    mesh = load_mesh(resolve_mesh_path("spot_low_resolution"))
    diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    return mesh.vertices, mesh.faces, diag


def _moved(vertices, seed, diag):
    """A copy of the vertices under a seeded rigid transform, and that transform."""
    rng = np.random.default_rng(seed)
    T = make_transform(random_rotation(rng), rng.normal(size=3) * diag)
    return transform_points(T, vertices), T


def _assert_close(T_est, T_true, diag):
    assert rotation_angle_deg(T_est[:3, :3], T_true[:3, :3]) < 2.0
    assert np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]) < 0.01 * diag


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_known_transform(cow, seed):
    vertices, faces, diag = cow
    moved, T_moved_orig = _moved(vertices, seed, diag)
    T, fitness = fpfh_register(moved, faces, vertices, faces, voxel=diag / 30, seed=seed)
    assert T.shape == (4, 4) and T.dtype == np.float64
    assert 0.9 < fitness <= 1.0
    _assert_close(T, invert_transform(T_moved_orig), diag)


def test_deterministic_and_inputs_untouched(cow):
    vertices, faces, diag = cow
    moved, _ = _moved(vertices, 3, diag)
    before = [a.copy() for a in (moved, faces, vertices)]
    runs = [fpfh_register(moved, faces, vertices, faces, voxel=diag / 30, seed=5) for _ in range(3)]
    for T, fitness in runs[1:]:
        assert np.array_equal(T, runs[0][0]) and fitness == runs[0][1]
    for a, b in zip(before, (moved, faces, vertices)):
        assert np.array_equal(a, b)


def test_assemble_copies(cow):
    vertices, faces, diag = cow
    moved = [_moved(vertices, seed, diag) for seed in (10, 11, 12)]
    poses = fpfh_assemble([(v, faces) for v, _ in moved], voxel=diag / 30)
    assert len(poses) == 3 and np.array_equal(poses[0], np.eye(4))
    T_world_0 = moved[0][1]  # the world is fragment 0's frame: T_0 @ T_k^-1 maps copy k there
    for pose, (_, T_k) in zip(poses, moved):
        _assert_close(pose, T_world_0 @ invert_transform(T_k), diag)


def test_import_is_cheap():
    code = "import sys, reassemble.baseline; sys.exit('open3d' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
