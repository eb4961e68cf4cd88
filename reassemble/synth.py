"""Synthetic broken objects with exact ground truth, behind ``reassemble break``.

A closed mesh is cut recursively: the largest piece is split by a rough, multi-scale
surface (a fractal height field, never a plane) bent across the piece, using
manifold3d booleans. manifold3d keeps the origin of every output triangle, so each
face is labelled exactly as fracture (it came from a cut or chip solid) or original
surface. Optional realism: chipped-off losses along the break, simplification and
scan noise. Finally each fragment gets a random rigid pose and a shuffled name.

All lengths in :class:`BreakParams` are fractions of the object's bounding-box
diagonal (or of the piece being cut), so the same options work in any unit.
"""

from __future__ import annotations

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
    tet_volumes,
    transform_points,
)

log = logging.getLogger(__name__)

FRACTURE = 1
ORIGINAL = 0


@dataclass(frozen=True)
class BreakParams:
    """Options of the fracture generator.

    Attributes
    ----------
    pieces : number of fragments, >= 2
    roughness : RMS height of a cut surface as a fraction of the radius of the piece it cuts
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
    """

    pieces: int
    roughness: float = 0.08
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

    def check(self) -> None:
        """Raise :class:`ReassembleError` for options out of range, naming the option."""
        if self.pieces < 2:
            raise ReassembleError(f"--pieces must be at least 2 (got {self.pieces})")
        if self.pieces > 200:
            raise ReassembleError(f"--pieces must be at most 200 (got {self.pieces})")
        for name in ("roughness", "noise", "chips", "decimate", "gap"):
            if not getattr(self, name) >= 0:
                raise ReassembleError(f"--{name} must be >= 0 (got {getattr(self, name)})")
        if not 0.0 < self.roughness <= 0.5:
            raise ReassembleError(f"--roughness must be in (0, 0.5] (got {self.roughness})")
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


def _heightfield_solid(
    center: np.ndarray, frame: np.ndarray, radius: float, spacing: float, height: np.ndarray
):
    """Closed solid below a height field: the region ``z < h(x, y)`` of a box around a piece.

    ``frame`` columns are the field's x, y axes and its normal; ``height`` is (n, n).
    """
    import manifold3d as mf

    n = height.shape[0]
    half = 1.2 * radius
    xs = np.linspace(-half, half, n)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    top = np.column_stack([gx.ravel(), gy.ravel(), height.ravel()])
    bottom = np.column_stack([gx.ravel(), gy.ravel(), np.full(n * n, -half)])
    local = np.vstack([top, bottom])

    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    top_faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    bottom_faces = top_faces[:, ::-1] + n * n
    # boundary loop, counter-clockwise seen from +z
    loop = np.concatenate(
        [idx[:, 0], idx[-1, 1:], idx[-2::-1, -1], idx[0, -2:0:-1]]
    )
    p, q = loop, np.roll(loop, -1)
    side_faces = np.concatenate(
        [np.column_stack([p, p + n * n, q + n * n]), np.column_stack([p, q + n * n, q])]
    )
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


def _split_piece(piece, *, params: BreakParams, diag: float, min_vol: float, min_thick: float, room: int, rng):
    """Try rough cuts of ``piece`` until one gives 2..room+1 chunky parts; None if none does.

    Chunky: each part at least ``min_vol`` in volume and ``min_thick`` times the piece's
    thickness (its smallest extent), so no thin slabs are shaved off its side.
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
        height = params.roughness * radius * fractal_heightfield(n, hurst=params.hurst, rng=rng)
        cutter = _heightfield_solid(center, _frame_from_normal(normal, rng), radius, spacing, height)
        parts = (piece ^ cutter).decompose() + (piece - cutter).decompose()
        if not 2 <= len(parts) <= room + 1:
            continue
        if min(p.volume() for p in parts) < min_vol:
            continue
        if min(_shape(p)[4] for p in parts) < min_thick * thick:
            continue
        return parts, cutter.original_id()
    return None


def _fracture(solid, *, params: BreakParams, diag: float, rng) -> tuple[list, set[int]]:
    """Cut ``solid`` into ``params.pieces`` parts; returns the parts and the cutters' IDs."""
    total = solid.volume()
    pieces = [solid]
    cut_ids: set[int] = set()
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
        parts, cut_id = result
        pieces[i : i + 1] = parts
        cut_ids.add(cut_id)
    return pieces, cut_ids


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
        back to the (scaled) input mesh's frame.
    """
    import manifold3d as mf

    params.check()
    vertices = np.asarray(vertices, dtype=np.float64) * params.scale
    faces = np.asarray(faces, dtype=np.uint32)
    solid = mf.Manifold(mf.Mesh64(vert_properties=np.ascontiguousarray(vertices), tri_verts=faces))
    if solid.status() != mf.Error.NoError or solid.is_empty():
        raise ReassembleError(f"mesh is not a valid solid for booleans ({solid.status().name})")
    solid = solid.as_original()
    object_id = solid.original_id()
    bbox_min, bbox_max = vertices.min(axis=0), vertices.max(axis=0)
    diag = float(np.linalg.norm(bbox_max - bbox_min))
    volume, area = solid.volume(), solid.surface_area()

    # one stream per stage: noise, chips or decimation never change the cuts or the poses
    cut_rng, chip_rng, pose_rng, noise_rng = rng.spawn(4)
    pieces, cut_ids = _fracture(solid, params=params, diag=diag, rng=cut_rng)
    damage_ids = set(cut_ids)
    if params.chips > 0:
        chipped = []
        for piece in pieces:
            piece, ids = _chip(piece, cut_ids=cut_ids, params=params, diag=diag, rng=chip_rng)
            damage_ids |= ids
            chipped.append(piece)
        pieces = chipped
    if params.decimate > 0:
        pieces = [p.simplify(params.decimate * diag) for p in pieces]

    names = [f"fragment_{k:02d}" for k in pose_rng.permutation(len(pieces))]
    world = []
    for name, piece in zip(names, pieces):
        v, f, origin = _mesh_arrays(piece)
        labels = np.where(origin == object_id, ORIGINAL, FRACTURE).astype(np.int8)
        if not np.all(np.isin(origin, list(damage_ids | {object_id}))):
            raise RuntimeError("manifold3d lost the origin of some triangles")
        world.append((name, v, f, labels))
    contacts = _contacts(world, tol=max(1e-5, 2.0 * params.decimate) * diag)
    if params.gap > 0:  # after the contacts: they are the true neighbours, gap or not
        world = [(name, _erode(v, f, labels == FRACTURE, 0.5 * params.gap * diag), f, labels)
                 for name, v, f, labels in world]

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
    contacts.sort(key=lambda c: (c.a, c.b))
    stats = {"cuts": len(cut_ids), "chips": len(damage_ids) - len(cut_ids)}
    log.info("broke into %d fragments with %d cuts, %d chips", len(fragments), stats["cuts"], stats["chips"])
    return Puzzle(fragments, contacts, bbox_min, bbox_max, float(volume), float(area), stats)
