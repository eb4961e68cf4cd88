"""--max-memory by box tiling: a grid too large for the limit is convolved in tiles, with the
values of the whole grid but for the FFT kernels' far tails (:mod:`descriptors.tiles`).
"""

import logging
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from reassemble.descriptors import DescriptorParams, integral_invariants
from reassemble.descriptors.tiles import plan_tiles
from reassemble.descriptors.voxelize import make_grid
from reassemble.errors import ReassembleError

# measured (of the column's largest value): V 8e-6, P 1.5e-5, H 1.4e-5, SA 5e-5, area 6e-5,
# D2 4e-5, D 2e-5, SD2 1.7e-4; adding 12 empty voxels to the untiled grid's margin moves
# V 7e-6, SA 3e-5, area 7e-5, D2 5e-6
BOUNDS = {"V": 3e-5, "P": 3e-5, "H": 3e-5, "SA": 1.5e-4, "area": 1.5e-4, "D2": 1e-4, "D": 1e-4, "SD2": 4e-4}


def tube(radius: float, length: float, sections: int, rings: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed cylinder along z: ``rings`` rings of ``sections`` vertices, and fans for caps."""
    th = 2 * np.pi * np.arange(sections) / sections
    ring = np.column_stack([radius * np.cos(th), radius * np.sin(th)])
    V = np.column_stack([np.tile(ring, (rings, 1)), np.repeat(np.linspace(0.0, length, rings), sections)])
    V = np.vstack([V, [[0, 0, 0], [0, 0, length]]])
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(sections), indexing="ij")
    a, b = i * sections + j, i * sections + (j + 1) % sections
    c, d = a + sections, b + sections
    j, n = np.arange(sections), rings * sections
    F = np.vstack([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3),
                   np.column_stack([np.full(sections, n), (j + 1) % sections, j]),
                   np.column_stack([np.full(sections, n + 1), n - sections + j, n - sections + (j + 1) % sections])])
    return V, F


@pytest.fixture(scope="module")
def cylinder():
    """A cylinder 20 diameters long (9650 vertices), and a radius of 0.6 of its radius."""
    V, F = tube(0.15, 6.0, 48, 201)
    assert trimesh.Trimesh(V, F).is_watertight
    return V, F, [0.09]


def test_tiles_cover_every_point_once():
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0, 0], [1, 1, 8], size=(5000, 3))
    grid = make_grid(pts.min(axis=0), pts.max(axis=0), h=0.02, margin=0.1)
    tiles = plan_tiles(grid, pts, reach=6, max_memory=grid.size * 48 / 5, what="test")
    assert len(tiles) >= 5
    rows = np.concatenate([r for _, r in tiles])
    assert np.array_equal(np.sort(rows), np.arange(len(pts)))
    for tile, r in tiles:
        assert tile.size * 48 <= grid.size * 48 / 5 and tile.h == grid.h
        offset = (tile.origin - grid.origin) / grid.h  # on the whole grid's lattice
        assert np.allclose(offset, np.round(offset), atol=1e-9)
        cut = np.array(tile.shape) < grid.shape  # elsewhere the tile spans the grid
        assert cut.any() and np.allclose(offset[~cut], 0)
        u = ((pts[r] - tile.origin) / tile.h)[:, cut]  # each point's stencil and reach inside its tile
        assert (u >= 6 + 16 + 1).all() and (u <= np.array(tile.shape)[cut] - 6 - 16 - 3).all()


def _tile_counts(messages: list[str]) -> list[int]:
    return [int(m.split(" in ")[1].split()[0]) for m in messages if " tiles of " in m]


def test_tiled_invariants_equal_untiled(cylinder, caplog):
    V, F, radii = cylinder
    params = DescriptorParams(resolution=4, d2_resolution=4)  # grids of 12 and 23 MB
    whole = integral_invariants(V, F, radii, params=params)
    with caplog.at_level(logging.INFO, logger="reassemble.descriptors.invariants"):
        volume = integral_invariants(V, F, radii, params=replace(params, max_memory=6e6, with_d2=False))
        assert _tile_counts(caplog.messages) == [4]
        caplog.clear()
        distance = integral_invariants(V, F, radii, params=replace(params, max_memory=10e6))
        assert len(_tile_counts(caplog.messages)) == 2 and _tile_counts(caplog.messages)[1] >= 4
    for tiled, keys in ((volume, ("V", "P", "H", "SA", "area")), (distance, ("D2", "D", "SD2"))):
        for key in keys:
            a, b = getattr(whole, key), getattr(tiled, key)
            scale = np.abs(a).max(axis=0)
            assert (np.abs(a - b).max(axis=0) <= BOUNDS[key] * scale).all(), (key, np.abs(a - b).max(axis=0) / scale)
    cos = np.einsum("ijk,ijk->ij", whole.normal_area, volume.normal_area)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.01


def test_memory_too_small_for_one_tile_is_one_line(cylinder):
    V, F, radii = cylinder
    with pytest.raises(ReassembleError, match="limit 1 MB") as err:
        integral_invariants(V, F, radii, params=DescriptorParams(max_memory=1e6))
    assert "--max-memory" in str(err.value) and "smallest tile" in str(err.value) and "\n" not in str(err.value)


def test_open_surface_tiles_keep_z_whole_and_equal_untiled(caplog):
    """The winding-number occupancy makes whole columns along z exact: its tiles cut x and y
    only, and check the columns the whole grid checks (its coarse lattice)."""
    from data_synth.shapes import torus_mesh

    v, f = torus_mesh(1.0, 0.35, target_vertices=5000)
    faces = f[v[f].mean(axis=1)[:, 0] < 0.6]  # cut by a plane: two holes, w fractional near them
    used = np.unique(faces)
    params = DescriptorParams(resolution=4)  # grids of 34 MB (occupancy) and 47 MB (distance)
    whole = integral_invariants(v, faces, [0.1], params=params)
    with caplog.at_level(logging.INFO, logger="reassemble.descriptors.invariants"):
        volume = integral_invariants(v, faces, [0.1], params=replace(params, max_memory=20e6, with_d2=False))
        distance = integral_invariants(v, faces, [0.1], params=replace(params, max_memory=40e6))
    shapes = [m.split(" grid")[0].split(" on a ")[1] for m in caplog.messages if " tiles of " in m]
    tiles = [m.split(" tiles of ")[1].split(")")[0] + ")" for m in caplog.messages if " tiles of " in m]
    assert len(tiles) == 2 and all(s.split(", ")[2] == t.split(", ")[2] for s, t in zip(shapes, tiles)), caplog.messages
    for tiled, keys in ((volume, ("V", "P", "SA", "area")), (distance, ("D2", "D", "SD2"))):
        for key in keys:  # measured V 2.8e-5, P 4.5e-5, SA 1.4e-4, area 1.8e-4, D2 5e-6, D 1e-5, SD2 4e-5
            a, b = getattr(whole, key)[used], getattr(tiled, key)[used]
            change = np.abs(a - b).max() / np.abs(a).max()
            assert change <= 2 * BOUNDS[key], (key, change)


def test_memory_is_checked_for_every_grid_before_any_work(cylinder, monkeypatch):
    from reassemble.descriptors import invariants

    def no_work(*args, **kwargs):
        raise AssertionError("voxelized before the memory check")

    monkeypatch.setattr(invariants, "occupancy", no_work)
    V, F, radii = cylinder
    with pytest.raises(ReassembleError, match="D2 at radius"):  # the occupancy grid would fit in tiles
        integral_invariants(V, F, radii, params=DescriptorParams(resolution=4, d2_resolution=4, max_memory=6e6))
