"""Compiled loops of the FFT convolution: a grid's spectrum times the radial kernels', and the
cubic spline read at the query points.

The numpy versions in :mod:`.kernels` stay the reference (and the tests compare against
them). Here each product is one pass over the half-spectrum, the kernel evaluated on one
quadrant and mirrored (|omega| is even in the first two axes), the separable spectral
factor (prefilter x spline integration) applied on the fly instead of stored, and the
spline read with value and gradient from one gather of its 64 coefficients.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from .kernels import prefilter_axis

# TBB, numba's first choice, warns when the system's is too old; OpenMP ships with numba
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

BALL, BALL_MOMENT2, SPHERE = 0, 1, 2  # the kernels of :func:`radial_products`
_SERIES_BELOW = 2.0  # |omega| r where the closed forms cancel: the power series below it


@njit(cache=True, inline="always")
def _series(x2, a):
    """sum_n (-1)^n x^(2n) / ((2n + a)(2n + 1)!) for x^2 = x2 < 4 (terms < 1e-17 by n = 18)."""
    total, term, fact = 0.0, 1.0, 1.0
    for n in range(18):
        if n > 0:
            fact *= (2 * n) * (2 * n + 1)
            term *= -x2
        total += term / ((2 * n + a) * fact)
    return total


@njit(cache=True, inline="always")
def _radial(kind, x):
    """The kernel's profile at x = |omega| r, without its 4 pi r^a factor."""
    if kind == 2:
        return 1.0 if x == 0.0 else math.sin(x) / x
    if x < _SERIES_BELOW:
        return _series(x * x, 3 if kind == 0 else 5)
    s, c = math.sin(x), math.cos(x)
    if kind == 0:
        return (s - x * c) / (x * x * x)
    x2 = x * x
    return (-(x2 * x) * c + 3.0 * x2 * s + 6.0 * x * c - 6.0 * s) / (x2 * x2 * x)


@njit(cache=True, parallel=True)
def _products(spectrum, wx2, wy2, wz2, fx, fy, fz, kinds, scales, r, out):
    nx, ny, nz = spectrum.shape
    qx, qy = nx // 2 + 1, ny // 2 + 1
    m = len(kinds)
    for i in prange(qx):
        prof = np.empty(m)
        ix2 = nx - i  # the mirror row, if any
        for j in range(qy):
            jy2 = ny - j
            for k in range(nz):
                x = math.sqrt(wx2[i] + wy2[j] + wz2[k]) * r
                for q in range(m):
                    prof[q] = _radial(kinds[q], x) * scales[q]
                fyz = fy[j] * fz[k]
                for q in range(m):
                    out[q, i, j, k] = spectrum[i, j, k] * (prof[q] * fx[i] * fyz)
                    if 0 < ix2 < nx and ix2 != i:
                        out[q, ix2, j, k] = spectrum[ix2, j, k] * (prof[q] * fx[ix2] * fyz)
                    if 0 < jy2 < ny and jy2 != j:
                        out[q, i, jy2, k] = spectrum[i, jy2, k] * (prof[q] * fx[i] * fy[jy2] * fz[k])
                        if 0 < ix2 < nx and ix2 != i:
                            out[q, ix2, jy2, k] = spectrum[ix2, jy2, k] * (prof[q] * fx[ix2] * fy[jy2] * fz[k])
    return out


