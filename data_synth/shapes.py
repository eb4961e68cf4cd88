"""Analytic test shapes as closed, outward-oriented triangle meshes, and their exact curvatures.

Every vertex lies on the analytic surface (to float64 rounding), so the meshes differ
from their surfaces only by the flatness of the triangles: the descriptor benchmarks
compare against exact references computed on the analytic surfaces.

    python -m data_synth.shapes          # self-check: closed, manifold, oriented, on the surface
"""

from __future__ import annotations

import numpy as np

from reassemble.geometry import signed_volume


def torus_mesh(
    R: float = 1.0,
    a: float = 0.45,
    n_major: int | None = None,
    n_minor: int | None = None,
    *,
    target_vertices: int = 70_000,
) -> tuple[np.ndarray, np.ndarray]:
    """A torus about the z axis: tube radius ``a`` around the circle of radius ``R``.

    Vertex (i, j) is at ``u = 2 pi (i + j/2) / n_major`` around the z axis and
    ``v = 2 pi j / n_minor`` around the tube: odd rings are staggered by half a step, so
    the triangles are close to equilateral on the tube's top and bottom circles
    (cos v = 0) when ``n_major / n_minor = (sqrt(3)/2) R / a``, the default. They stretch
    by (R + a cos v)/R towards the outer and inner equators, as on any (u, v) grid.

    Parameters
    ----------
    R, a : major and minor radii, ``0 < a < R``
    n_major, n_minor : vertices around the z axis and around the tube (n_minor even);
        by default chosen from ``target_vertices``
    target_vertices : about how many vertices (n_major * n_minor) when the counts are not given

    Returns
    -------
    vertices (n_major * n_minor, 3) float64, faces (2 n_major n_minor, 3) int64, outward
    """
    if not 0 < a < R:
        raise ValueError(f"need 0 < a < R (got R={R}, a={a})")
    ratio = np.sqrt(3.0) / 2.0 * R / a
    if n_minor is None:
        n_minor = int(round(np.sqrt(target_vertices / ratio) / 2.0)) * 2
    if n_major is None:
        n_major = int(round(n_minor * ratio))
    if n_minor < 4 or n_minor % 2 or n_major < 3:
        raise ValueError(f"need an even n_minor >= 4 and n_major >= 3 (got {n_major}, {n_minor})")
    i = np.arange(n_major)
    j = np.arange(n_minor)
    u = 2.0 * np.pi * (i[:, None] + 0.5 * (j[None, :] % 2)) / n_major  # (n_major, n_minor)
    v = np.broadcast_to(2.0 * np.pi * j[None, :] / n_minor, u.shape)
    rho = R + a * np.cos(v)
    vertices = np.stack([rho * np.cos(u), rho * np.sin(u), a * np.sin(v)], axis=-1).reshape(-1, 3)

    def vid(ii, jj):
        return (ii % n_major) * n_minor + (jj % n_minor)

    I, J = np.meshgrid(i, j, indexing="ij")
    I, J = I.ravel(), J.ravel()
    even = (J % 2) == 0  # ring j+1 is shifted by +1/2 step relative to ring j when j is even
    # (u, v) is orientation-preserving for the outward normal: counter-clockwise in (u, v)
    f1 = np.where(even[:, None],
                  np.stack([vid(I, J), vid(I + 1, J), vid(I, J + 1)], axis=1),
                  np.stack([vid(I, J), vid(I + 1, J), vid(I + 1, J + 1)], axis=1))
    f2 = np.where(even[:, None],
                  np.stack([vid(I, J + 1), vid(I + 1, J), vid(I + 1, J + 1)], axis=1),
                  np.stack([vid(I, J), vid(I + 1, J + 1), vid(I, J + 1)], axis=1))
    faces = np.vstack([f1, f2]).astype(np.int64)
    return vertices.astype(np.float64), faces


def torus_angles(points: np.ndarray, R: float, a: float) -> tuple[np.ndarray, np.ndarray]:
    """(cos v, sin v) of the tube angle of points (on or near the torus): the direction
    from the nearest point of the core circle."""
    points = np.asarray(points, dtype=np.float64)
    dr = np.hypot(points[:, 0], points[:, 1]) - R
    z = points[:, 2]
    n = np.hypot(dr, z)
    return dr / n, z / n


