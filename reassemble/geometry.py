"""Small geometric primitives shared by every stage: rigid transforms, areas, surface sampling.

Transforms are 4x4 homogeneous matrices acting on column vectors and are named by
direction: ``T_world_fragment`` maps fragment coordinates to world coordinates.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Build a 4x4 rigid transform.

    Parameters
    ----------
    R : (3, 3) float
        Rotation matrix.
    t : (3,) float
        Translation.

    Returns
    -------
    T : (4, 4) float
    """
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def invert_transform(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (exact for rotations, no general matrix inverse)."""
    R = T[:3, :3]
    return make_transform(R.T, -R.T @ T[:3, 3])


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (n, 3) points; returns a new (n, 3) array."""
    points = np.asarray(points, dtype=np.float64)
    return points @ T[:3, :3].T + T[:3, 3]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix drawn uniformly from SO(3)."""
    return Rotation.random(random_state=rng).as_matrix()


def rotation_from_vector(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` (3,) (Rodrigues): the step of a linearized solve."""
    angle = float(np.linalg.norm(w))
    if angle < 1e-15:
        return np.eye(3)
    k = w / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def is_rigid(T: np.ndarray, *, atol: float = 1e-6) -> bool:
    """True when ``T`` is a finite 4x4 proper rigid transform."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return False
    R = T[:3, :3]
    return (
        np.allclose(R.T @ R, np.eye(3), atol=atol)
        and abs(np.linalg.det(R) - 1.0) < atol
        and np.allclose(T[3], [0, 0, 0, 1], atol=atol)
    )


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Geodesic angle in degrees between rotations, batched over leading axes.

    Parameters
    ----------
    R_a, R_b : (..., 3, 3) float

    Returns
    -------
    angle : (...) float, in [0, 180]
    """
    R_rel = np.swapaxes(R_a, -1, -2) @ R_b
    # atan2 of the skew and symmetric parts: accurate near 0 and 180 degrees, unlike arccos
    skew = np.stack([R_rel[..., 2, 1] - R_rel[..., 1, 2], R_rel[..., 0, 2] - R_rel[..., 2, 0],
                     R_rel[..., 1, 0] - R_rel[..., 0, 1]], axis=-1)
    sin2 = np.linalg.norm(skew, axis=-1)
    cos2 = np.trace(R_rel, axis1=-2, axis2=-1) - 1.0
    return np.degrees(np.arctan2(sin2, cos2))


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area of each triangle: (m,) from (n, 3) vertices and (m, 3) faces."""
    v = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) unit outward normals of the triangles (zero for collapsed ones)."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def tet_volumes(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed volume of the tetrahedron (origin, triangle) of each face: (m,); their sum is the
    mesh's volume, positive for an outward-oriented closed mesh."""
    t = np.asarray(vertices, dtype=np.float64)[faces]
    return np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6.0


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed triangle mesh (negative when its faces point inwards)."""
    return float(tet_volumes(vertices, faces).sum())


def face_adjacency(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of faces sharing an edge and that edge's vertices.

    Returns
    -------
    pairs : (e, 2) int, face indices
    edges : (e, 2) int, vertex indices of the shared edge
    """
    f = len(faces)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(f), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, owner = e[order], owner[order]
    same = np.flatnonzero(np.all(e[1:] == e[:-1], axis=1))
    # non-manifold edges (more than two faces) pair consecutive owners: good enough here
    return np.column_stack([owner[same], owner[same + 1]]), e[same]


def connected_components(n: int, pairs: np.ndarray) -> tuple[int, np.ndarray]:
    """(count, (n,) label) of the graph on n nodes with edges ``pairs`` (e, 2)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components as components

    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return components(graph, directed=False)


def make_scene(vertices: np.ndarray, faces: np.ndarray):
    """An Open3D ray-casting scene (BVH) of a triangle mesh, for rays and distance queries."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        np.ascontiguousarray(vertices, dtype=np.float32), np.ascontiguousarray(faces, dtype=np.uint32)
    )
    return scene


