"""Synthetic broken objects with exact ground truth, behind ``reassemble break``.

A closed mesh is cut with manifold3d booleans, in one of four styles:

- ``fractal``: the largest piece is split recursively by a rough, multi-scale surface (a
  fractal height field) bent across the piece; roughness 0 is a plane.
- ``smooth``: the same recursion with a few long-wavelength undulations and no fine
  roughness, as clean breaks in ceramics, glass and stone.
- ``cells``: a Voronoi-like partition: near-planar, gently curved faces meeting at sharp
  edges, several pieces around an edge or corner, as physics-based prefracture datasets
  (Breaking Bad) and Blender's cell fracture make them.
- ``mixed``: the recursion where every cut draws its own style and roughness.

manifold3d keeps the origin of every output triangle, so each face is labelled exactly
as fracture (it came from a cut or chip solid) or original surface. Optional realism:
chipped-off losses along the break, simplification, scan noise, and fragments written as
unions of cells that keep the faces between them (``keep_cell_faces``, labelled interior).
Finally each fragment gets a random rigid pose and a shuffled name.

All lengths in :class:`BreakParams` are fractions of the object's bounding-box
diagonal (or of the piece being cut), so the same options work in any unit.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np

from .errors import ReassembleError
from .geometry import (
    face_areas,
    invert_transform,
    make_scene,
    make_transform,
    random_rotation,
    signed_volume,
    tet_volumes,
    transform_points,
)

log = logging.getLogger(__name__)

FRACTURE = 1
ORIGINAL = 0
INTERIOR = 2  # a face between two cells of one fragment (``keep_cell_faces``), kept twice

LABEL_NAMES = {ORIGINAL: "original surface", FRACTURE: "fracture", INTERIOR: "interior"}

STYLES = ("fractal", "smooth", "cells", "mixed")
# RMS height of a cut / radius of the piece it cuts, when --roughness is not given
STYLE_ROUGHNESS = {"fractal": 0.08, "smooth": 0.05, "cells": 0.02}
CELLS_PER_FRAGMENT = 4  # cells in a fragment written with keep_cell_faces
# up to this many cells, each is cut from what the earlier ones left (the data_synth sets,
# 20 pieces at most, were made so); beyond, from the solid itself (_partition's Notes)
SEQUENTIAL_CELLS = 20
# a shell of the input under this share of its volume is a speck, dropped before breaking:
# far below the smallest piece (min_volume / pieces, halved three times, at 200 pieces ~6e-5)
SPECK_VOLUME = 1e-6


@dataclass(frozen=True)
class BreakParams:
    """Options of the fracture generator.

    Attributes
    ----------
    pieces : number of fragments, >= 2
    roughness : RMS height of a cut surface as a fraction of the radius of the piece it cuts
        (0 = a plane); by default the style's (:data:`STYLE_ROUGHNESS`). ``mixed`` draws its
        own for every cut and takes none.
    hurst : Hurst exponent of the fractal cut surface (lower is rougher at small scales)
    cut_edge : edge length of the cut-surface grid, fraction of the object diagonal
    noise : standard deviation of Gaussian vertex noise, fraction of the object diagonal
    chips : mean number of chipped-off losses per fragment, along the break
    chip_size : typical chip radius, fraction of the object diagonal
    decimate : simplification tolerance, fraction of the object diagonal (0 = off)
    gap : material lost at the break: every fracture surface is eroded by half of it along
        its normals, so mating surfaces end about this far apart (fraction of the diagonal)
    min_volume : smallest allowed fragment, as a fraction of the mean fragment volume
    min_thickness : thinnest allowed part of a cut, as a fraction of the piece's thickness
    scale : factor applied to the input mesh first (to make puzzles in other units)
    style : one of :data:`STYLES`: how the cut surfaces are shaped
    keep_cell_faces : write every fragment as a union of cells keeping the faces between
        them, each twice with opposite orientations, labelled :data:`INTERIOR` (the layout
        of Breaking Bad's early release)
    """

    pieces: int
    roughness: float | None = None
    hurst: float = 0.6
    cut_edge: float = 0.008
    noise: float = 0.0
    chips: float = 0.0
    chip_size: float = 0.02
    decimate: float = 0.0
    gap: float = 0.0
    min_volume: float = 0.3
    min_thickness: float = 0.35
    scale: float = 1.0
    style: str = "fractal"
    keep_cell_faces: bool = False

    @property
    def cut_roughness(self) -> float | None:
        """``roughness``, or the style's default when it is None (None for ``mixed``).

        Resolved when read, not when made: options changed later (``--style cells`` after
        the defaults) then take their own style's default.
        """
        return STYLE_ROUGHNESS.get(self.style) if self.roughness is None else self.roughness

    def to_dict(self) -> dict:
        """The options as written to ``ground_truth.json``, the roughness resolved.

        Options added after the first ground-truth format (``style``, ``keep_cell_faces``)
        are left out at their defaults, so a default puzzle's files read as before.
        """
        out = dataclasses.asdict(self)
        out["roughness"] = self.cut_roughness
        for name in ("style", "keep_cell_faces"):
            if out[name] == BreakParams.__dataclass_fields__[name].default:
                del out[name]
        return out

    def label_names(self) -> dict[str, str]:
        """``{label value: meaning}`` of the labels a puzzle made with these options holds."""
        used = (ORIGINAL, FRACTURE, INTERIOR) if self.keep_cell_faces else (ORIGINAL, FRACTURE)
        return {str(k): LABEL_NAMES[k] for k in used}

    def check(self) -> None:
        """Raise :class:`ReassembleError` for options out of range, naming the option."""
        if self.style not in STYLES:
            raise ReassembleError(f"--style must be one of {', '.join(STYLES)} (got {self.style!r})")
        if self.pieces < 2:
            raise ReassembleError(f"--pieces must be at least 2 (got {self.pieces})")
        if self.pieces > 200:
            raise ReassembleError(f"--pieces must be at most 200 (got {self.pieces})")
        for name in ("noise", "chips", "decimate", "gap"):
            if not getattr(self, name) >= 0:
                raise ReassembleError(f"--{name} must be >= 0 (got {getattr(self, name)})")
        if self.style == "mixed":
            if self.roughness is not None:
                raise ReassembleError("--roughness does not apply to --style mixed (every cut draws its own)")
        elif not 0.0 <= self.cut_roughness <= 0.5:
            raise ReassembleError(f"--roughness must be in [0, 0.5] (got {self.cut_roughness})")
        if not 0.0 < self.hurst < 1.0:
            raise ReassembleError(f"hurst must be in (0, 1) (got {self.hurst})")
        if not 1e-4 <= self.cut_edge <= 0.1:
            raise ReassembleError(f"--cut-edge must be in [1e-4, 0.1] (got {self.cut_edge})")
        if not 0 < self.chip_size <= 0.2:
            raise ReassembleError(f"--chip-size must be in (0, 0.2] (got {self.chip_size})")
        if not 0 < self.min_volume < 1:
            raise ReassembleError(f"min_volume must be in (0, 1) (got {self.min_volume})")
        if not (self.scale > 0 and np.isfinite(self.scale)):
            raise ReassembleError(f"--scale must be a positive number (got {self.scale})")


@dataclass
class Fragment:
    """One fragment of a synthetic puzzle.

    Attributes
    ----------
    name : file stem
    vertices : (n, 3) float64, in the fragment's own (posed) coordinates
    faces : (m, 3) int64
    labels : (m,) int8, ``FRACTURE`` or ``ORIGINAL`` per face
    T_world_fragment : (4, 4) float64, maps fragment coordinates to the object's frame
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    labels: np.ndarray
    T_world_fragment: np.ndarray


@dataclass
class Contact:
    """Two fragments touching in the assembled object; ``area`` of the shared fracture."""

    a: str
    b: str
    area: float


@dataclass
class Puzzle:
    """Result of :func:`break_mesh`: fragments, true contacts and the object's extent."""

    fragments: list[Fragment]
    contacts: list[Contact]
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    volume: float
    area: float
    stats: dict = field(default_factory=dict)


def fractal_heightfield(n: int, *, hurst: float, rng: np.random.Generator) -> np.ndarray:
    """Zero-mean, unit-RMS fractional Brownian surface on an (n, n) grid by spectral synthesis.

    The power spectrum falls as ``f**-(2*hurst + 2)`` from the grid size down to the grid
    step, so the surface is rough at every scale in between.
    """
    m = 2 * n  # synthesize on a larger periodic grid and crop, so the crop is not periodic
    fx = np.fft.fftfreq(m)[:, None]
    fy = np.fft.rfftfreq(m)[None, :]
    f = np.hypot(fx, fy)
    f[0, 0] = np.inf
    amplitude = f ** (-(hurst + 1.0))
    amplitude[f < 1.0 / n] = 0.0  # nothing longer than the piece: its bend comes from the band edge
    amplitude *= np.exp(-((f / 0.35) ** 2))  # roll off near the grid step: no single-cell spikes
    phase = rng.random(amplitude.shape)
    spectrum = amplitude * rng.standard_normal(amplitude.shape) * np.exp(2j * np.pi * phase)
    h = np.fft.irfft2(spectrum, s=(m, m))[:n, :n]
    h -= h.mean()
    rms = np.sqrt(np.mean(h * h))
    return h / rms if rms > 0 else h


def undulating_heightfield(
    n: int, *, waves: int, wavelength: tuple[float, float], rng: np.random.Generator
) -> np.ndarray:
    """Zero-mean, unit-RMS sum of a few plane waves on an (n, n) grid: long undulations,
    no fine roughness.

    ``wavelength`` (low, high) is in units of the grid's side; each wave draws its own
    wavelength in that range, direction, phase and amplitude.
    """
    u = np.linspace(0.0, 1.0, n)
    gx, gy = np.meshgrid(u, u, indexing="ij")
    h = np.zeros((n, n))
    for _ in range(waves):
        angle = rng.uniform(0.0, 2.0 * np.pi)
        k = 2.0 * np.pi / rng.uniform(*wavelength)
        h += rng.uniform(0.5, 1.0) * np.cos(k * (np.cos(angle) * gx + np.sin(angle) * gy)
                                             + rng.uniform(0.0, 2.0 * np.pi))
    h -= h.mean()
    rms = np.sqrt(np.mean(h * h))
    return h / rms if rms > 0 else h


def _heightfield_solid(
    center: np.ndarray, frame: np.ndarray, radius: float, spacing: float, height: np.ndarray,
    *, coarse_bottom: bool = False,
):
    """Closed solid below a height field: the region ``z < h(x, y)`` of a box around a piece.

    ``frame`` columns are the field's x, y axes and its normal; ``height`` is (n, n).
    ``coarse_bottom`` closes the box with a fan under the field's rim instead of a second
    grid: the same solid where it cuts, half the triangles.
    """
    import manifold3d as mf

    n = height.shape[0]
    half = 1.2 * radius
    xs = np.linspace(-half, half, n)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    top = np.column_stack([gx.ravel(), gy.ravel(), height.ravel()])

    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    top_faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    # boundary loop, counter-clockwise seen from +z
    loop = np.concatenate(
        [idx[:, 0], idx[-1, 1:], idx[-2::-1, -1], idx[0, -2:0:-1]]
    )
    if coarse_bottom:
        rim = top[loop] * [1.0, 1.0, 0.0] - [0.0, 0.0, half]
        local = np.vstack([top, rim, [[0.0, 0.0, -half]]])
        under = n * n + np.arange(len(loop))  # the rim vertex under each loop vertex
        p, q, bp, bq = loop, np.roll(loop, -1), under, np.roll(under, -1)
        bottom_faces = np.column_stack([np.full(len(loop), len(local) - 1), bq, bp])
    else:
        bottom = np.column_stack([gx.ravel(), gy.ravel(), np.full(n * n, -half)])
        local = np.vstack([top, bottom])
        bottom_faces = top_faces[:, ::-1] + n * n
        p, q = loop, np.roll(loop, -1)
        bp, bq = p + n * n, q + n * n
    side_faces = np.concatenate([np.column_stack([p, bp, bq]), np.column_stack([p, bq, q])])
    faces = np.concatenate([top_faces, bottom_faces, side_faces]).astype(np.uint32)
    world = local @ frame.T + center
    solid = mf.Manifold(mf.Mesh64(vert_properties=np.ascontiguousarray(world), tri_verts=faces))
    if solid.status() != mf.Error.NoError or solid.volume() <= 0:
        raise RuntimeError(f"cut surface is not a valid solid ({solid.status()})")
    return solid.as_original()


def _mesh_arrays(solid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (n, 3), faces (m, 3) and the original ID of every face of a manifold."""
    mesh = solid.to_mesh64()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy()
    faces = np.asarray(mesh.tri_verts, dtype=np.int64).copy()
    run_index = np.asarray(mesh.run_index, dtype=np.int64) // 3
    run_id = np.asarray(mesh.run_original_id, dtype=np.int64)
    origin = np.repeat(run_id, np.diff(run_index)) if len(run_id) else np.zeros(0, np.int64)
    return vertices, faces, origin


def _shape(solid) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Vertices, volume centroid, principal (longest) axis, RMS extent along it, thickness.

    Thickness is the smallest RMS extent of the surface (area-weighted covariance of the
    face centroids).
    """
    v, f, _ = _mesh_arrays(solid)
    tri = v[f]
    vol = tet_volumes(v, f)
    centroid = (tri.sum(axis=1) / 4.0 * vol[:, None]).sum(axis=0) / vol.sum()
    d = v - centroid
    evals, evecs = np.linalg.eigh(d.T @ d / len(d))
    w = face_areas(v, f)
    c = tri.mean(axis=1)
    dc = c - (c * w[:, None]).sum(axis=0) / w.sum()
    thickness = np.sqrt(max(np.linalg.eigvalsh((dc * w[:, None]).T @ dc / w.sum())[0], 0.0))
    return v, centroid, evecs[:, -1], float(np.sqrt(max(evals[-1], 0.0))), float(thickness)


def _random_unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def _frame_from_normal(normal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Orthonormal frame (columns x, y, normal) with a random spin about the normal."""
    x = np.cross(normal, _random_unit(rng))
    x /= np.linalg.norm(x)
    y = np.cross(normal, x)
    return np.column_stack([x, y, normal])


# wavelengths of the undulating cut surfaces, in units of the cut grid's side (2.4 piece radii)
_SMOOTH_WAVES = dict(waves=3, wavelength=(0.33, 0.83))  # 0.8-2 radii: a clean, curved break
_CELL_WAVES = dict(waves=2, wavelength=(0.6, 1.25))  # 1.5-3 radii: a near-planar cell face


def _cut_height(style: str, roughness: float, n: int, radius: float, *, hurst: float, rng) -> np.ndarray:
    """(n, n) heights of one cut surface of the given style, RMS ``roughness * radius``."""
    if style == "fractal":
        return roughness * radius * fractal_heightfield(n, hurst=hurst, rng=rng)
    waves = _SMOOTH_WAVES if style == "smooth" else _CELL_WAVES
    return roughness * radius * undulating_heightfield(n, **waves, rng=rng)


def _draw_cut(params: BreakParams, rng) -> tuple[str, float]:
    """Style and roughness of one cut: the options', or for ``mixed`` a draw of its own."""
    if params.style != "mixed":
        return params.style, params.cut_roughness
    style = ("fractal", "smooth", "cells")[int(rng.integers(3))]
    return style, STYLE_ROUGHNESS[style] * float(rng.uniform(0.25, 1.5))


def _split_piece(piece, *, params: BreakParams, diag: float, min_vol: float, min_thick: float, room: int, rng):
    """Try rough cuts of ``piece`` until one gives 2..room+1 chunky parts; None if none does.

    Chunky: each part at least ``min_vol`` in volume and ``min_thick`` times the piece's
    thickness (its smallest extent), so no thin slabs are shaved off its side.
    Returns (parts, the cutter's ID, (style, roughness) of the cut).
    """
    v, centroid, axis, extent, thick = _shape(piece)
    for _attempt in range(40):
        # mostly across the longest extent, tilted at random: chunky pieces, varied faces
        normal = axis + 0.6 * _random_unit(rng)
        normal /= np.linalg.norm(normal)
        center = centroid + axis * rng.uniform(-0.25, 0.25) * extent
        radius = float(np.max(np.linalg.norm(v - center, axis=1))) * 1.02
        spacing = params.cut_edge * diag
        n = int(np.clip(np.ceil(2.4 * radius / spacing) + 1, 16, 600))
        style, roughness = _draw_cut(params, rng)
        height = _cut_height(style, roughness, n, radius, hurst=params.hurst, rng=rng)
        cutter = _heightfield_solid(center, _frame_from_normal(normal, rng), radius, spacing, height,
                                    coarse_bottom=style != "fractal")
        parts = (piece ^ cutter).decompose() + (piece - cutter).decompose()
        if not 2 <= len(parts) <= room + 1:
            continue
        if min(p.volume() for p in parts) < min_vol:
            continue
        if min(_shape(p)[4] for p in parts) < min_thick * thick:
            continue
        return parts, cutter.original_id(), (style, roughness)
    return None


def _fracture(solid, *, params: BreakParams, diag: float, rng) -> tuple[list, set[int], list]:
    """Cut ``solid`` into ``params.pieces`` parts by recursive splits; returns the parts, the
    cutters' IDs and the (style, roughness) of every cut."""
    total = solid.volume()
    pieces = [solid]
    cut_ids: set[int] = set()
    cuts = []
    min_fraction = params.min_volume
    while len(pieces) < params.pieces:
        order = np.argsort([-p.volume() for p in pieces], kind="stable")
        result = None
        for relax in range(4):
            min_vol = min_fraction * 0.5**relax * total / params.pieces
            min_thick = params.min_thickness * 0.5**relax
            for i in order[:3]:  # the largest pieces first
                result = _split_piece(
                    pieces[i], params=params, diag=diag, min_vol=min_vol, min_thick=min_thick,
                    room=params.pieces - len(pieces), rng=rng,
                )
                if result is not None:
                    break
            if result is not None:
                break
        if result is None:
            raise ReassembleError(
                f"could not cut into {params.pieces} pieces without slivers "
                "(try fewer --pieces or a lower --roughness)"
            )
        parts, cut_id, cut = result
        pieces[i : i + 1] = parts
        cut_ids.add(cut_id)
        cuts.append(cut)
    return pieces, cut_ids, cuts


def _inside_voxels(vertices: np.ndarray, faces: np.ndarray, *, target: int):
    """Centres of the cubic grid cells inside a closed mesh, about ``target`` of them.

    Returns points (k, 3), their integer grid indices (k, 3) and the grid step.
    """
    v = np.asarray(vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    step = (max(signed_volume(v, faces), 1e-300) / target) ** (1.0 / 3.0)
    step = max(step, float(np.prod(hi - lo) / 4e6) ** (1.0 / 3.0))  # at most ~4M grid points
    shape = np.maximum(np.ceil((hi - lo) / step).astype(np.int64), 1)
    ijk = np.indices(shape).reshape(3, -1).T
    points = lo + (ijk + 0.5) * step
    scene = make_scene(v, faces)
    import open3d as o3d

    inside = scene.compute_occupancy(o3d.core.Tensor(points.astype(np.float32))).numpy() > 0.5
    return points[inside], ijk[inside], float(step)


def _cell_seeds(points: np.ndarray, count: int, rng, *, iterations: int = 2) -> np.ndarray:
    """``count`` cell centres among ``points``: k-means++ seeding, then a few Lloyd steps.

    Few steps on purpose: the cells come out chunky but not all of one size.
    """
    from scipy.spatial import cKDTree

    seeds = [points[rng.integers(len(points))]]
    d2 = np.sum((points - seeds[0]) ** 2, axis=1)
    for _ in range(count - 1):
        pick = points[rng.choice(len(points), p=d2 / d2.sum())]
        seeds.append(pick)
        d2 = np.minimum(d2, np.sum((points - pick) ** 2, axis=1))
    seeds = np.array(seeds)
    for _ in range(iterations):
        owner = cKDTree(seeds).query(points)[1]
        for c in range(count):
            if np.any(owner == c):
                seeds[c] = points[owner == c].mean(axis=0)
    return seeds


def _cutter_pairs(points: np.ndarray, owner: np.ndarray, seeds: np.ndarray, *,
                  start: list[set[int]] | None = None) -> list[list[int]]:
    """For every cell i, the later cells j whose bisector must bound it when the cells are
    cut out one after another (cell i = what is left, on i's side of those bisectors).

    Found by replaying the sequence on the grid points: a point cell i would take from a
    nearer seed m adds the pair (i, m), until every point goes to its nearest seed.
    ``start``: pairs known before (e.g. cells that touch on the grid); without them the
    first replay gives cell i every later cell, mostly bisectors that never meet it.
    """
    k = len(seeds)
    later: list[set[int]] = [set(s) for s in start] if start is not None else [set() for _ in range(k)]
    while True:
        taken = np.full(len(points), -1)
        for i in range(k - 1):
            mine = taken < 0
            for j in later[i]:
                mid, normal = 0.5 * (seeds[i] + seeds[j]), seeds[j] - seeds[i]
                mine &= (points - mid) @ normal < 0
            taken[mine] = i
        taken[taken < 0] = k - 1
        wrong = np.flatnonzero(taken != owner)
        if len(wrong) == 0:
            return [sorted(s) for s in later]
        for i, m in set(zip(taken[wrong].tolist(), owner[wrong].tolist())):
            later[i].add(m)


def _touching_cells(grid_index: np.ndarray, owner: np.ndarray, count: int) -> list[set[int]]:
    """For every cell i, the later cells whose grid points are next to its own (26-neighbours)."""
    lo = grid_index.min(axis=0)
    grid = np.full(tuple(grid_index.max(axis=0) - lo + 3), -1, dtype=np.int64)
    grid[tuple((grid_index - lo + 1).T)] = owner
    core = tuple(slice(1, n - 1) for n in grid.shape)
    here = grid[core]
    out: list[set[int]] = [set() for _ in range(count)]
    for offset in np.ndindex(3, 3, 3):
        there = grid[tuple(slice(1 + d - 1, n - 1 + d - 1) for d, n in zip(offset, grid.shape))]
        both = (here >= 0) & (there >= 0) & (here < there)
        for i, j in set(zip(here[both].tolist(), there[both].tolist())):
            out[i].add(j)
    return out


def _partition(solid, seeds: np.ndarray, points: np.ndarray, owner: np.ndarray, *, step: float,
               roughness: float, spacing: float | None, rng, grid_index: np.ndarray | None = None,
               ) -> tuple[list, set[int]]:
    """Cut ``solid`` into the Voronoi-like cells of ``seeds`` (an exact partition).

    Cell i is what is left of the solid on i's side of the (gently undulating) bisectors
    with the later cells :func:`_cutter_pairs` names; the last cell is the rest. Every cut
    is a pair's bisector, so mating faces are the same surface. ``spacing`` None: flat
    bisectors on a coarse grid. Returns the cells (some may be empty or in several bodies)
    and the cutters' IDs.

    Notes
    -----
    Up to :data:`SEQUENTIAL_CELLS` cells, each is cut from the remainder of the ones before
    (the puzzles made so far, byte for byte). Beyond, the remainder would gather every
    earlier cut and each boolean grow with it, so a cell is cut from the solid and only the
    earlier cells' regions that reach its own are taken away: the same set, at a cost that
    grows with the number of cells, not its square. There, too, the bisectors are sought
    from the cells that touch on the grid (``grid_index``, the points' integer grid
    positions) rather than from none, which would give the first cells a bisector with
    nearly every other.
    """
    sequential = len(seeds) <= SEQUENTIAL_CELLS
    start = None if sequential or grid_index is None else _touching_cells(grid_index, owner, len(seeds))
    pairs = _cutter_pairs(points, owner, seeds, start=start)
    regions, ids = [], set()
    for i in range(len(seeds) - 1):
        poly = _cell_region(seeds, points[owner == i], i, pairs[i], step=step, roughness=roughness,
                            spacing=spacing, rng=rng)
        regions.append(poly)
        if poly is not None:
            ids.update(poly[1])
    if sequential:
        rest, cells = solid, []
        for poly in regions:
            if poly is None:  # nothing later borders this cell: it is all that is left
                cells.append(rest)
                rest = rest - rest
            else:
                cells.append(rest ^ poly[0])
                rest = rest - poly[0]
        return cells + [rest], ids
    return _local_cells(solid, regions), ids


def _cell_region(seeds, region, i: int, later: list[int], *, step: float, roughness: float, spacing, rng):
    """The solid on cell i's side of its bisectors with the ``later`` cells (the
    intersection of their cutters) and the cutters' IDs; None when there are none."""
    poly, ids = None, []
    for j in later:
        mid = 0.5 * (seeds[i] + seeds[j])
        normal = (seeds[j] - seeds[i]) / np.linalg.norm(seeds[j] - seeds[i])
        reach = float(np.max(np.linalg.norm(region - mid, axis=1))) if len(region) else 0.0
        radius = 1.02 * (reach + 3.0 * step)
        if spacing is None or roughness == 0:
            n = 16
            height = np.zeros((n, n))
        else:
            n = int(np.clip(np.ceil(2.4 * radius / spacing) + 1, 16, 600))
            height = _cut_height("cells", roughness, n, radius, hurst=0.5, rng=rng)
        frame = _frame_from_normal(normal, rng)
        cutter = _heightfield_solid(mid, frame, radius, 2.4 * radius / (n - 1), height, coarse_bottom=True)
        ids.append(cutter.original_id())
        poly = cutter if poly is None else poly ^ cutter
    return None if poly is None else (poly, ids)


def _local_cells(solid, regions: list) -> list:
    """Cell i = the solid within region i, less the earlier regions whose boxes meet its
    box; the last cell = the solid less every region (see :func:`_partition`)."""
    import manifold3d as mf

    def less(a, others):
        return a - mf.Manifold.batch_boolean(others, mf.OpType.Add) if others else a

    boxes = [None if r is None else np.reshape(r[0].bounding_box(), (2, 3)) for r in regions]
    cells = []
    for i, r in enumerate(regions):
        if r is None:  # nothing later borders this cell: it is all that is left
            cells.append(less(solid, [q[0] for q in regions[:i]]))
            return cells + [solid - solid] * (len(regions) - i)
        lo, hi = boxes[i]
        near = [regions[m][0] for m in range(i) if np.all(boxes[m][0] <= hi) and np.all(lo <= boxes[m][1])]
        cells.append(less(solid ^ r[0], near))
    return cells + [less(solid, [r[0] for r in regions])]


def _single_bodies(grid_index: np.ndarray, owner: np.ndarray, count: int) -> bool:
    """True if every cell's grid points form one 26-connected body, but for specks (under
    8 points and 1 % of the cell: where a bisector crosses a wall a few points thick
    at a shallow angle the grid leaves such islands): a cheap test of seeds."""
    from scipy import ndimage

    lo = grid_index.min(axis=0)
    grid = np.full(tuple(grid_index.max(axis=0) - lo + 1), -1, dtype=np.int64)
    grid[tuple((grid_index - lo).T)] = owner
    for c, box in enumerate(ndimage.find_objects(grid + 1)):
        if c >= count:
            break
        if box is None:
            return False
        mask = grid[box] == c
        labelled, bodies = ndimage.label(mask, structure=np.ones((3, 3, 3)))
        if bodies > 1:
            sizes = np.sort(np.bincount(labelled.ravel())[1:])
            if sizes[-2] >= max(8, 0.01 * sizes.sum()):
                return False
    return True


def _cells(solid, *, params: BreakParams, diag: float, rng) -> tuple[list, set[int], list]:
    """Cut ``solid`` into ``params.pieces`` Voronoi-like cells; returns the parts, the
    cutters' IDs and the (style, roughness) of every cut.

    Seeds that would leave a cell in several bodies (on a grid of ~40k points inside) or
    smaller than ``min_volume`` of the mean are redrawn before any boolean.
    """
    from scipy.spatial import cKDTree

    v, f, _ = _mesh_arrays(solid)
    points, grid_index, step = _inside_voxels(v, f, target=40_000)
    if len(points) < 20 * params.pieces:
        raise ReassembleError(f"too thin to cut into {params.pieces} cells")
    total = solid.volume()
    for relax in range(4):
        min_vol = params.min_volume * 0.5**relax * total / params.pieces
        for _attempt in range(10):
            seeds = _cell_seeds(points, params.pieces, rng)
            owner = cKDTree(seeds).query(points)[1]
            counts = np.bincount(owner, minlength=params.pieces)
            if counts.min() * step**3 < min_vol or not _single_bodies(grid_index, owner, params.pieces):
                continue
            cells, ids = _partition(solid, seeds, points, owner, step=step, roughness=params.cut_roughness,
                                    spacing=params.cut_edge * diag, rng=rng, grid_index=grid_index)
            if params.pieces > SEQUENTIAL_CELLS:  # with many cells some speck is near certain
                cells = _absorb_specks(cells, speck=0.01 * total / params.pieces)
            parts = [p for c in cells for p in c.decompose()]
            if len(parts) == params.pieces and min(p.volume() for p in parts) >= min_vol:
                return parts, ids, [("cells", params.cut_roughness)] * len(ids)
    raise ReassembleError(
        f"could not cut into {params.pieces} cells of one body each (try fewer --pieces)"
    )


def _absorb_specks(cells: list, *, speck: float) -> list:
    """Each speck (a body under ``speck`` volume split off a cell where an undulating
    bisector grazes the surface) joined to a cell it touches, where they make one body;
    the other bodies stay as they are (the cell then counts as several)."""
    import manifold3d as mf

    cells, specks = list(cells), []
    for k, c in enumerate(cells):
        bodies = sorted(c.decompose(), key=lambda b: -b.volume())
        small = [b for b in bodies[1:] if b.volume() < speck]
        if small:
            specks += [(k, b) for b in small]
            cells[k] = mf.Manifold.batch_boolean([b for b in bodies if not any(b is s for s in small)], mf.OpType.Add)
    boxes = [np.reshape(c.bounding_box(), (2, 3)) for c in cells]
    for k, b in specks:
        lo, hi = np.reshape(b.bounding_box(), (2, 3))
        for m in np.argsort([np.linalg.norm((bx[0] + bx[1]) - (lo + hi)) for bx in boxes]):
            if m != k and not cells[m].is_empty() and np.all(boxes[m][0] <= hi) and np.all(lo <= boxes[m][1]):
                joined = cells[m] + b
                if len(joined.decompose()) == len(cells[m].decompose()):
                    cells[m] = joined
                    break
        else:  # touches no other cell as one body: it stays its cell's
            cells[k] = cells[k] + b
    return cells


def _split_into_cells(piece, *, count: int, rng) -> tuple[list, set[int]]:
    """``piece`` cut by flat bisectors into up to ``count`` cells (an exact partition, a cell
    may have several bodies); returns the non-empty cells and the cutters' IDs."""
    from scipy.spatial import cKDTree

    v, f, _ = _mesh_arrays(piece)
    points, _, step = _inside_voxels(v, f, target=4000)
    if len(points) < 4 * count:
        return [piece], set()
    seeds = _cell_seeds(points, count, rng)
    owner = cKDTree(seeds).query(points)[1]
    cells, ids = _partition(piece, seeds, points, owner, step=step, roughness=0.0, spacing=None, rng=rng)
    return [c for c in cells if not c.is_empty()], ids


def _chip(piece, *, cut_ids: set[int], params: BreakParams, diag: float, rng):
    """Knock small irregular chips off ``piece`` along its break; returns (piece, chip IDs)."""
    import manifold3d as mf

    chip_ids: set[int] = set()
    count = rng.poisson(params.chips)
    for _ in range(count):
        v, f, origin = _mesh_arrays(piece)
        fracture_faces = np.isin(origin, list(cut_ids))
        on_fracture = np.zeros(len(v), bool)
        on_fracture[f[fracture_faces].ravel()] = True
        on_original = np.zeros(len(v), bool)
        on_original[f[~fracture_faces].ravel()] = True
        rim = np.flatnonzero(on_fracture & on_original)
        if len(rim) == 0:
            break
        center = v[rng.choice(rim)]
        radii = params.chip_size * diag * rng.uniform(0.5, 1.5) * rng.uniform(0.6, 1.0, 3)
        R = random_rotation(rng)
        chip = mf.Manifold.sphere(1.0, 20).scale(radii.tolist())
        chip = chip.transform(np.column_stack([R, center]).tolist()).as_original()
        chipped = piece - chip
        parts = chipped.decompose()
        if len(parts) != 1 or parts[0].volume() < 0.8 * piece.volume():
            continue
        piece = parts[0]
        chip_ids.add(chip.original_id())
    return piece, chip_ids


def _contacts(world: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], tol: float) -> list[Contact]:
    """Fracture area each pair of fragments shares, from face centroids within ``tol``."""
    import open3d as o3d

    scenes, boxes = [], []
    for _, v, f, _ in world:
        scenes.append(make_scene(v, f))
        boxes.append((v.min(axis=0) - tol, v.max(axis=0) + tol))
    contacts = []
    for i in range(len(world)):
        for j in range(i + 1, len(world)):
            if np.any(boxes[i][1] < boxes[j][0]) or np.any(boxes[j][1] < boxes[i][0]):
                continue
            areas = []
            for a, b in ((i, j), (j, i)):
                _, v, f, lab = world[a]
                sel = lab == FRACTURE
                cent = v[f[sel]].mean(axis=1).astype(np.float32)
                if len(cent) == 0:
                    areas.append(0.0)
                    continue
                d = scenes[b].compute_distance(o3d.core.Tensor(cent)).numpy()
                areas.append(float(face_areas(v, f[sel])[d < tol].sum()))
            area = 0.5 * (areas[0] + areas[1])
            if area > 0:
                a, b = sorted((world[i][0], world[j][0]))
                contacts.append(Contact(a, b, area))
    return contacts


def _erode(vertices: np.ndarray, faces: np.ndarray, fracture: np.ndarray, depth: float) -> np.ndarray:
    """Vertices of the fracture faces moved ``depth`` inwards along their (fracture-face)
    normals; a new array."""
    t = np.asarray(vertices, dtype=np.float64)[faces[fracture]]
    weighted = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # area-weighted face normals
    normals = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(normals, faces[fracture, k], weighted)
    length = np.linalg.norm(normals, axis=1)
    moved = length > 0
    out = np.array(vertices, dtype=np.float64, copy=True)
    out[moved] -= depth * normals[moved] / length[moved, None]
    return out


def _weld_exact(meshes: list[tuple[np.ndarray, np.ndarray, np.ndarray]]):
    """One mesh of several (vertices, faces, origin): vertices at the same position merged,
    so the cells of a fragment share their seams (noise then moves both sides alike)."""
    v = np.vstack([m[0] for m in meshes])
    offsets = np.cumsum([0] + [len(m[0]) for m in meshes[:-1]])
    f = np.vstack([m[1] + o for m, o in zip(meshes, offsets)])
    unique, inverse = np.unique(v, axis=0, return_inverse=True)
    return unique, inverse.reshape(-1)[f], np.concatenate([m[2] for m in meshes])


def break_mesh(
    vertices: np.ndarray, faces: np.ndarray, params: BreakParams, *, rng: np.random.Generator
) -> Puzzle:
    """Break a closed mesh into fragments with exact per-face labels and true poses.

    Parameters
    ----------
    vertices : (n, 3) float
        A closed, consistently oriented triangle mesh (not modified).
    faces : (m, 3) int
    params : BreakParams
    rng : numpy Generator, the only source of randomness

    Returns
    -------
    Puzzle
        Fragments in random poses, sorted by name, with ``T_world_fragment`` mapping each
        back to the (scaled) input mesh's frame. ``labels`` are ``ORIGINAL``, ``FRACTURE``
        and, with ``keep_cell_faces``, ``INTERIOR``; ``stats["cut_styles"]`` lists the
        (style, roughness) of every cut.

    Notes
    -----
    The ``cells`` partition is Voronoi fracture, as Blender's Cell Fracture add-on makes it
    and with the near-planar faces of the Breaking Bad dataset's pieces (Sellán et al.,
    "Breaking Bad: A Dataset for Geometric Fracture and Reassembly", NeurIPS 2022): every
    cell is bounded by the bisectors of its seed and its neighbours', so pieces meet along
    edges and at corners.
    Each cell is cut from what is left (beyond :data:`SEQUENTIAL_CELLS`, from the solid
    less the earlier cells' regions near it: the same set), so the cells partition the solid
    exactly even where the bisectors undulate, and every cut face is a piece of one cutter:
    it is labelled fracture and its mate lies on the same surface. With many cells, a speck
    split off a cell where a bisector grazes the surface is joined to a neighbour; a
    crumb-size void may stay beside it.
    """
    import manifold3d as mf

    params.check()
    vertices = np.asarray(vertices, dtype=np.float64) * params.scale
    faces = np.asarray(faces, dtype=np.uint32)
    solid = mf.Manifold(mf.Mesh64(vert_properties=np.ascontiguousarray(vertices), tri_verts=faces))
    if solid.status() != mf.Error.NoError or solid.is_empty():
        raise ReassembleError(f"mesh is not a valid solid for booleans ({solid.status().name})")
    solid = _without_specks(solid).as_original()
    object_id = solid.original_id()
    bbox_min, bbox_max = vertices.min(axis=0), vertices.max(axis=0)
    diag = float(np.linalg.norm(bbox_max - bbox_min))
    volume, area = solid.volume(), solid.surface_area()

    # one stream per stage: noise, chips or decimation never change the cuts or the poses
    cut_rng, chip_rng, pose_rng, noise_rng = rng.spawn(4)
    split = _cells if params.style == "cells" else _fracture
    pieces, cut_ids, cuts = split(solid, params=params, diag=diag, rng=cut_rng)
    pieces, damage_ids = _damage(pieces, cut_ids, params=params, diag=diag, rng=chip_rng)

    interior_ids: set[int] = set()
    if params.keep_cell_faces:  # last, on the final pieces: their outer surface stays as it is
        (cell_rng,) = rng.spawn(1)
        meshes = []
        for piece in pieces:
            cells, ids = _split_into_cells(piece, count=CELLS_PER_FRAGMENT, rng=cell_rng)
            interior_ids |= ids
            meshes.append(_weld_exact([_mesh_arrays(c) for c in cells]))
    else:
        meshes = [_mesh_arrays(p) for p in pieces]

    names = [f"fragment_{k:02d}" for k in pose_rng.permutation(len(pieces))]
    world = [(name, v, f, _face_labels(origin, object_id, damage_ids, interior_ids))
             for name, (v, f, origin) in zip(names, meshes)]
    contacts = _contacts(world, tol=max(1e-5, 2.0 * params.decimate) * diag)
    if params.gap > 0:  # after the contacts: they are the true neighbours, gap or not
        world = [(name, _erode(v, f, labels == FRACTURE, 0.5 * params.gap * diag), f, labels)
                 for name, v, f, labels in world]

    fragments = _pose(world, params=params, diag=diag, pose_rng=pose_rng, noise_rng=noise_rng)
    contacts.sort(key=lambda c: (c.a, c.b))
    stats = {"cuts": len(cut_ids), "chips": len(damage_ids) - len(cut_ids), "cut_styles": cuts,
             "interior_cuts": len(interior_ids)}
    log.info("broke into %d fragments with %d cuts, %d chips", len(fragments), stats["cuts"], stats["chips"])
    return Puzzle(fragments, contacts, bbox_min, bbox_max, float(volume), float(area), stats)


def _without_specks(solid):
    """``solid`` less its shells under :data:`SPECK_VOLUME` of its volume (floating crumbs,
    or cavities a simplification left as shells of their own).

    Every cut would also decompose into such a shell, and no part that small passes the
    sliver test, so a mesh with one speck could not be broken at all.
    """
    import manifold3d as mf

    bodies = solid.decompose()
    if len(bodies) < 2:
        return solid
    total = abs(solid.volume())
    kept = [b for b in bodies if abs(b.volume()) >= SPECK_VOLUME * total]
    if len(kept) == len(bodies) or not kept:
        return solid
    log.info("dropped %d specks (shells under %g of the volume)", len(bodies) - len(kept), SPECK_VOLUME)
    return mf.Manifold.compose(kept)


def _face_labels(origin: np.ndarray, object_id: int, damage_ids: set[int], interior_ids: set[int]) -> np.ndarray:
    """(m,) int8 labels of faces from the manifold3d original id each came from: the input
    solid's are ``ORIGINAL``, the cells' ``INTERIOR``, the cutters' and chips' ``FRACTURE``."""
    labels = np.where(origin == object_id, ORIGINAL, FRACTURE).astype(np.int8)
    labels[np.isin(origin, list(interior_ids))] = INTERIOR
    if not np.all(np.isin(origin, list(damage_ids | interior_ids | {object_id}))):
        raise RuntimeError("manifold3d lost the origin of some triangles")
    return labels


def _damage(pieces: list, cut_ids: set[int], *, params: BreakParams, diag: float, rng: np.random.Generator):
    """Chip the pieces' rims and decimate them, as ``params`` asks.

    Parameters
    ----------
    pieces : manifold3d Manifolds
    cut_ids : original ids of the cutters (the fracture surfaces)
    params : BreakParams (``chips``, ``decimate``)
    diag : the solid's bounding-box diagonal
    rng : the chips' stream

    Returns
    -------
    pieces : the damaged Manifolds, in the same order
    damage_ids : ``cut_ids`` and the original ids of every chip (their faces are fracture)
    """
    damage_ids = set(cut_ids)
    if params.chips > 0:
        chipped = []
        for piece in pieces:
            piece, ids = _chip(piece, cut_ids=cut_ids, params=params, diag=diag, rng=rng)
            damage_ids |= ids
            chipped.append(piece)
        pieces = chipped
    if params.decimate > 0:
        pieces = [p.simplify(params.decimate * diag) for p in pieces]
    return pieces, damage_ids


def _pose(world: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], *, params: BreakParams, diag: float,
          pose_rng: np.random.Generator, noise_rng: np.random.Generator) -> list[Fragment]:
    """Fragments in random poses (and with scan noise), sorted by name.

    Parameters
    ----------
    world : (name, (n, 3) vertices in the object's frame, (m, 3) faces, (m,) labels) per fragment
    params : BreakParams (``noise``)
    diag : the solid's bounding-box diagonal
    pose_rng, noise_rng : the poses' and the noise's streams

    Returns
    -------
    list of Fragment, each with the ``T_world_fragment`` that puts it back
    """
    fragments = []
    for name, v, f, labels in world:
        R = random_rotation(pose_rng)
        centroid = v.mean(axis=0)
        offset = pose_rng.uniform(-1.0, 1.0, 3) * diag
        T_world_fragment = make_transform(R, centroid - R @ offset)
        local = transform_points(invert_transform(T_world_fragment), v)
        if params.noise > 0:
            local = local + noise_rng.normal(0.0, params.noise * diag, local.shape)
        fragments.append(Fragment(name, local, f, labels, T_world_fragment))
    fragments.sort(key=lambda fr: fr.name)
    return fragments
