"""Fourier transforms of the ball kernels, and the spectral tools of the FFT convolution.

The descriptors run the compiled loops of :mod:`.compiled`; the array versions here are
their reference (``tests/test_compiled.py``) and the closed forms they are checked against.

For a radial kernel ``g(|y|) 1(|y| < r)`` the 3D Fourier transform depends on
``k = |omega|`` only: ``4 pi / k * integral_0^r rho g(rho) sin(k rho) d rho``.
With ``x = k r``:

- ball (volume descriptor V_r):  4 pi r^3 (sin x - x cos x) / x^3
- ball weighted by |y|^2 (second moment P_r):
  4 pi r^5 (-x^3 cos x + 3 x^2 sin x + 6 x cos x - 6 sin x) / x^5
- sphere (the uniform measure on the sphere of radius r; SA_r and SD2_r): 4 pi r^2 sin x / x,
  the derivative in r of the ball's

Both equal ``4 pi r^a sum_n (-1)^n x^(2n) / ((2n + a) (2n + 1)!)`` with a = 3, 5: the
series is used for small x, where the closed forms cancel catastrophically.
"""

from __future__ import annotations

from math import factorial

import numpy as np


def _radial_spectrum(x: np.ndarray, a: int, sin_cos=None) -> np.ndarray:
    """sum_n (-1)^n x^(2n) / ((2n + a)(2n + 1)!) for the ball (a=3) and second moment (a=5).

    Closed form in float32 where x >= 2 (most of a grid's spectrum), the series below.
    ``sin_cos`` may pass precomputed ``(sin x, cos x)``.
    """
    x = np.asarray(x, dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        s, c = sin_cos if sin_cos is not None else (np.sin(x), np.cos(x))
        if a == 3:
            out = (s - x * c) / (x * x * x)
        elif a == 5:
            x2 = x * x
            out = (-(x2 * x) * c + 3 * x2 * s + 6 * x * c - 6 * s) / (x2 * x2 * x)
        else:
            raise ValueError(a)
    small = np.flatnonzero(x.ravel() < 2.0)
    xs = x.ravel()[small].astype(np.float64)
    series = np.zeros_like(xs)
    term = np.ones_like(xs)
    for n in range(18):  # |x| < 2: the terms fall below 1e-17 well before n = 18
        series += (-1) ** n * term / ((2 * n + a) * factorial(2 * n + 1))
        term = term * xs * xs
    out.ravel()[small] = series
    return out


def ball_spectrum(k: np.ndarray, r: float) -> np.ndarray:
    """Fourier transform of the indicator of the ball of radius r, at angular frequency |k| (float32)."""
    out = _radial_spectrum(np.asarray(k, np.float32) * np.float32(r), 3)
    out *= np.float32(4.0 * np.pi * r**3)
    return out


def ball_spectra(k: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Both :func:`ball_spectrum` and :func:`ball_moment2_spectrum`, sharing sin and cos."""
    x = np.asarray(k, np.float32) * np.float32(r)
    sc = (np.sin(x), np.cos(x))
    v = _radial_spectrum(x, 3, sc)
    v *= np.float32(4.0 * np.pi * r**3)
    p = _radial_spectrum(x, 5, sc)
    p *= np.float32(4.0 * np.pi * r**5)
    return v, p


def sphere_spectrum(k: np.ndarray, r: float) -> np.ndarray:
    """Fourier transform of the uniform measure on the sphere of radius r: 4 pi r^2 sin(x)/x, x = k r.

    It is d/dr of :func:`ball_spectrum`: convolved with an occupancy grid it gives the sphere
    area descriptor SA_r = dV_r/dr, with a squared-distance grid SD2_r (float32).
    """
    x = np.asarray(k, np.float32) * np.float32(r)
    out = np.sinc(x / np.float32(np.pi)).astype(np.float32)
    out *= np.float32(4.0 * np.pi * r * r)
    return out


def radial_on_grid(func, shape: tuple[int, int, int], h: float, *args):
    """Evaluate radial spectra ``func(k, *args)`` on an rfftn half-spectrum, using its symmetry.

    |omega| is even in the first two frequency axes, so each function is evaluated on
    one quadrant (a quarter of the work) and mirrored. ``func`` returns a tuple of arrays.
    """
    nx, ny = shape[0], shape[1]
    qx, qy = nx // 2 + 1, ny // 2 + 1
    k = frequency_norm(shape, h)[:qx, :qy]
    quadrant = func(k, *args)
    # fftfreq index i >= qx holds frequency -(n - i): mirror of index n - i
    mx = np.concatenate([np.arange(qx), nx - np.arange(qx, nx)])
    my = np.concatenate([np.arange(qy), ny - np.arange(qy, ny)])
    return tuple(q[mx][:, my] for q in quadrant)


def ball_moment2_spectrum(k: np.ndarray, r: float) -> np.ndarray:
    """Fourier transform of |y|^2 on the ball of radius r, zero outside (float32)."""
    out = _radial_spectrum(np.asarray(k, np.float32) * np.float32(r), 5)
    out *= np.float32(4.0 * np.pi * r**5)
    return out


def frequency_norm(shape: tuple[int, int, int], h: float) -> np.ndarray:
    """|omega| (angular, per unit length) on the ``rfftn`` half-spectrum of a grid, float32."""
    w = [2.0 * np.pi * np.fft.fftfreq(n, d=h) for n in shape[:2]] + [2.0 * np.pi * np.fft.rfftfreq(shape[2], d=h)]
    fx, fy, fz = (np.asarray(v, np.float32) ** 2 for v in w)
    return np.sqrt(fx[:, None, None] + fy[None, :, None] + fz[None, None, :])


def prefilter_axis(n: int, real: bool) -> np.ndarray:
    """One axis's factor of :func:`bspline_prefilter` (``real``: the ``rfftfreq`` axis)."""
    f = np.fft.rfftfreq(n) if real else np.fft.fftfreq(n)
    return 3.0 / (2.0 + np.cos(2.0 * np.pi * f))


def integration_axis(n: int, real: bool) -> np.ndarray:
    """One axis's factor of :func:`spline_integration` (``real``: the ``rfftfreq`` axis)."""
    f = np.fft.rfftfreq(n) if real else np.fft.fftfreq(n)
    x = np.pi * f  # omega h / 2
    return np.sinc(f) ** 4 * 3.0 / (2.0 + np.cos(2.0 * x))


def bspline_prefilter(shape: tuple[int, int, int]) -> np.ndarray:
    """Spectrum that turns samples into cubic B-spline coefficients (1 / the B-spline's DFT)."""
    axis = prefilter_axis
    return (
        axis(shape[0], False)[:, None, None]
        * axis(shape[1], False)[None, :, None]
        * axis(shape[2], True)[None, None, :]
    )


def _stencil(u: np.ndarray, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The 4x4x4 coefficients around fractional voxel indices ``u`` (k, 3): their flat
    indices (k, 64), clipped to the grid, and the offsets within the cell (k, 3)."""
    fl = np.floor(u)
    base = fl.astype(np.int64) - 1
    offsets = np.arange(4)
    ix, iy, iz = (np.clip(base[:, a, None] + offsets, 0, shape[a] - 1) for a in range(3))
    lin = (ix[:, :, None, None] * shape[1] + iy[:, None, :, None]) * shape[2] + iz[:, None, None, :]
    return lin.reshape(len(u), 64), u - fl


def _bspline_weights(t: np.ndarray) -> np.ndarray:
    """The cubic B-spline's four weights per axis at offsets ``t`` (k, 3): (k, 3, 4)."""
    t2, t3 = t * t, t * t * t
    return np.stack([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], axis=-1) / 6.0


def bspline_eval(coeffs: list[np.ndarray], points_grid: np.ndarray, *, chunk: int = 65536) -> np.ndarray:
    """Evaluate cubic B-splines (given by coefficient grids) at points in voxel-index units.

    Parameters
    ----------
    coeffs : m arrays of one shape (nx, ny, nz)
    points_grid : (n, 3) float, fractional voxel indices (at least 2 voxels from the edge)

    Returns
    -------
    (n, m) float64
    """
    flat = [c.ravel() for c in coeffs]
    n = len(points_grid)
    out = np.empty((n, len(coeffs)), np.float64)
    for s in range(0, n, chunk):
        u = points_grid[s : s + chunk]
        lin, t = _stencil(u, coeffs[0].shape)
        w = _bspline_weights(t)
        wt = (w[:, 0, :, None, None] * w[:, 1, None, :, None] * w[:, 2, None, None, :]).reshape(len(u), 64)
        for j, f in enumerate(flat):
            out[s : s + chunk, j] = np.einsum("ij,ij->i", f[lin], wt)
    return out


def bspline_gradient(coeff: np.ndarray, points_grid: np.ndarray, *, chunk: int = 65536) -> np.ndarray:
    """Gradient of a cubic B-spline (given by its coefficient grid) at points, in voxel-index units.

    Parameters
    ----------
    coeff : (nx, ny, nz) coefficients
    points_grid : (n, 3) float, fractional voxel indices (at least 2 voxels from the edge)

    Returns
    -------
    (n, 3) float64: d/du_x, d/du_y, d/du_z (divide by the spacing for length units)
    """
    flat = coeff.ravel()
    n = len(points_grid)
    out = np.empty((n, 3), np.float64)
    for s in range(0, n, chunk):
        u = points_grid[s : s + chunk]
        lin, t = _stencil(u, coeff.shape)
        w = _bspline_weights(t)
        t2 = t * t
        dw = np.stack([-3 * (1 - t) ** 2, 9 * t2 - 12 * t, -9 * t2 + 6 * t + 3, 3 * t2], axis=-1) / 6.0
        vals = flat[lin]
        for a in range(3):
            wa = [dw[:, i] if i == a else w[:, i] for i in range(3)]
            wt = (wa[0][:, :, None, None] * wa[1][:, None, :, None] * wa[2][:, None, None, :]).reshape(len(u), 64)
            out[s : s + chunk, a] = np.einsum("ij,ij->i", vals, wt)
    return out


def spline_integration(shape: tuple[int, int, int], h: float) -> np.ndarray:
    """Spectral factor that makes a kernel integrate the cubic spline through the samples.

    Multiplying a kernel's continuous Fourier transform by this factor (the cubic
    B-spline's transform, prod sinc^4(w h / 2), over its sampled transform) turns the
    FFT convolution into the exact integral of the cubic B-spline interpolant of the
    grid samples: exact for cubic polynomials, and local, so values a few voxels away
    from a ball do not leak into it as they do through a band-limited kernel.
    Aliases of the spline's spectrum are below 1e-5 of the kernel and neglected.
    """
    axis = integration_axis
    return (
        axis(shape[0], False)[:, None, None]
        * axis(shape[1], False)[None, :, None]
        * axis(shape[2], True)[None, None, :]
    )


def _ball_derivatives(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """psi = phi'(x)/x and phi''(x) for phi(x) = (sin x - x cos x)/x^3, the ball's profile.

    Series below x = 2 (the closed forms cancel there), closed forms above; float64.
    """
    x = np.asarray(x, dtype=np.float64)
    psi = np.empty_like(x)
    dd = np.empty_like(x)
    small = x < 2.0
    xs = x[small]
    p_s = np.zeros_like(xs)
    d_s = np.zeros_like(xs)
    term = np.ones_like(xs)  # x^(2n-2)
    for n in range(1, 19):
        c = (-1) ** n * 2 * n / ((2 * n + 3) * factorial(2 * n + 1))
        p_s += c * term
        d_s += c * (2 * n - 1) * term
        term = term * xs * xs
    psi[small], dd[small] = p_s, d_s
    xl = x[~small]
    s, c = np.sin(xl), np.cos(xl)
    psi[~small] = (xl * xl * s - 3 * s + 3 * xl * c) / xl**5
    dd[~small] = (xl**3 * c - 5 * xl * xl * s - 12 * xl * c + 12 * s) / xl**5
    return psi, dd


def ball_moment_spectra(shape: tuple[int, int, int], h: float, r: float) -> list[np.ndarray]:
    """Spectra of the first and second moment kernels of the ball, on an rfftn half-spectrum.

    Convolved with an occupancy grid they give, at p, ``m_i = ∫ (x - p)_i`` and
    ``M_ij = ∫ (x - p)_i (x - p)_j`` over ball(p, r) ∩ solid. With F(k) the ball's
    transform: first moments ``-i F'(k) w_i / k``; second moments
    ``-(F'' w_i w_j / k^2 + F'/k (delta_ij - w_i w_j / k^2))``.

    Returns
    -------
    [m_x, m_y, m_z, M_xx, M_yy, M_zz, M_xy, M_xz, M_yz] (complex64 for m, float32 for M)
    """
    def radial(k, r):
        psi, dd = _ball_derivatives(k * r)
        return (np.float32(4.0 * np.pi * r**5) * psi.astype(np.float32),
                np.float32(4.0 * np.pi * r**5) * dd.astype(np.float32))

    f1_over_k, f2 = radial_on_grid(radial, shape, h, r)  # F'(k)/k and F''(k), float32
    w = [np.float32(2.0 * np.pi) * np.fft.fftfreq(n, d=h).astype(np.float32) for n in shape[:2]]
    w.append(np.float32(2.0 * np.pi) * np.fft.rfftfreq(shape[2], d=h).astype(np.float32))
    wx, wy, wz = w[0][:, None, None], w[1][None, :, None], w[2][None, None, :]
    k2 = wx * wx + wy * wy + wz * wz
    k2[0, 0, 0] = 1.0  # the direction at k = 0 is undefined; its products are zeroed below
    inv_k2 = np.float32(1.0) / k2
    out = [(-1j * (f1_over_k * wi)).astype(np.complex64) for wi in (wx, wy, wz)]
    diff = f2 - f1_over_k  # spec = -(f1/k delta_ij + (F'' - F'/k) w_i w_j / k^2)
    for wi, wj, same in ((wx, wx, True), (wy, wy, True), (wz, wz, True), (wx, wy, False), (wx, wz, False), (wy, wz, False)):
        spec = diff * (wi * wj * inv_k2)
        if same:
            spec += f1_over_k
        spec *= np.float32(-1.0)
        spec[0, 0, 0] = 4.0 * np.pi * r**5 / 15.0 if same else 0.0
        out.append(spec)
    return out