def _axes(shape: tuple[int, int, int], h: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per axis of the half-spectrum: the angular frequency, and the factor of the spline's
    prefilter times spline integration (:func:`.kernels.prefilter_axis` times :func:`.kernels.integration_axis`)."""
    freqs = [np.fft.fftfreq(shape[0]), np.fft.fftfreq(shape[1]), np.fft.rfftfreq(shape[2])]
    # integration_axis's expression, multiplied in this order: the descriptors stay the
    # same to the last bit as when this module computed the factors itself
    factors = [prefilter_axis(n, r) * np.sinc(f) ** 4 * 3.0 / (2.0 + np.cos(2.0 * np.pi * f))
               for n, r, f in zip(shape, (False, False, True), freqs)]
    return [2.0 * np.pi * f / h for f in freqs], factors


def radial_products(spectrum: np.ndarray, shape: tuple[int, int, int], h: float, r: float, kinds) -> np.ndarray:
    """The spectrum times each radial kernel of radius r, the spline's spectral factor applied.

    Parameters
    ----------
    spectrum : (nx, ny, nz // 2 + 1) complex, ``rfftn`` of a grid of ``shape``
    shape : the grid's shape; h : its spacing
    r : the kernels' radius
    kinds : kernels among :data:`BALL` (V_r), :data:`BALL_MOMENT2` (P_r), :data:`SPHERE` (SA_r)

    Returns
    -------
    (len(kinds), nx, ny, nz // 2 + 1) complex64: each ``irfftn``'d (``s=shape``) gives the
    B-spline coefficients of the convolved grid (:func:`.invariants._coefficient_grids`)
    """
    kinds = np.asarray(kinds, np.int64)
    w, f = _axes(shape, h)
    exponent = np.where(kinds == BALL, 3, np.where(kinds == BALL_MOMENT2, 5, 2))
    scales = 4.0 * np.pi * float(r) ** exponent.astype(float)
    out = np.empty((len(kinds),) + spectrum.shape, np.complex64)
    return _products(spectrum, *(x * x for x in w), *f, kinds, scales, float(r), out)


@njit(cache=True)
def _axis(t, i, hi):
    """The four cubic B-spline weights, their derivatives and the (clipped) indices at
    u = i + t along one axis of a grid of hi + 1 nodes."""
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    w = (s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0)
    dw = (-0.5 * s * s, (9.0 * t2 - 12.0 * t) / 6.0, (-9.0 * t2 + 6.0 * t + 3.0) / 6.0, 0.5 * t2)
    idx = (min(max(i - 1, 0), hi), min(max(i, 0), hi), min(max(i + 1, 0), hi), min(max(i + 2, 0), hi))
    return w, dw, idx


@njit(cache=True, parallel=True)
def _spline(coeff, u, value, gradient, with_gradient):
    nx, ny, nz = coeff.shape
    for p in prange(u.shape[0]):
        fx, fy, fz = math.floor(u[p, 0]), math.floor(u[p, 1]), math.floor(u[p, 2])
        wx, dx, ix = _axis(u[p, 0] - fx, int(fx), nx - 1)
        wy, dy, iy = _axis(u[p, 1] - fy, int(fy), ny - 1)
        wz, dz, iz = _axis(u[p, 2] - fz, int(fz), nz - 1)
        v = gx = gy = gz = 0.0
        for a in range(4):
            for b in range(4):
                # the z sums first: value and z-derivative along the column, then weighted
                sv = sd = 0.0
                for c in range(4):
                    cv = coeff[ix[a], iy[b], iz[c]]
                    sv += cv * wz[c]
                    sd += cv * dz[c]
                v += wx[a] * wy[b] * sv
                if with_gradient:
                    gx += dx[a] * wy[b] * sv
                    gy += wx[a] * dy[b] * sv
                    gz += wx[a] * wy[b] * sd
        value[p] = v
        if with_gradient:
            gradient[p, 0], gradient[p, 1], gradient[p, 2] = gx, gy, gz


def spline_at(coeff: np.ndarray, points_grid: np.ndarray, *, gradient: bool = False):
    """A cubic B-spline (its coefficient grid) at points in voxel-index units.

    Parameters
    ----------
    coeff : (nx, ny, nz) coefficients
    points_grid : (n, 3) fractional voxel indices (the stencil clipped to the grid, as
        :func:`.kernels.bspline_eval`)
    gradient : also return the gradient (per voxel index: divide by the spacing)

    Returns
    -------
    (n,) float64 values, and with ``gradient`` (n, 3) float64
    """
    u = np.ascontiguousarray(points_grid, dtype=np.float64)
    value = np.empty(len(u))
    grad = np.empty((len(u), 3) if gradient else (0, 3))
    _spline(np.ascontiguousarray(coeff), u, value, grad, gradient)
    return (value, grad) if gradient else value


@njit(cache=True, inline="always")
def _ball_derivatives(x):
    """psi = phi'(x)/x and phi''(x) for the ball's profile phi(x) = (sin x - x cos x)/x^3
    (as :func:`.kernels._ball_derivatives`: series below x = 2)."""
    if x < _SERIES_BELOW:
        x2 = x * x
        psi = dd = 0.0
        term, fact = 1.0, 6.0  # x^(2n-2), (2n+1)!
        for n in range(1, 19):
            c = (-1.0 if n % 2 else 1.0) * 2 * n / ((2 * n + 3) * fact)
            psi += c * term
            dd += c * (2 * n - 1) * term
            term *= x2
            fact *= (2 * n + 2) * (2 * n + 3)
        return psi, dd
    s, c = math.sin(x), math.cos(x)
    x2 = x * x
    x5 = x2 * x2 * x
    return (x2 * s - 3.0 * s + 3.0 * x * c) / x5, (x2 * x * c - 5.0 * x2 * s - 12.0 * x * c + 12.0 * s) / x5


@njit(cache=True, parallel=True)
def _moment_products(spectrum, wx, wy, wz, fx, fy, fz, r, scale, at_zero, out):
    nx, ny, nz = spectrum.shape
    qx, qy = nx // 2 + 1, ny // 2 + 1
    for ii in prange(qx):
        i = np.int64(ii)  # prange's index is unsigned: nx - i would not type as an index
        for j in range(qy):
            for k in range(nz):
                k2 = wx[i] * wx[i] + wy[j] * wy[j] + wz[k] * wz[k]
                psi, dd = _ball_derivatives(math.sqrt(k2) * r)
                f1k, diff = scale * psi, scale * (dd - psi)
                for a in range(2):
                    ia = i if a == 0 else nx - i
                    if a == 1 and (ia >= nx or ia == i):
                        continue
                    for b in range(2):
                        jb = j if b == 0 else ny - j
                        if b == 1 and (jb >= ny or jb == j):
                            continue
                        s = spectrum[ia, jb, k] * (fx[ia] * fy[jb] * fz[k])
                        if k2 == 0.0:
                            for q in range(3):
                                out[q, ia, jb, k] = s * at_zero
                            for q in range(3, 6):
                                out[q, ia, jb, k] = 0.0
                            continue
                        w0, w1, w2 = wx[ia], wy[jb], wz[k]
                        g = diff / k2
                        out[0, ia, jb, k] = s * -(f1k + g * w0 * w0)
                        out[1, ia, jb, k] = s * -(f1k + g * w1 * w1)
                        out[2, ia, jb, k] = s * -(f1k + g * w2 * w2)
                        out[3, ia, jb, k] = s * -(g * w0 * w1)
                        out[4, ia, jb, k] = s * -(g * w0 * w2)
                        out[5, ia, jb, k] = s * -(g * w1 * w2)
    return out


def moment_products(spectrum: np.ndarray, shape: tuple[int, int, int], h: float, r: float) -> np.ndarray:
    """The spectrum times the ball's second-moment kernels (xx, yy, zz, xy, xz, yz) of radius r,
    the spline's spectral factor applied (as :func:`.kernels.ball_moment_spectra`, the first
    moments left out: :func:`.invariants._level_integrals` has them from V's and P's gradients).

    Returns
    -------
    (6, nx, ny, nz // 2 + 1) complex64, each ``irfftn``'d to a coefficient grid
    """
    w, f = _axes(shape, h)
    out = np.empty((6,) + spectrum.shape, np.complex64)
    scale = 4.0 * np.pi * float(r) ** 5
    return _moment_products(spectrum, *w, *f, float(r), scale, scale / 15.0, out)
