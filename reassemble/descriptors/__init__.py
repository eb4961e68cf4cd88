"""Integral invariants: voxel grids (voxelize), ball kernels (kernels), V/P/D2/SA/D -> curvatures and normals (invariants)."""

from .invariants import (  # noqa: F401
    DescriptorParams,
    Descriptors,
    curvature_difference_sq,
    integral_invariants,
    mean_curvature,
    normal_from_area,
    robust_mean_curvature,
    signed_distance_mean_curvature,
    sphere_area_mean_curvature,
    sphere_curvature_difference_sq,
)
