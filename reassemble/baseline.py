"""The "Open3D textbook" peer baseline: FPFH + RANSAC global registration refined by ICP.

Follows Open3D's *Global registration* tutorial step by step (voxel downsampling, normals
within 2 voxels, FPFH within 5 voxels, RANSAC on feature matches, point-to-plane ICP), so
benchmarks can compare the pipeline against what a reader of that tutorial would get.
"""

from __future__ import annotations

import contextlib
import logging

import numpy as np

from .geometry import face_normals, invert_transform, sample_surface

log = logging.getLogger(__name__)


@contextlib.contextmanager
def _single_threaded(o3d):
    """Run Open3D on one thread: its RANSAC threads share one random generator and its ICP
    sums in parallel, so only then do equal seeds give bit-identical results. The limit is
    process-wide, hence restored on exit."""
    if not hasattr(o3d.utility, "set_max_threads"):  # older Open3D: no thread limit to set
        yield
        return
    threads = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield
    finally:
        o3d.utility.set_max_threads(threads)


def _point_cloud(vertices: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator):
    """An Open3D cloud of ``count`` points drawn uniformly on the mesh, with face normals."""
    import open3d as o3d

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    points, face_index = sample_surface(vertices, faces, count, rng=rng)
    normals = face_normals(vertices, faces)[face_index]
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.normals = o3d.utility.Vector3dVector(normals)
    return pcd


def _preprocess(pcd, voxel: float):
    """Tutorial ``preprocess_point_cloud``: downsample, re-estimate normals, FPFH."""
    import open3d as o3d

    down = pcd.voxel_down_sample(voxel)
    # the averaged face normals already present orient the estimated ones consistently
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.0 * voxel, max_nn=30))
    fpfh = o3d.pipelines.registration.compute_fpfh_feature(
        down, o3d.geometry.KDTreeSearchParamHybrid(radius=5.0 * voxel, max_nn=100)
    )
    return down, fpfh


def fpfh_register(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    *,
    voxel: float,
    n_points: int = 20000,
    seed: int = 0,
) -> tuple[np.ndarray, float]:
    """Register a source mesh onto a target mesh with FPFH + RANSAC + point-to-plane ICP.

    Parameters
    ----------
    source_vertices, target_vertices : (n, 3) float
    source_faces, target_faces : (m, 3) int
        Triangle meshes; they are not modified.
    voxel : float
        Downsampling voxel size; every other radius and threshold is a multiple of it.
    n_points : int
        Points sampled uniformly on each surface before downsampling.
    seed : int
        Seeds the surface sampling and Open3D's RANSAC; equal seeds give equal results.

    Returns
    -------
    T_target_source : (4, 4) float64
        Maps source coordinates into the target's frame.
    fitness : float
        Final ICP fitness in [0, 1]: the fraction of source points with a target point
        within ``0.4 * voxel``.
    """
    import open3d as o3d

    rng = np.random.default_rng(seed)
    source = _point_cloud(source_vertices, source_faces, n_points, rng)
    target = _point_cloud(target_vertices, target_faces, n_points, rng)
    source_down, source_fpfh = _preprocess(source, voxel)
    target_down, target_fpfh = _preprocess(target, voxel)

    reg = o3d.pipelines.registration
    distance = 1.5 * voxel
    with _single_threaded(o3d):
        if hasattr(o3d.utility, "random"):
            o3d.utility.random.seed(seed)
        ransac = reg.registration_ransac_based_on_feature_matching(
            source_down, target_down, source_fpfh, target_fpfh, False, distance,
            reg.TransformationEstimationPointToPoint(False), 3,
            [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
             reg.CorrespondenceCheckerBasedOnDistance(distance)],
            reg.RANSACConvergenceCriteria(100000, 0.999),
        )
        icp = reg.registration_icp(
            source, target, 0.4 * voxel, ransac.transformation,
            reg.TransformationEstimationPointToPlane(),
        )
    log.debug("fpfh_register: ransac fitness %.3f, icp fitness %.3f rmse %.3g",
              ransac.fitness, icp.fitness, icp.inlier_rmse)
    return np.array(icp.transformation, dtype=np.float64), float(icp.fitness)


def fpfh_assemble(
    meshes: list[tuple[np.ndarray, np.ndarray]], *, voxel: float, seed: int = 0
) -> list[np.ndarray]:
    """Textbook multi-piece baseline: pairwise FPFH registration glued by a spanning tree.

    Every pair is registered with :func:`fpfh_register`; the maximum spanning tree of the
    fitness graph is kept, fragment 0 is anchored at the identity, and transforms are
    composed outwards along the tree.

    Parameters
    ----------
    meshes : list of ((n_i, 3) float vertices, (m_i, 3) int faces)
    voxel : float
        Passed to :func:`fpfh_register`.
    seed : int
        Passed to :func:`fpfh_register`.

    Returns
    -------
    T_world_fragment : list of (4, 4) float64, one per mesh (the first is the identity)
    """
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    n = len(meshes)
    pair: dict[tuple[int, int], np.ndarray] = {}  # (i, j), i < j -> T_i_j
    weight = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            pair[i, j], fitness = fpfh_register(*meshes[j], *meshes[i], voxel=voxel, seed=seed)
            # offset so zero-fitness pairs stay edges (csgraph drops zero weights): always spanning
            weight[i, j] = -(fitness + 1.0)
            log.info("fpfh_assemble: pair (%d, %d) fitness %.3f", i, j, fitness)
    poses = [np.eye(4) for _ in range(n)]
    if n < 2:
        return poses
    tree = minimum_spanning_tree(weight)
    order, parent = breadth_first_order(tree, 0, directed=False)
    for child in order[1:]:
        p = parent[child]
        T_p_c = pair[p, child] if p < child else invert_transform(pair[child, p])
        poses[child] = poses[p] @ T_p_c
    return poses