def vertex_noise(vertices: np.ndarray, *, neighbours: int = 16, percentile: float = 25.0,
                 chunk: int = 50000) -> float:
    """The standard deviation of a mesh's vertex noise along the normal (mesh units).

    At every vertex a quadric height field is fitted to its ``neighbours`` nearest vertices
    (least squares in the local principal frame); the RMS residual, corrected for the six
    fitted coefficients, is the noise there plus whatever the surface does beyond a quadric.
    The ``percentile``-th value over the vertices is taken, where the surface is smoothest.
    On a smooth surface with pure noise that reads 0.82 sigma (the quartile of a chi
    distribution with 10 degrees of freedom); where the geometry adds its share it reads
    more (``python -m benchmarks.accuracy.noise_estimate`` compares it with the added noise).
    """
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    k = min(neighbours, len(v))
    if k <= 6:
        return 0.0
    _, idx = cKDTree(v).query(v, k=k)
    rms = []
    for start in range(0, len(v), chunk):
        P = v[idx[start:start + chunk]] - v[start:start + chunk, None, :]
        Q = P - P.mean(axis=1, keepdims=True)
        _, U = np.linalg.eigh(np.einsum("nki,nkj->nij", Q, Q))  # ascending: U[..., 0] is the normal
        L = np.einsum("nki,nij->nkj", P, U)
        h, x, y = L[..., 0], L[..., 1], L[..., 2]
        A = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
        AtA = np.einsum("nki,nkj->nij", A, A)
        AtA += 1e-12 * np.trace(AtA, axis1=1, axis2=2)[:, None, None] * np.eye(6)  # degenerate neighbourhoods
        coef = np.linalg.solve(AtA, np.einsum("nki,nk->ni", A, h)[..., None])[..., 0]
        r = h - np.einsum("nki,ni->nk", A, coef)
        rms.append(np.sqrt((r ** 2).sum(axis=1) / (k - 6)))
    return float(np.percentile(np.concatenate(rms), percentile))


def taubin_smooth(vertices: np.ndarray, faces: np.ndarray, iterations: int) -> np.ndarray:
    """(n, 3) vertices after ``iterations`` of Taubin smoothing (no shrinkage), a new array."""
    import trimesh

    mesh = trimesh.Trimesh(np.array(vertices, dtype=np.float64, copy=True), faces, process=False)
    if iterations > 0:
        trimesh.smoothing.filter_taubin(mesh, lamb=0.5, nu=0.53, iterations=iterations)
    return np.asarray(mesh.vertices, dtype=np.float64)


def denoise(
    vertices: np.ndarray, faces: np.ndarray, *, target: float, step: int = 5, max_iterations: int = 40
) -> tuple[np.ndarray, int]:
    """Taubin-smooth a mesh, ``step`` iterations at a time, until its measured vertex noise
    (:func:`vertex_noise`) is at most ``target`` (mesh units) or ``max_iterations`` are done.

    Returns
    -------
    vertices : (n, 3) smoothed vertices (a new array; the faces are unchanged)
    iterations : int, how many were applied
    """
    v, done = np.array(vertices, dtype=np.float64, copy=True), 0
    while done < max_iterations and vertex_noise(v) > target:
        v = taubin_smooth(v, faces, step)
        done += step
    return v, done


def decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) simplified to about ``target_faces`` triangles (quadric error
    decimation, Open3D); the mesh itself when it has no more than that. New arrays."""
    if len(faces) <= target_faces:
        return np.array(vertices, dtype=np.float64, copy=True), np.array(faces, dtype=np.int64, copy=True)
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(vertices, np.float64)),
                                     o3d.utility.Vector3iVector(np.asarray(faces, np.int32)))
    small = mesh.simplify_quadric_decimation(target_number_of_triangles=int(target_faces))
    return np.asarray(small.vertices, np.float64), np.asarray(small.triangles, np.int64)


def farthest_points(points: np.ndarray, count: int) -> np.ndarray:
    """Indices of up to ``count`` points spread over ``points`` (n, 3): greedy farthest-point
    order from the point nearest the centroid (deterministic)."""
    n = len(points)
    if n == 0:
        return np.zeros(0, int)
    chosen = [int(np.argmin(np.linalg.norm(points - points.mean(axis=0), axis=1)))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(min(count, n) - 1):
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return np.asarray(chosen)


def sample_surface(
    vertices: np.ndarray, faces: np.ndarray, count: int, *, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Points drawn uniformly by area on a triangle mesh.

    Returns
    -------
    points : (count, 3) float
    face_index : (count,) int, the triangle each point lies on
    """
    areas = face_areas(vertices, faces)
    cdf = np.cumsum(areas)
    face_index = np.searchsorted(cdf, rng.random(count) * cdf[-1], side="right")
    face_index = np.minimum(face_index, len(faces) - 1)
    u, v = rng.random((2, count))
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    tri = vertices[faces[face_index]]
    points = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    return points, face_index


def canonical_order(
    vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reorder vertices lexicographically and faces by their vertex indices.

    Makes files byte-identical whatever order a (multi-threaded) library produced.

    Returns
    -------
    vertices : (n, 3) reordered copy
    faces : (m, 3) re-indexed, each rotated to start at its smallest index, rows sorted
    face_order : (m,) int, ``faces_new[i]`` came from ``faces[face_order[i]]``
    """
    v_order = np.lexsort(vertices.T[::-1])
    new_index = np.empty_like(v_order)
    new_index[v_order] = np.arange(len(v_order))
    f = new_index[faces]
    shift = np.argmin(f, axis=1)
    rows = np.arange(len(f))[:, None]
    f = f[rows, (shift[:, None] + np.arange(3)) % 3]  # keep orientation
    face_order = np.lexsort(f.T[::-1])
    return vertices[v_order], f[face_order], face_order