def torus_curvatures(points: np.ndarray, R: float, a: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact (H, K2) of the torus at points on it (or at their nearest torus points).

    kappa1 = 1/a (around the tube), kappa2 = cos v / (R + a cos v) (around the z axis),
    H = (kappa1 + kappa2)/2 (positive for convex), K2 = (kappa1 - kappa2)^2.
    """
    cos_v, _ = torus_angles(points, R, a)
    k1 = 1.0 / a
    k2 = cos_v / (R + a * cos_v)
    return 0.5 * (k1 + k2), (k1 - k2) ** 2


def project_to_torus(points: np.ndarray, R: float, a: float) -> np.ndarray:
    """Nearest points of the torus surface (points off the z axis and the core circle)."""
    points = np.asarray(points, dtype=np.float64)
    phi = np.arctan2(points[:, 1], points[:, 0])
    cos_v, sin_v = torus_angles(points, R, a)
    rho = R + a * cos_v
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), a * sin_v])


def torus_sdf(points: np.ndarray, R: float, a: float) -> np.ndarray:
    """Signed distance to the torus, negative inside."""
    points = np.asarray(points, dtype=np.float64)
    return np.hypot(np.hypot(points[..., 0], points[..., 1]) - R, points[..., 2]) - a


def sphere_mesh(subdivisions: int = 5, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Icosphere (vertices on the sphere of the given radius), outward.

    Subdivisions 5, 6, 7 give 10 242, 40 962, 163 842 vertices.
    """
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    v = np.asarray(m.vertices, dtype=np.float64)
    v *= radius / np.linalg.norm(v, axis=1, keepdims=True)  # exactly on the sphere
    return v, np.asarray(m.faces, dtype=np.int64)


def box_mesh(size=4.0) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box centred at the origin (12 triangles), outward; ``size`` a scalar or
    three edge lengths. Points near a face centre see a plane for balls smaller than the
    distance to the face's edges."""
    import trimesh

    extents = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    m = trimesh.creation.box(extents=extents)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def vase_mesh(*, wall: float = 0.05, segments: int = 96, rows: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """A thin-walled pot (surface of revolution about +z, 2 high): flat base, a belly of
    radius 0.8, a neck of 0.36 and a flared rim, walls ``wall`` thick, open at the top.

    The sherd shape the synthetic puzzles otherwise lack (every bench mesh is a solid).
    ``segments`` around, ``rows`` up the profile.
    """
    return _vessel([0.0, 0.3, 0.9, 1.5, 1.8, 2.0], [0.42, 0.68, 0.80, 0.52, 0.36, 0.44],
                   wall=wall, segments=segments, rows=rows)


def bowl_mesh(*, wall: float = 0.04, segments: int = 96, rows: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A thin-walled open bowl (about +z, 0.7 high): flat base of radius 0.3 widening to a
    rim of radius 1, walls ``wall`` thick. A second sherd shape, unlike the pot: shallow,
    no neck, wide open, so its fragments are gently curved plates."""
    return _vessel([0.0, 0.1, 0.3, 0.55, 0.7], [0.30, 0.50, 0.78, 0.95, 1.0],
                   wall=wall, segments=segments, rows=rows)


def tile_mesh(*, thickness: float = 0.05, segments: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """A flat tile (1 by 0.7, ``thickness`` thick) with rounded corners, a raised border
    frame 0.05 wide and 0.02 high on top, and two nail holes: a flat sherd shape (tiles,
    plaques, tablets), meshed as CAD is, with a few large triangles per face."""
    import manifold3d as m3

    slab = m3.Manifold.cube([1.0, 0.7, thickness], center=True)
    corners = [m3.Manifold.cylinder(thickness + 0.01, 0.06, circular_segments=segments)
               .translate([sx * 0.44, sy * 0.29, -(thickness + 0.01) / 2]) for sx in (-1, 1) for sy in (-1, 1)]
    slab = slab ^ m3.Manifold.batch_hull(corners)
    frame = m3.Manifold.cube([0.96, 0.66, 0.02], center=True) - m3.Manifold.cube([0.86, 0.56, 0.03], center=True)
    tile = slab + frame.translate([0.0, 0.0, thickness / 2 + 0.009])
    for x in (-0.3, 0.3):
        tile = tile - m3.Manifold.cylinder(4 * thickness, 0.02, circular_segments=segments // 4 * 3).translate(
            [x, 0.2, -2 * thickness])
    mesh = tile.to_mesh()
    return np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64)


def flange_mesh(*, thickness: float = 0.1, segments: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """A flat annular flange (outer radius 1, bore 0.45, ``thickness`` thick) with a collar
    0.08 wide and 0.12 high round the bore, eight bolt holes on the 0.72 circle and a key
    notch in the outer rim: a flat ring of CAD (gaskets, flanges, washers), meshed as CAD
    is, with a few large triangles per face."""
    import manifold3d as m3

    def disk(radius, height, z=0.0, n=segments):
        return m3.Manifold.cylinder(height, radius, circular_segments=n).translate([0.0, 0.0, z])

    ring = disk(1.0, thickness) - disk(0.45, 3 * thickness, -thickness)
    ring = ring + (disk(0.53, 0.12, thickness) - disk(0.45, 0.2, thickness - 0.05))
    for k in range(8):
        a = 2.0 * np.pi * (k + 0.5) / 8
        ring = ring - disk(0.06, 3 * thickness, -thickness, segments // 3).translate(
            [0.72 * np.cos(a), 0.72 * np.sin(a), 0.0])
    ring = ring - m3.Manifold.cube([0.2, 0.16, 3 * thickness], center=True).translate([1.0, 0.0, 0.0])
    mesh = ring.to_mesh()
    return np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64)


def _vessel(z_ctrl, r_ctrl, *, wall: float, segments: int, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed solid of revolution: the outer profile r(z) through the control points, the
    inner one ``wall`` in from it, a flat base ``wall`` thick, open at the top."""
    import manifold3d as m3
    from scipy.interpolate import PchipInterpolator

    height = z_ctrl[-1]
    radius = PchipInterpolator(z_ctrl, r_ctrl)
    z = np.linspace(0.0, height, rows)
    outer = np.column_stack([radius(z), z])
    zi = np.linspace(height, wall, rows)
    inner = np.column_stack([radius(zi) - wall, zi])  # horizontal offset: about the wall's thickness
    profile = np.vstack([[[0.0, 0.0]], outer, inner, [[0.0, wall]]])
    solid = m3.Manifold.revolve(m3.CrossSection([profile]), circular_segments=segments)
    mesh = solid.to_mesh()
    return np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64)


def is_closed_manifold(faces: np.ndarray) -> bool:
    """Every directed edge appears exactly once and its reverse exactly once: closed,
    edge-manifold and consistently oriented."""
    faces = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if np.any(e[:, 0] == e[:, 1]):
        return False
    n = int(faces.max()) + 1
    key = e[:, 0] * n + e[:, 1]
    rev = e[:, 1] * n + e[:, 0]
    uniq, counts = np.unique(key, return_counts=True)
    if np.any(counts != 1):
        return False
    return bool(np.all(np.isin(rev, uniq)))


def _self_check() -> None:
    R, a = 1.0, 0.45
    v, f = torus_mesh(R, a)
    vol, exact = signed_volume(v, f), 2 * np.pi**2 * R * a * a
    print(f"torus: {len(v)} vertices, {len(f)} faces; closed manifold oriented: {is_closed_manifold(f)}; "
          f"volume {vol:.6f} (exact {exact:.6f}); max |sdf| at vertices {np.abs(torus_sdf(v, R, a)).max():.1e}; "
          f"Euler characteristic {len(v) - len(f) // 2 * 3 + len(f)}")
    assert is_closed_manifold(f) and 0.99 * exact < vol < exact
    v, f = sphere_mesh(4)
    vol = signed_volume(v, f)
    print(f"sphere: {len(v)} vertices; closed manifold oriented: {is_closed_manifold(f)}; volume {vol:.5f} "
          f"(ball {4 * np.pi / 3:.5f}); max ||v| - 1| {np.abs(np.linalg.norm(v, axis=1) - 1).max():.1e}")
    assert is_closed_manifold(f) and 0.99 * 4 * np.pi / 3 < vol < 4 * np.pi / 3
    v, f = box_mesh(3.0)
    print(f"box: closed manifold oriented: {is_closed_manifold(f)}; volume {signed_volume(v, f):.6f} (27)")
    assert is_closed_manifold(f) and abs(signed_volume(v, f) - 27.0) < 1e-9


if __name__ == "__main__":
    _self_check()
