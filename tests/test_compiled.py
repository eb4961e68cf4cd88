"""The compiled convolution loops against the numpy reference implementations in kernels."""

import numpy as np
import pytest
from scipy.fft import irfftn, rfftn

from reassemble.descriptors.compiled import BALL, BALL_MOMENT2, SPHERE, moment_products, radial_products, spline_at
from reassemble.descriptors.kernels import (
    ball_moment_spectra,
    ball_spectra,
    bspline_eval,
    bspline_gradient,
    bspline_prefilter,
    radial_on_grid,
    sphere_spectrum,
    spline_integration,
)


def _reference_factor(shape, h):
    return (bspline_prefilter(shape) * spline_integration(shape, h)).astype(np.float32)


@pytest.mark.parametrize("shape", [(33, 40, 27), (64, 51, 80), (20, 20, 21)])
def test_radial_products_match_numpy(shape):
    rng = np.random.default_rng(0)
    h, r = 0.01, 0.07
    spectrum = rfftn(rng.random(shape).astype(np.float32))
    ball, moment = radial_on_grid(ball_spectra, shape, h, r)
    (sphere,) = radial_on_grid(lambda k, r: (sphere_spectrum(k, r),), shape, h, r)
    pre = _reference_factor(shape, h)
    got = radial_products(spectrum, shape, h, r, [BALL, BALL_MOMENT2, SPHERE])
    for kernel, product in zip((ball, moment, sphere), got):
        want = spectrum * (kernel * pre)
        assert np.abs(product - want).max() < 1e-6 * np.abs(want).max()


@pytest.mark.parametrize("shape", [(33, 40, 27), (64, 50, 80)])
def test_moment_products_match_numpy(shape):
    rng = np.random.default_rng(1)
    h, r = 0.01, 0.08
    spectrum = rfftn(rng.random(shape).astype(np.float32))
    pre = _reference_factor(shape, h)
    got = moment_products(spectrum, shape, h, r)
    for kernel, product in zip(ball_moment_spectra(shape, h, r)[3:], got):  # xx, yy, zz, xy, xz, yz
        want = spectrum * (kernel * pre)
        assert np.abs(product - want).max() < 1e-6 * np.abs(want).max()


def test_spline_at_matches_numpy_and_clips_like_it():
    rng = np.random.default_rng(2)
    coeff = rng.random((30, 25, 40)).astype(np.float32)
    u = rng.random((500, 3)) * (np.array(coeff.shape) + 2) - 1  # some stencils leave the grid
    value, gradient = spline_at(coeff, u, gradient=True)
    assert np.allclose(value, bspline_eval([coeff], u)[:, 0], rtol=0, atol=1e-12)
    assert np.allclose(gradient, bspline_gradient(coeff, u), rtol=0, atol=1e-12)
    assert np.array_equal(spline_at(coeff, u), value)


def test_first_moments_from_the_gradients_of_v_and_p():
    """m = (r^2 grad V - grad P) / 2 (the identity the descriptors use instead of three FFTs),
    against the first-moment kernels convolved directly, on a ball's smoothed occupancy."""
    n, h, r = 64, 1.0 / 64, 0.15
    x = (np.arange(n) - n / 2 + 0.3) * h
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    occ = np.clip(0.5 - (np.sqrt(X**2 + Y**2 + Z**2) - 0.3) / (2 * h), 0, 1).astype(np.float32)
    spectrum = rfftn(occ)
    shape = occ.shape
    V, P = (irfftn(p, s=shape) for p in radial_products(spectrum, shape, h, r, [BALL, BALL_MOMENT2]))
    pre = _reference_factor(shape, h)
    direct = [irfftn(spectrum * (k * pre), s=shape) for k in ball_moment_spectra(shape, h, r)[:3]]
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(200, 3))
    pts = 0.3 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)  # on the sphere
    u = (pts - x[0]) / h
    m = 0.5 * (r * r * spline_at(V, u, gradient=True)[1] - spline_at(P, u, gradient=True)[1]) / h
    want = bspline_eval(direct, u)
    assert np.abs(m - want).max() < 5e-4 * np.abs(want).max()  # measured 5e-5; a sign slip: 1.9
