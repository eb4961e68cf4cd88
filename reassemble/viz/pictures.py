"""The pictures of a run, each from arrays: a fragment's labels and curvature, a match
pulled apart and in contact, the assembly from several sides and exploded.

Every function takes an open :class:`~reassemble.viz.render.Renderer` and returns an
(h, w, 3) uint8 image; files are the orchestrator's business.
"""

from __future__ import annotations

import numpy as np

from ..geometry import transform_points
from .colors import FRACTURE_RGB, ORIGINAL_RGB, diverging, shade
from .render import Renderer, Shape, caption, grid, perpendicular, principal_axes, views, with_colorbar


def label_colors(fracture: np.ndarray) -> np.ndarray:
    """(m, 3) uint8 per-face colours: fracture red, original surface grey."""
    return np.where(np.asarray(fracture, bool)[:, None], FRACTURE_RGB, ORIGINAL_RGB).astype(np.uint8)


def curvature_limit(values: np.ndarray) -> float:
    """Colour-scale limit of a signed curvature: the 98th percentile of its magnitude, so a
    few spikes along sharp edges do not wash out the rest."""
    finite = np.abs(values[np.isfinite(values)])
    return float(np.percentile(finite, 98)) if len(finite) and np.any(finite > 0) else 1.0


def fragment_picture(
    renderer: Renderer,
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    fracture: np.ndarray,
    H: np.ndarray | None,
    title: str,
    H_title: str = "H",
) -> np.ndarray:
    """One fragment from both sides of its broad face: top row fracture (red) / original
    (grey), bottom row mean curvature ``H`` (m,) per face with a colour bar (omitted when
    ``H`` is None: the fragment had no descriptors)."""
    e1, e2, e3 = principal_axes(vertices)
    sides = [(e3, e2, "front"), (-e3, e2, "back")]
    labels = Shape(vertices, faces, label_colors(fracture))
    row = [caption(renderer.render([labels], front=f, up=u), f"{title}: fracture (red), {n}") for f, u, n in sides]
    tiles = grid(row, columns=2)
    if H is None:
        return tiles
    limit = curvature_limit(H)
    curved = Shape(vertices, faces, diverging(H, limit))
    row = [caption(renderer.render([curved], front=f, up=u), f"{title}: mean curvature, {n}") for f, u, n in sides]
    curvature = with_colorbar(grid(row, columns=2), limit=limit, title=H_title)
    pad = np.full((tiles.shape[0], curvature.shape[1] - tiles.shape[1], 3), 255, np.uint8)
    return np.vstack([np.hstack([tiles, pad]), curvature])


def _posed(vertices, faces, T, color, fracture) -> Shape:
    """A fragment at pose ``T`` in its colour, its fracture faces darker."""
    colors = np.tile(np.asarray(color, np.uint8), (len(faces), 1))
    if fracture is not None:
        colors[np.asarray(fracture, bool)] = shade(color, 0.6)
    return Shape(transform_points(T, vertices), faces, colors)


def match_picture(
    renderer: Renderer,
    meshes: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    T_world: tuple[np.ndarray, np.ndarray],
    *,
    points: tuple[np.ndarray, np.ndarray],
    colors: tuple[np.ndarray, np.ndarray],
    fracture: tuple[np.ndarray | None, np.ndarray | None] = (None, None),
    title: str,
) -> np.ndarray:
    """Two touching fragments: left pulled apart along the contact with lines between the
    touching points, right in contact, seen across the pull direction.

    ``points``: ((k, 3) on a in a's coordinates, (k, 3) on b in b's coordinates).
    """
    (va, fa), (vb, fb) = meshes
    Ta, Tb = (np.asarray(T, dtype=float) for T in T_world)
    pa, pb = transform_points(Ta, points[0]), transform_points(Tb, points[1])
    ca, cb = transform_points(Ta, va).mean(axis=0), transform_points(Tb, vb).mean(axis=0)
    both = np.vstack([transform_points(Ta, va), transform_points(Tb, vb)])
    direction = (pb.mean(axis=0) - ca) if len(pa) else (cb - ca)
    direction = direction if np.linalg.norm(direction) > 0 else np.array([1.0, 0.0, 0.0])
    direction = direction / np.linalg.norm(direction)
    span = float(np.linalg.norm(np.ptp(both, axis=0)))
    pull = np.eye(4)
    pull[:3, 3] = 0.6 * span * direction
    front, up = perpendicular(direction, both)
    a = _posed(va, fa, Ta, colors[0], fracture[0])
    apart = [a, _posed(vb, fb, pull @ Tb, colors[1], fracture[1])]
    left = renderer.render(apart, front=front, up=up, lines=(pa, pa + pull[:3, 3]) if len(pa) else None)
    left = caption(left, f"{title}: pulled apart, {len(pa)} touching points")
    right = caption(renderer.render([a, _posed(vb, fb, Tb, colors[1], fracture[1])], front=front, up=up),
                    f"{title}: in contact")
    return grid([left, right], columns=2)


def posed_shapes(meshes: list[tuple[np.ndarray, np.ndarray]], T_world: np.ndarray, *, colors: np.ndarray) -> list[Shape]:
    """Every fragment at its pose ``T_world`` (n, 4, 4), each in its own colour."""
    return [_posed(v, f, T, c, None) for (v, f), T, c in zip(meshes, T_world, colors)]


def assembly_pictures(
    renderer: Renderer,
    meshes: list[tuple[np.ndarray, np.ndarray]],
    T_world: np.ndarray,
    *,
    placed: np.ndarray,
    colors: np.ndarray,
    explode: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(views, exploded): the whole result from six sides (unplaced fragments where
    ``T_world`` put them, beside the assembly), and the placed fragments pushed outward
    from the assembly's centre by ``explode`` times their offset from it."""
    shapes = posed_shapes(meshes, T_world, colors=colors)
    everything = np.vstack([s.vertices for s in shapes])
    tiles = [caption(renderer.render(shapes, front=f, up=u), n) for n, f, u in views(everything)]
    main = [k for k in range(len(meshes)) if placed[k]] or list(range(len(meshes)))
    centre = np.vstack([shapes[k].vertices for k in main]).mean(axis=0)
    pushed = [Shape(shapes[k].vertices + explode * (shapes[k].vertices.mean(axis=0) - centre), shapes[k].faces,
                    shapes[k].face_colors) for k in main]
    spread = np.vstack([s.vertices for s in pushed])
    exploded = [caption(renderer.render(pushed, front=f, up=u), f"exploded, {n}")
                for n, f, u in views(spread) if n in ("front", "three-quarter")]
    return grid(tiles, columns=3), grid(exploded, columns=2)


__all__ = [
    "assembly_pictures", "curvature_limit", "fragment_picture", "label_colors", "match_picture", "posed_shapes",
]
