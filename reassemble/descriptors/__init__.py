"""Integral invariants: voxel grids (voxelize), ball kernels (kernels), V/P/D2 -> curvatures (invariants)."""

from .invariants import (  # noqa: F401
    DescriptorParams,
    Descriptors,
    curvature_difference_sq,
    integral_invariants,
    mean_curvature,
    robust_mean_curvature,
)
