"""Multi-scale integral invariants V_r, P_r, D2_r, SA_r, D_r, SD2_r, the area vector, and the
curvatures and normals they estimate.

For a closed surface bounding the solid D, a query point p and a kernel radius r
(Pottmann et al. 2009, Sections 5, 7 and 9.1):

- ``V_r(p)``  = vol(ball(p, r) ∩ D);  ``H = 8/(3r) - 4 V_r/(pi r^4)``  (Eq. 19)
- ``P_r(p)``  = ∫ over ball ∩ D of |x - p|^2;
  ``H_rob = 12 V_r/(pi r^4) + 8/(5r) - 24 P_r/(pi r^6)``: a point a distance δ off the
  surface changes V_r by π r² δ and P_r by π r⁴ δ / 2, which cancel here, so scan noise
  and the sagitta of coarse meshes do not bias it to first order.
- ``D2_r(p)`` = ∫ over the ball of dist(x, surface)^2;
  ``K2 = (kappa1 - kappa2)^2 = (28 pi r^5 - 105 D2_r) / (pi r^7)``  (Eq. 32)
- ``SA_r(p)`` = area of the sphere p + rS inside the solid = dV_r/dr;
  ``H_SA = 2/r - SA_r/(pi r^3)``  (Eqs. 18-19)
- ``D_r(p)`` = ∫ over the ball of the signed distance (> 0 outside) = 4 pi H r^5/15 + O(r^6)
  (Theorem 4); ``SD2_r(p)`` = ∫ over the sphere p + rS of dist^2 = dD2_r/dr;
  ``(kappa1 - kappa2)^2 = (20 pi r^4 - 15 SD2_r)/(pi r^6)``  (Eq. 33)
- the area vector ``a_r(p) = grad V_r(p) = pi (r^2 - (3H^2 - K) r^4/8) n_in + O(r^5)``
  (Theorem 2, n_in the inward normal): its direction is a normal estimate

Each is a convolution of a grid (occupancy, or squared or signed distance) with a radial
kernel (the ball, or the sphere for SA_r and SD2_r), done by FFT with the kernel's exact Fourier transform. Radii whose ``r / h`` falls in
the same octave share one occupancy grid and its forward FFT. Results are read at the
query points by cubic B-spline interpolation, whose prefilter is applied in the
Fourier domain for free; the area vector is the gradient of V's spline. A grid larger
than ``DescriptorParams.max_memory`` is convolved in boxes around the query points
(:mod:`.tiles`, the paper's box tiling).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ReassembleError
from ..geometry import make_scene
from ..repair import is_closed_solid
from .closest import MeshDistance
from .compiled import BALL, BALL_MOMENT2, SPHERE, moment_products, radial_products, spline_at
from .tiles import DISTANCE_PAD, check_fits, plan_tiles, tile_offset
from .voxelize import (
    Grid,
    distance_band,
    inside_centres,
    make_grid,
    occupancy,
    saturated_signed,
    saturated_square,
    signed_distance,
    squared_distance,
    winding_occupancy,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DescriptorParams:
    """Settings of :func:`integral_invariants`.

    Attributes
    ----------
    resolution : smallest ``r / h`` of the occupancy grids (a radius gets the coarsest grid
        of the octave ladder with at least this many voxels per radius)
    d2_resolution : ``r / h`` of the squared-distance grid of each radius
    antialias : width of the occupancy ramp across the surface, in voxels
    with_d2 : compute D2_r and K2, and the signed-distance integrals D_r and SD2_r (the costly
        part: exact distances in a band about 2r wide)
    sphere_area : compute SA_r and H_SA (one more inverse FFT per radius)
    principal : also principal curvatures and directions from the covariance of ball ∩ solid
        (nine more convolutions per radius)
    max_memory : bytes of working memory allowed for one grid; a larger grid is cut into
        tiles convolved one at a time (:func:`tiles.plan_tiles`), the same values to float
        rounding
    """

    resolution: float = 8.0
    d2_resolution: float = 4.0
    antialias: float = 2.0
    with_d2: bool = True
    sphere_area: bool = True
    principal: bool = False
    max_memory: float = 4e9


@dataclass
class Descriptors:
    """Integral invariants at n query points and m radii.

    Attributes
    ----------
    points : (n, 3) query points
    radii : (m,) kernel radii, mesh units
    V, P, D2 : (n, m) volume, second moment and squared-distance integrals (D2 NaN when
        not computed)
    H, H_rob : (n, m) mean curvature, plain (Eq. 19) and offset-robust
    K2 : (n, m) (kappa1 - kappa2)^2 (Eq. 32)
    K2_cov, k1, k2 : (n, m) with ``principal``: (kappa1 - kappa2)^2 from the covariance of
        ball ∩ solid (offset-robust to first order), and k1 >= k2 = H_rob ± sqrt(K2_cov)/2
    dir1, normal : (n, m, 3) with ``principal``: the direction of k1, and the outward normal
    SA, H_SA : (n, m) sphere area descriptor and its mean curvature (NaN without ``sphere_area``)
    D, SD2 : (n, m) signed-distance integral over the ball and squared-distance integral over
        the sphere (NaN without ``with_d2``)
    area : (n, m, 3) area vector, the gradient of V_r (Theorem 2)
    normal_area : (n, m, 3) the outward unit normal it gives, ``-area / |area|``
    timings : seconds per stage
    """

    points: np.ndarray
    radii: np.ndarray
    V: np.ndarray
    P: np.ndarray
    D2: np.ndarray
    H: np.ndarray
    H_rob: np.ndarray
    K2: np.ndarray
    K2_cov: np.ndarray | None = None
    k1: np.ndarray | None = None
    k2: np.ndarray | None = None
    dir1: np.ndarray | None = None
    normal: np.ndarray | None = None
    SA: np.ndarray | None = None
    H_SA: np.ndarray | None = None
    D: np.ndarray | None = None
    SD2: np.ndarray | None = None
    area: np.ndarray | None = None
    normal_area: np.ndarray | None = None
    timings: dict = field(default_factory=dict)


def mean_curvature(V: np.ndarray, r) -> np.ndarray:
    """Eq. 19: H = 8/(3r) - 4 V/(pi r^4)."""
    return 8.0 / (3.0 * r) - 4.0 * V / (np.pi * r**4)


def robust_mean_curvature(V: np.ndarray, P: np.ndarray, r) -> np.ndarray:
    """H_rob = 12 V/(pi r^4) + 8/(5 r) - 24 P/(pi r^6): first-order insensitive to offsets."""
    return 12.0 * V / (np.pi * r**4) + 8.0 / (5.0 * r) - 24.0 * P / (np.pi * r**6)


def curvature_difference_sq(D2: np.ndarray, r) -> np.ndarray:
    """Eq. 32: (kappa1 - kappa2)^2 = (28 pi r^5 - 105 D2)/(pi r^7)."""
    return (28.0 * np.pi * r**5 - 105.0 * D2) / (np.pi * r**7)


def sphere_area_mean_curvature(SA: np.ndarray, r) -> np.ndarray:
    """Eq. 19: H = 2/r - SA/(pi r^3), from SA_r = 2 pi r^2 - pi H r^3 + O(r^4) (Eq. 18)."""
    return 2.0 / r - SA / (np.pi * r**3)


def signed_distance_mean_curvature(D: np.ndarray, r) -> np.ndarray:
    """Theorem 4: H = 15 D_r / (4 pi r^5)."""
    return 15.0 * D / (4.0 * np.pi * r**5)


def sphere_curvature_difference_sq(SD2: np.ndarray, r) -> np.ndarray:
    """Eq. 33: (kappa1 - kappa2)^2 = (20 pi r^4 - 15 SD2)/(pi r^6)."""
    return (20.0 * np.pi * r**4 - 15.0 * SD2) / (np.pi * r**6)


def normal_from_area(area: np.ndarray) -> np.ndarray:
    """Outward unit normals ``-a / |a|`` from area vectors (..., 3).

    Notes
    -----
    The area vector a_r = grad V_r points into the solid, with length pi r^2 (1 - (3H^2 -
    K) r^2/8) (Pottmann et al. 2009, Theorem 2, Eq. 23). Theorem 7's Remark 2 reads it
    the other way: a surface offset by delta changes V_r by pi r^2 delta to first order, so
    a zero-mean perturbation tilts a_r by a zero-mean amount, the same bound as V_r's.
    """
    norm = np.linalg.norm(area, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return -area / norm


def principal_from_moments(V: np.ndarray, m: np.ndarray, M: np.ndarray, r) -> tuple[np.ndarray, ...]:
    """Curvature difference, direction of the larger curvature and outward normal from moments.

    The covariance of ball ∩ solid about its barycentre has, in the principal frame, the
    tangential eigenvalues 2 pi r^5/15 - (pi/48)(3 k1 + k2) r^6 and 2 pi r^5/15 -
    (pi/48)(k1 + 3 k2) r^6 and the normal one 19 pi r^5/480 + O(r^6) (Pottmann et al.
    2007), so ``k1 - k2 = 24 (lambda_b - lambda_a) / (pi r^6)``. A point off the surface
    adds the same pi r^4 delta / 4 to both tangential eigenvalues: the difference ignores it.

    Parameters
    ----------
    V : (n,) volume, m : (n, 3) first and M : (n, 6) second moments about the query point
        (xx, yy, zz, xy, xz, yz), r : radius

    Returns
    -------
    K2_cov (n,), dir1 (n, 3), normal (n, 3) outward
    """
    C = np.empty((len(V), 3, 3))
    C[:, 0, 0], C[:, 1, 1], C[:, 2, 2] = M[:, 0], M[:, 1], M[:, 2]
    C[:, 0, 1] = C[:, 1, 0] = M[:, 3]
    C[:, 0, 2] = C[:, 2, 0] = M[:, 4]
    C[:, 1, 2] = C[:, 2, 1] = M[:, 5]
    C -= m[:, :, None] * m[:, None, :] / V[:, None, None]
    lam, vec = np.linalg.eigh(C)  # ascending: the normal's is far the smallest
    diff = 24.0 * (lam[:, 2] - lam[:, 1]) / (np.pi * r**6)
    normal = vec[:, :, 0]
    flip = np.einsum("ij,ij->i", normal, m) > 0  # the barycentre lies inside
    normal[flip] *= -1.0
    return diff * diff, vec[:, :, 1], normal


def _put(out: dict, key: str, rows, cols: np.ndarray, value: np.ndarray, shape: tuple[int, int]) -> None:
    """``out[key][rows, cols] = value`` (value (k, len(cols), ...)), the array made on first use."""
    if key not in out:
        out[key] = np.empty(shape + value.shape[2:])
    if isinstance(rows, slice):
        out[key][rows, cols] = value
    else:
        out[key][rows[:, None], cols] = value


def _coefficient_grids(products: np.ndarray, grid: Grid) -> list[np.ndarray]:
    """B-spline coefficient grids of the convolved grid: each spectrum-times-kernel product
    (:mod:`.compiled`, the spline's spectral factor applied) transformed back."""
    from scipy.fft import irfftn

    return [irfftn(product, s=grid.shape, workers=-1) for product in products]


def _radial_coefficients(spectrum: np.ndarray, grid: Grid, r: float, kinds) -> list[np.ndarray]:
    """The coefficient grids of the radial kernels ``kinds`` (:func:`.compiled.radial_products`) of radius r."""
    return _coefficient_grids(radial_products(spectrum, grid.shape, grid.h, r, kinds), grid)


def _read(coeffs: list[np.ndarray], u: np.ndarray) -> np.ndarray:
    """Each coefficient grid's spline at the fractional voxel indices u (n, 3): (n, len(coeffs))."""
    out = np.empty((len(u), len(coeffs)))
    for j, c in enumerate(coeffs):
        out[:, j] = spline_at(c, u)
    return out


def _check_radii(radii: np.ndarray, diag: float, params: DescriptorParams) -> None:
    """Raise ReassembleError unless every radius is positive, finite and below ``diag``."""
    if len(radii) == 0:
        raise ReassembleError("no radii given (--radii)")
    if not np.all(np.isfinite(radii)) or np.any(radii <= 0):
        raise ReassembleError(f"radii must be positive (got {radii.tolist()})")
    if np.any(radii > diag):
        raise ReassembleError(
            f"radius {radii.max():g} is larger than the object (bounding-box diagonal {diag:g}); "
            "use smaller --radii, or --relative for fractions of the diagonal"
        )
    if params.resolution < 2 or params.d2_resolution < 2:
        raise ReassembleError("--resolution must be at least 2 voxels per radius")


def _add_time(timings: dict, key: str, since: float) -> None:
    timings[key] = timings.get(key, 0.0) + time.perf_counter() - since


def _level_integrals(
    spectrum: np.ndarray, grid: Grid, radii: np.ndarray, points: np.ndarray, params: DescriptorParams,
) -> dict[str, np.ndarray]:
    """The volume integrals of the radii of one occupancy grid, read at the points.

    Parameters
    ----------
    spectrum : rfftn of the grid's occupancy
    grid : Grid
    radii : (k,) kernel radii sharing the grid
    points : (n, 3) query points
    params : DescriptorParams

    Returns
    -------
    V, P, SA : (n, k) (SA NaN without ``params.sphere_area``); area : (n, k, 3) area vectors;
    with ``params.principal`` also K2_cov (n, k), dir1 and normal (n, k, 3)

    Notes
    -----
    The area vector is the gradient of V_r (Pottmann et al. 2009, Theorem 2), read off the
    cubic spline of V's convolved grid: no more FFTs, and exact for cubics where V is, to
    leading order, a cubic in the offset from the surface. SA_r = dV_r/dr is the
    occupancy integrated against the sphere p + rS, the derivative in r of the ball (Eq. 17).
    The first moments m = ∫ (x - p) over ball ∩ solid need no FFT either: differentiating
    V and P under the integral gives grad V = ∫ over the sphere of the occupancy times the
    outward normal, grad P = r^2 grad V - 2 m, so m = (r^2 grad V - grad P) / 2.
    """
    n, k = len(points), len(radii)
    u = (points - grid.origin) / grid.h
    out = {key: np.full((n, k), np.nan) for key in ("V", "P", "SA")}
    out["area"] = np.empty((n, k, 3))
    kinds = [BALL, BALL_MOMENT2] + ([SPHERE] if params.sphere_area else [])
    if params.principal:
        out["K2_cov"], out["dir1"], out["normal"] = np.empty((n, k)), np.empty((n, k, 3)), np.empty((n, k, 3))
    for j, r in enumerate(radii):  # one radius's grids at a time
        coeffs = _radial_coefficients(spectrum, grid, r, kinds)
        out["V"][:, j], area = spline_at(coeffs[0], u, gradient=True)
        out["area"][:, j] = area / grid.h
        if params.principal:  # P's gradient gives the first moments
            out["P"][:, j], grad_p = spline_at(coeffs[1], u, gradient=True)
        else:
            out["P"][:, j] = spline_at(coeffs[1], u)
        if params.sphere_area:
            out["SA"][:, j] = spline_at(coeffs[2], u)
        del coeffs
        if params.principal:
            first = 0.5 * (r * r * out["area"][:, j] - grad_p / grid.h)
            second = _read(_coefficient_grids(moment_products(spectrum, grid.shape, grid.h, r), grid), u)
            out["K2_cov"][:, j], out["dir1"][:, j], out["normal"][:, j] = principal_from_moments(
                out["V"][:, j], first, second, r
            )
    # The ramp averages the solid over offsets of variance s2: V gains s2/2 * V'' and P
    # s2/2 * P'', with V'' = pi r^2 H and P'' = pi r^4 H / 2 to leading order; SA = dV/dr
    # gains s2/2 * d(V'')/dr = s2 pi r H (exact on a sphere).
    s2 = (params.antialias * grid.h) ** 2 / 12.0
    H_smooth = mean_curvature(out["V"], radii)
    out["V"] = out["V"] - 0.5 * s2 * np.pi * radii**2 * H_smooth
    out["P"] = out["P"] - 0.25 * s2 * np.pi * radii**4 * H_smooth
    out["SA"] -= s2 * np.pi * radii * H_smooth
    # and the circle where the sphere meets the surface shrinks by t^2 at offset t: the
    # area vector's length pi (r^2 - t^2) loses pi s2 on average (curvature: O(s2 r^2 H^2))
    length = np.linalg.norm(out["area"], axis=2, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out["area"] = out["area"] * (1.0 + np.pi * s2 / length)
    return out


def _volume_grids(vertices: np.ndarray, radii: np.ndarray, params: DescriptorParams,
                  winding) -> list[tuple[np.ndarray, Grid, dict]]:
    """The occupancy grids: per octave of ``r / h``, its radii (indices), its grid, and the
    keywords of :func:`tiles.plan_tiles` for it."""
    bbox_min, bbox_max = vertices.min(axis=0), vertices.max(axis=0)
    r_min = radii.min()
    level = np.floor(np.log2(radii / r_min) + 1e-9).astype(int)
    out = []
    for lev in np.unique(level):
        idx = np.flatnonzero(level == lev)
        h = r_min * 2.0**lev / params.resolution
        # the FFT convolution is circular: a ball at the object's edge may wrap into the
        # margin on the other side, which is empty when margin > r/2; plus the ramp and
        # the spline stencil
        grid = make_grid(bbox_min, bbox_max, h=h, margin=0.5 * radii[idx].max() + 4 * h)
        tiling = {"reach": int(np.ceil(radii[idx].max() / h)) + 2, "tile_z": winding is None,
                  "what": f"radius {radii[idx].max():g}"}
        out.append((idx, grid, tiling))
    return out


def _distance_grid(vertices: np.ndarray, r: float, params: DescriptorParams, winding) -> tuple[Grid, dict]:
    """The squared- and signed-distance grid of radius r, and the keywords of :func:`tiles.plan_tiles`.

    Notes
    -----
    The distances are exact wherever the spline of the samples can reach inside the ball
    (r + h), then rolled off smoothly to ``band`` (a kink would ring into every ball; a
    shorter roll-off, measured, rings more). A tile's samples are those of the whole grid
    where the surface within the band of them lies in the tile: its padding covers the band.
    """
    h = r / params.d2_resolution
    band = r + 5 * h
    grid = make_grid(vertices.min(axis=0), vertices.max(axis=0), h=h, margin=band + 2 * h)
    return grid, {"reach": int(np.ceil(r / h)) + 2, "pad": max(DISTANCE_PAD, int(np.ceil(band / h)) + 2),
                  "tile_z": winding is None, "what": f"D2 at radius {r:g}"}


def _check_memory(vertices: np.ndarray, radii: np.ndarray, params: DescriptorParams, winding) -> None:
    """Raise ReassembleError, before any work, if some grid does not fit ``params.max_memory`` even in tiles."""
    grids = [(grid, tiling) for _, grid, tiling in _volume_grids(vertices, radii, params, winding)]
    if params.with_d2:
        grids += [_distance_grid(vertices, r, params, winding) for r in radii]
    for grid, tiling in grids:
        check_fits(grid, max_memory=params.max_memory, **tiling)


def _volume_integrals(
    scene, distance, vertices: np.ndarray, faces: np.ndarray, winding, radii: np.ndarray, points: np.ndarray,
    params: DescriptorParams, timings: dict,
) -> dict[str, np.ndarray]:
    """V_r, P_r, SA_r, the area vectors (and, with ``params.principal``, the covariance
    curvatures) at the points.

    Radii of one octave of ``r / h`` share an occupancy grid and its forward FFT.

    Parameters
    ----------
    scene : ray-casting scene of the mesh (:func:`geometry.make_scene`)
    distance : its :class:`closest.MeshDistance`
    vertices : (v, 3) float64, faces : (f, 3) int64
    winding : None for a closed solid (inside by ray parity), else the surface's
        :class:`repair.WindingNumber` (inside where it exceeds 1/2)
    radii : (m,) kernel radii
    points : (n, 3) query points
    params : DescriptorParams
    timings : seconds per stage, added to in place

    Returns
    -------
    as :func:`_level_integrals`, for all m radii
    """
    from scipy.fft import rfftn

    out: dict[str, np.ndarray] = {}
    for idx, grid, tiling in _volume_grids(vertices, radii, params, winding):
        h = grid.h
        tiles = plan_tiles(grid, points, max_memory=params.max_memory, **tiling)
        start = None if tiles[0][0] is grid else vertices.min(axis=0) - h  # a tile may begin inside the solid
        for tile, rows in tiles:
            t = time.perf_counter()
            if winding is None:
                occ = occupancy(scene, distance, tile, width=params.antialias, ray_start=start)
            else:
                frame = None if tile is grid else (tile_offset(tile, grid), grid.shape)
                occ = winding_occupancy(scene, vertices, faces, tile, width=params.antialias, winding=winding,
                                        distance=distance, ray_start=start, frame=frame)
            _add_time(timings, "voxelize", t)
            t = time.perf_counter()
            spectrum = rfftn(occ, workers=-1)
            del occ
            for key, value in _level_integrals(spectrum, tile, radii[idx], points[rows], params).items():
                _put(out, key, rows, idx, value, (len(points), len(radii)))
            del spectrum
            _add_time(timings, "volume_fft", t)
        log.info("V, P for r = %s on a %s grid (h = %.3g)%s", radii[idx].round(6).tolist(), grid.shape, h,
                 f" in {len(tiles)} tiles of {tiles[0][0].shape}" if len(tiles) > 1 else "")
    return out


def _distance_integrals(
    scene, distance, vertices: np.ndarray, faces: np.ndarray, winding, radii: np.ndarray, points: np.ndarray,
    params: DescriptorParams, timings: dict,
) -> dict[str, np.ndarray]:
    """D2_r, SD2_r and D_r at the points: the squared distance to the surface integrated over
    each ball and each sphere, and the signed distance over each ball.

    Parameters
    ----------
    scene, distance, vertices, faces, winding, radii, points, params, timings : as in
        :func:`_volume_integrals`

    Returns
    -------
    D2, SD2, D : (n, m)

    Notes
    -----
    The signed distance (Pottmann et al. 2009, Section 7.1) shares the squared distance's band
    and takes its sign from the inside of the grid's voxel centres. It is linear across the
    surface, so its spline is exact there where the occupancy's ramp must be corrected for;
    points in a ball about a surface point lie within r of the surface, so beyond the band it
    is rolled off to ±c (:func:`voxelize.saturated_signed`) without changing D_r.
    """
    out = {key: np.full((len(points), len(radii)), np.nan) for key in ("D2", "SD2", "D")}
    for i, r in enumerate(radii):
        grid, tiling = _distance_grid(vertices, r, params, winding)
        tiles = plan_tiles(grid, points, max_memory=params.max_memory, **tiling)
        start = None if tiles[0][0] is grid else vertices.min(axis=0) - grid.h
        for tile, rows in tiles:
            frame = None if tile is grid else (tile_offset(tile, grid), grid.shape)
            values = _distance_tile(scene, distance, vertices, faces, winding, tile, r, points[rows], params,
                                    timings, ray_start=start, frame=frame)
            for key, value in values.items():
                out[key][rows, i] = value
        if len(tiles) > 1:
            log.info("D2 for r = %.6g on a %s grid in %d tiles of %s", r, grid.shape, len(tiles), tiles[0][0].shape)
    return out


def _distance_tile(
    scene, distance, vertices: np.ndarray, faces: np.ndarray, winding, grid: Grid, r: float, points: np.ndarray,
    params: DescriptorParams, timings: dict, *, ray_start: np.ndarray | None = None, frame=None,
) -> dict[str, np.ndarray]:
    """D2_r, SD2_r and D_r of one radius at the points, from one grid (the whole one, or a tile).

    Parameters
    ----------
    scene, distance, vertices, faces, winding, params, timings : as in :func:`_volume_integrals`
    grid : Grid of spacing ``r / params.d2_resolution``
    r : radius
    points : (n, 3) query points, inside the grid's reach
    ray_start : as :func:`voxelize.inside_centres`; frame : as :func:`voxelize.winding_occupancy`

    Returns
    -------
    D2, SD2, D : (n,)
    """
    from scipy.fft import rfftn

    h = grid.h
    exact, band = r + h, r + 5 * h  # as _distance_grid
    out = {}
    t = time.perf_counter()
    near = distance_band(distance, grid, r=exact, band=band)
    sq = squared_distance(distance, grid, r=exact, band=band, near=near)
    _add_time(timings, "distance", t)
    t = time.perf_counter()
    spectrum = rfftn(sq, workers=-1)
    del sq
    far = float(saturated_square(np.array(band), exact, band))
    u = (points - grid.origin) / grid.h
    values = _read(_radial_coefficients(spectrum, grid, r, [BALL, SPHERE]), u)
    out["D2"] = values[:, 0] + far * 4.0 * np.pi * r**3 / 3.0
    out["SD2"] = values[:, 1] + far * 4.0 * np.pi * r**2
    _add_time(timings, "d2_fft", t)
    t = time.perf_counter()
    if winding is None:
        inside = inside_centres(scene, grid, ray_start=ray_start)
    else:
        inside = winding_occupancy(scene, vertices, faces, grid, width=params.antialias, winding=winding,
                                   distance=distance, ray_start=ray_start, frame=frame) > 0.5
    spectrum = rfftn(signed_distance(near, inside, r=exact, band=band), workers=-1)
    del inside, near
    c = float(saturated_signed(np.array(band), exact, band))
    out["D"] = _read(_radial_coefficients(spectrum, grid, r, [BALL]), u)[:, 0] + c * 4.0 * np.pi * r**3 / 3.0
    _add_time(timings, "d_fft", t)
    return out


def integral_invariants(
    vertices: np.ndarray,
    faces: np.ndarray,
    radii,
    *,
    points: np.ndarray | None = None,
    params: DescriptorParams = DescriptorParams(),
) -> Descriptors:
    """Integral invariants of a solid bounded by a triangle mesh at several radii.

    Parameters
    ----------
    vertices : (n, 3) float (not modified): a closed, outward-oriented mesh, whose inside is
        found by ray parity, or any outward surface (open, non-manifold, overlapping: as
        :func:`repair.repair_surface` leaves it), whose inside is its winding number
        (:func:`voxelize.winding_occupancy`)
    faces : (f, 3) int
    radii : (m,) kernel radii in mesh units, each > 0 and below the bounding-box diagonal
    points : (q, 3) query points; default the vertices
    params : DescriptorParams

    Returns
    -------
    Descriptors
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    radii = np.asarray(radii, dtype=np.float64).ravel()
    points = vertices if points is None else np.asarray(points, dtype=np.float64)
    diag = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    _check_radii(radii, diag, params)

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    scene = make_scene(vertices, faces)
    distance = MeshDistance(vertices, faces)  # one tree (and face adjacency) for every grid
    winding = None
    if not is_closed_solid(faces):  # an open or non-manifold surface (repair.repair_surface)
        from ..repair import WindingNumber

        winding = WindingNumber(vertices, faces)  # one hierarchy for every grid of both stages
    timings["bvh"] = time.perf_counter() - t0
    _check_memory(vertices, radii, params, winding)

    vol = _volume_integrals(scene, distance, vertices, faces, winding, radii, points, params, timings)
    nan = np.full((len(points), len(radii)), np.nan)
    if params.with_d2:
        dist = _distance_integrals(scene, distance, vertices, faces, winding, radii, points, params, timings)
    else:
        dist = {"D2": nan, "SD2": nan.copy(), "D": nan.copy()}

    timings["total"] = time.perf_counter() - t0
    V, P, D2 = vol["V"], vol["P"], dist["D2"]
    H = mean_curvature(V, radii)
    H_rob = robust_mean_curvature(V, P, radii)
    out = Descriptors(
        points=points.copy(), radii=radii.copy(), V=V, P=P, D2=D2, H=H, H_rob=H_rob,
        K2=curvature_difference_sq(D2, radii), SA=vol["SA"], H_SA=sphere_area_mean_curvature(vol["SA"], radii),
        D=dist["D"], SD2=dist["SD2"], area=vol["area"], normal_area=normal_from_area(vol["area"]), timings=timings,
    )
    if params.principal:
        half = 0.5 * np.sqrt(vol["K2_cov"])
        out.K2_cov, out.k1, out.k2 = vol["K2_cov"], H_rob + half, H_rob - half
        out.dir1, out.normal = vol["dir1"], vol["normal"]
    return out
