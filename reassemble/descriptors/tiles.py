"""Box tiling of a convolution grid that would exceed the memory limit (Pottmann et al. 2009, Section 9.1).

The query points are covered by boxes of ``b`` voxels per side (the cores), each padded by
what a value read in it depends on: the kernel radius, the support of the cubic spline the
kernel integrates, the reading stencil, and ``PAD`` more voxels for the recursive spline
prefilters, whose influence decays by 0.268 a voxel. Each padded box is a grid of its own,
on the lattice of the whole grid, convolved independently; each query point is read from
the box whose core holds it.

The samples of a tile are those of the whole grid, but the values differ by more than
rounding: the kernels are continuous spectra cut at the grid's Nyquist frequency, whose
spatial counterparts have tails falling off as 1/d^2 along the axes, and a tile sees what
lies beyond its padding through them no more. Measured on a cylinder 20 diameters long
(``tests/test_descriptors_tiles.py``): V, P, SA and the area vector move by 1e-5 to 7e-5
of their largest value, as much as the untiled grid's own values move when 12 empty voxels
are added to its margin; D2 and D by up to 4e-5, SD2 by 1.7e-4 (``DISTANCE_PAD``). K2,
a small difference of large terms, amplifies D2's change: 0.16 on the cylinder's side,
where its scatter is 1.4.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..errors import ReassembleError
from .voxelize import Grid

BYTES_PER_VOXEL = 48  # peak working memory per voxel of the largest grid, measured
PAD = 16  # voxels beyond a value's support: 0.268^16 = 7e-10 of the prefilter's reach left
# ... and for the distance grids, whose fields are larger against their integrals (|d^2 -
# far| ~ 2.6 r^2 deep inside, D2 ~ 0.8 r^5): the kernels' 1/d^2 tails, cut at the padding,
# moved D2 by 9e-5 of its largest value with 16, 2.5e-5 with 32 (a cylinder, r/h = 4)
DISTANCE_PAD = 32
STENCIL = 4  # the cubic spline's reading stencil spans 4 nodes: a core of b voxels needs b + 4
COUNT_SAMPLE = 100_000  # query points used to count the occupied tiles of a candidate size


def human(nbytes: float) -> str:
    """``nbytes`` as "1.2 GB" or "35 MB"."""
    return f"{nbytes / 1e9:.1f} GB" if nbytes >= 1e8 else f"{nbytes / 1e6:.0f} MB"


def _shape_text(shape) -> str:
    return "x".join(str(int(n)) for n in shape)


def _cells(u: np.ndarray, b: int, tiled: np.ndarray) -> np.ndarray:
    """(n, 3) int64 index of the core holding each point (voxel units ``u``); 0 on untiled axes."""
    cells = np.floor(u / b).astype(np.int64)
    cells[:, ~tiled] = 0
    return cells


def _smallest(full: np.ndarray, reach: int, axes: np.ndarray) -> tuple[int, np.ndarray]:
    """(side, shape) of the smallest useful tile: a core as wide as the padding of one side."""
    from scipy.fft import next_fast_len

    side = int(next_fast_len(3 * reach + STENCIL, real=True))
    return side, np.where(axes, np.minimum(side, full), full)


def _count(cells: np.ndarray) -> int:
    """The number of distinct rows of (n, 3) int64 ``cells``."""
    c = cells - cells.min(axis=0)
    m = c.max(axis=0) + 1
    return len(np.unique((c[:, 0] * m[1] + c[:, 1]) * m[2] + c[:, 2]))


def _candidates(full: np.ndarray, reach: int, max_memory: float, axes: np.ndarray):
    """(side, shape) of the useful tiles that fit, smallest first: ``side`` voxels on the
    tileable ``axes`` longer than it, the whole grid on the others."""
    from scipy.fft import next_fast_len

    n, shape = _smallest(full, reach, axes)
    while np.prod(shape, dtype=np.float64) * BYTES_PER_VOXEL <= max_memory:
        yield n, shape
        if n >= full[axes].max():
            return
        n = int(next_fast_len(n + 1, real=True))
        shape = np.where(axes, np.minimum(n, full), full)


def check_fits(grid: Grid, *, reach: int, max_memory: float, what: str, pad: int = PAD,
               tile_z: bool = True) -> None:
    """Raise ReassembleError unless the grid, or its smallest useful tile, fits in ``max_memory``
    (the arguments as :func:`plan_tiles`)."""
    if grid.size * BYTES_PER_VOXEL <= max_memory:
        return
    full = np.array(grid.shape)
    smallest = _smallest(full, int(reach) + max(int(pad), PAD), np.array([True, True, bool(tile_z)]))[1]
    need = np.prod(smallest, dtype=np.float64) * BYTES_PER_VOXEL
    if need > max_memory:
        raise ReassembleError(
            f"{what}: a {_shape_text(full)} grid needs about {human(grid.size * BYTES_PER_VOXEL)} and its "
            f"smallest tile, {_shape_text(smallest)}, about {human(need)} "
            f"(limit {human(max_memory)}): raise --max-memory if the machine has it"
        )


def plan_tiles(grid: Grid, points: np.ndarray, *, reach: int, max_memory: float, what: str,
               pad: int = PAD, tile_z: bool = True) -> list[tuple[Grid, np.ndarray | slice]]:
    """The grids to convolve and the query points each is read at.

    Parameters
    ----------
    grid : the whole grid (:func:`voxelize.make_grid`)
    points : (n, 3) query points
    reach : voxels from a reading stencil's nodes to the farthest sample their values
        depend on (the kernel radius plus the spline's support)
    max_memory : bytes allowed for one grid (``BYTES_PER_VOXEL`` a voxel)
    what : the grid's name in the error message ("radius 0.1")
    pad : voxels more on each side, at least ``PAD``
    tile_z : whether the z axis may be cut (not for the winding-number occupancy, whose
        columns along z are made exact as wholes: :func:`voxelize.winding_occupancy`)

    Returns
    -------
    list of (tile, rows): ``[(grid, slice(None))]`` when the grid fits; else tiles on the
    grid's lattice and the (k,) int64 indices of the points each serves, every point once

    Raises
    ------
    ReassembleError
        when not even the smallest useful tile fits

    Notes
    -----
    Of the shapes that fit (``side`` voxels on the axes cut, the whole grid on the others,
    for every choice of axes), the one of least estimated cost is taken: the occupied tiles
    times ``N log N`` for N voxels a tile, the paper's model, whose optimum for boxes along
    a surface is ``b = 2.28 r`` with a padding of r; here the padding is larger and the
    count is that of the boxes the query points occupy. A core narrower than the padding p
    is not useful: a tile then computes more than ``((b + 2 p) / b)^3 = 27`` voxels per
    core voxel (3 when one axis is cut), and thousands with a core of one voxel (an open
    torus patch: 2 356 tiles, 200 times the untiled time), so the limit is refused instead.
    """
    if grid.size * BYTES_PER_VOXEL <= max_memory:
        return [(grid, slice(None))]
    check_fits(grid, reach=reach, max_memory=max_memory, what=what, pad=pad, tile_z=tile_z)
    full = np.array(grid.shape)
    reach = int(reach) + max(int(pad), PAD)
    axes = np.array([True, True, bool(tile_z)])
    u = (np.asarray(points, np.float64) - grid.origin) / grid.h
    sample = u[:: max(1, len(u) // COUNT_SAMPLE)]
    best = None
    for cut in itertools.product(*[(True, False) if a else (False,) for a in axes]):  # which axes to cut
        cut = np.array(cut)
        if not cut.any():
            continue
        for side, shape in _candidates(full, reach, max_memory, cut):
            b, tiled = side - 2 * reach - STENCIL, cut & (full > side)
            voxels = float(np.prod(shape, dtype=np.float64))
            cost = _count(_cells(sample, b, tiled)) * voxels * np.log(voxels)
            if best is None or cost < best[0]:
                best = (cost, b, tiled, shape)
    _, b, tiled, shape = best
    cells = _cells(u, b, tiled)
    keys, inverse = np.unique(cells, axis=0, return_inverse=True)
    order = np.argsort(inverse.ravel(), kind="stable")
    bounds = np.searchsorted(inverse.ravel()[order], np.arange(len(keys) + 1))
    tiles = []
    for t, key in enumerate(keys):
        first = np.where(tiled, key * b - reach - 1, 0)  # the core's stencil starts a node below it
        tile = Grid(origin=grid.origin + grid.h * first, h=grid.h, shape=tuple(int(n) for n in shape))
        tiles.append((tile, order[bounds[t]:bounds[t + 1]]))
    return tiles


def tile_offset(tile: Grid, grid: Grid) -> np.ndarray:
    """(3,) int64: the index in ``grid`` of the tile's voxel (0, 0, 0)."""
    return np.round((tile.origin - grid.origin) / grid.h).astype(np.int64)
