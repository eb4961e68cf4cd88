"""Integral invariants: kernels, interpolation, and accuracy on shapes with known answers.

Tolerances come from the targets (0.5 % of H for V_r on a sphere, 0.5 % for D2_r on a
plane) or from the theory of the estimators, measured here well inside them.
"""

import numpy as np
import pytest
import trimesh
from scipy.integrate import quad

from reassemble.descriptors import DescriptorParams, integral_invariants
from reassemble.descriptors.kernels import _radial_spectrum, ball_moment2_spectrum, ball_spectrum, bspline_eval, bspline_prefilter
from reassemble.errors import ReassembleError
from reassemble.geometry import make_transform, random_rotation, transform_points


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(subdivisions=6)  # 40962 vertices on the unit sphere
    return np.asarray(m.vertices), np.asarray(m.faces), (3 * m.volume / (4 * np.pi)) ** (1 / 3)


def lens_volume(r, R, D):
    """Volume of ball(p, r) ∩ ball(0, R) with |p| = D."""
    return np.pi * (R + r - D) ** 2 * (D**2 + 2 * D * r - 3 * r**2 + 2 * D * R + 6 * R * r - 3 * R**2) / (12 * D)


def sphere_moment2(r, R, D):
    """∫ over ball(p, r) ∩ ball(0, R) of |x - p|^2, by quadrature over spheres around p."""
    def f(rho):
        mu = np.clip((R * R - D * D - rho * rho) / (2 * rho * D), -1, 1)
        return rho**4 * 2 * np.pi * (1 + mu)
    return quad(f, 0, r, epsabs=0, epsrel=1e-12, limit=200)[0]


def test_kernel_spectra_match_numerical_transforms():
    r = 0.7
    for k in (0.0, 0.3, 2.0 / r, 2.0001 / r, 5.0, 23.0):
        def radial(g):
            if k == 0:
                return quad(lambda rho: 4 * np.pi * rho**2 * g(rho), 0, r)[0]
            return quad(lambda rho: 4 * np.pi * rho * g(rho) * np.sin(k * rho) / k, 0, r, limit=200)[0]
        assert ball_spectrum(np.array([k]), r)[0] == pytest.approx(radial(lambda p: 1.0), rel=2e-6, abs=1e-7)
        assert ball_moment2_spectrum(np.array([k]), r)[0] == pytest.approx(radial(lambda p: p * p), rel=2e-6, abs=1e-7)
    x = np.array([1.999999, 2.0, 2.000001])  # series and closed form meet without a jump
    for a in (3, 5):
        v = _radial_spectrum(x, a)
        assert np.ptp(v) < 1e-6


def test_bspline_interpolation_reproduces_smooth_fields():
    from scipy.fft import irfftn, rfftn

    shape = (24, 20, 28)
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1).astype(float)
    f = lambda u: np.sin(2 * np.pi * u[..., 0] / shape[0]) * np.cos(4 * np.pi * u[..., 1] / shape[1]) + np.cos(2 * np.pi * u[..., 2] / shape[2])  # noqa: E731
    coeffs = irfftn(rfftn(f(ijk)) * bspline_prefilter(shape), s=shape)
    pts = np.random.default_rng(0).uniform(3, 17, (500, 3))
    got = bspline_eval([coeffs], pts)[:, 0]
    assert np.abs(got - f(pts)).max() < 2e-3  # fourth-order: (2 pi / 20)^4 / 384 scale


def test_volume_descriptor_on_a_sphere(sphere):
    V, F, R = sphere
    radii = np.array([0.15, 0.3])
    q = V[::40]
    d = integral_invariants(V, F, radii, points=q, params=DescriptorParams(with_d2=False))
    D = np.linalg.norm(q, axis=1)
    for j, r in enumerate(radii):
        dH = 4 * (d.V[:, j] - lens_volume(r, R, D)) / (np.pi * r**4)
        assert np.sqrt(np.mean(dH**2)) < 0.005  # target: 0.5 % of H = 1
        ref_P = sphere_moment2(r, R, 1.0)
        ref_Hrob = 12 * lens_volume(r, R, 1.0) / (np.pi * r**4) + 8 / (5 * r) - 24 * ref_P / (np.pi * r**6)
        assert np.sqrt(np.mean((d.H_rob[:, j] - ref_Hrob) ** 2)) < 0.01


def test_robust_mean_curvature_ignores_offsets(sphere):
    """Query points 0.4 % of the radius off the sphere: H moves by 4 δ/r², H_rob does not."""
    V, F, _ = sphere
    r, delta = 0.2, 0.004
    q = V[::80]
    base = integral_invariants(V, F, [r], points=q, params=DescriptorParams(with_d2=False))
    moved = integral_invariants(V, F, [r], points=q * (1 - delta), params=DescriptorParams(with_d2=False))
    shift = moved.H[:, 0] - base.H[:, 0]
    assert np.mean(shift) == pytest.approx(-4 * delta / r**2, rel=0.05)
    assert np.abs(moved.H_rob[:, 0] - base.H_rob[:, 0]).mean() < 0.03 * abs(np.mean(shift))


def test_squared_distance_integral_on_a_plane():
    box = trimesh.creation.box(extents=(4.0, 4.0, 4.0))
    V, F = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, 0.5)
    q = np.array([[0.0, 0.0, 2.0], [0.3, -0.2, 2.0], [2.0, 0.1, 0.4]])
    radii = [0.25, 0.5]
    d = integral_invariants(V, F, radii, points=q)
    for j, r in enumerate(radii):
        exact = 4 * np.pi * r**5 / 15
        assert np.abs(d.D2[:, j] / exact - 1).max() < 0.005
        assert np.abs(d.H[:, j]).max() < 0.02 / r  # flat: mean curvature ~0 on the scale 1/r


def test_descriptors_are_rigid_and_scale_covariant(rng):
    mesh = trimesh.creation.capsule(height=1.0, radius=0.4, count=[24, 24])
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    radii = [0.1, 0.25]
    q = V[::17]
    base = integral_invariants(V, F, radii, points=q, params=DescriptorParams(with_d2=False))
    T = make_transform(random_rotation(rng), rng.normal(size=3) * 10)
    moved = integral_invariants(transform_points(T, V), F, radii, points=transform_points(T, q),
                                params=DescriptorParams(with_d2=False))
    assert np.allclose(moved.H, base.H, atol=0.02 * np.abs(base.H).max())
    s = 250.0  # millimetres instead of decimetres, say
    scaled = integral_invariants(V * s, F, np.array(radii) * s, points=q * s, params=DescriptorParams(with_d2=False))
    assert np.allclose(scaled.V / s**3, base.V, rtol=2e-3)
    assert np.allclose(scaled.H * s, base.H, atol=0.02 * np.abs(base.H).max())


def test_bad_radii_and_memory_are_named():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    V, F = mesh.vertices, mesh.faces
    with pytest.raises(ReassembleError, match="positive"):
        integral_invariants(V, F, [0.1, 0.0])
    with pytest.raises(ReassembleError, match="larger than the object"):
        integral_invariants(V, F, [10.0])
    with pytest.raises(ReassembleError, match="--max-memory"):
        integral_invariants(V, F, [0.001], params=DescriptorParams(max_memory=1e6))


def test_descriptors_are_deterministic():
    mesh = trimesh.creation.icosphere(subdivisions=3)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    a = integral_invariants(V, F, [0.3, 0.5])
    b = integral_invariants(V, F, [0.3, 0.5])
    for key in ("V", "P", "D2", "H", "H_rob", "K2"):
        assert np.array_equal(getattr(a, key), getattr(b, key))


def test_principal_curvatures_on_a_torus():
    """Covariance of ball ∩ solid: k1 = 1/a around the tube, normals and directions exact."""
    from data_synth.shapes import torus_curvatures, torus_mesh

    R, a, r = 1.0, 0.45, 0.2
    v, f = torus_mesh(R, a, target_vertices=20000)
    q = v[:: len(v) // 150]
    d = integral_invariants(v, f, [r], points=q, params=DescriptorParams(principal=True, with_d2=False))
    _, K2 = torus_curvatures(q, R, a)
    assert np.sqrt(np.mean((d.K2_cov[:, 0] - K2) ** 2)) < 0.1 * np.sqrt(np.mean(K2**2))
    assert np.abs(d.k1[:, 0] - 1 / a).max() < 0.05 / a
    rho = np.hypot(q[:, 0], q[:, 1])
    centre = np.column_stack([q[:, 0] / rho * R, q[:, 1] / rho * R, np.zeros(len(q))])
    n_true = (q - centre) / a
    assert np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d.normal[:, 0], n_true), -1, 1))).max() < 3
    around = np.column_stack([-q[:, 1], q[:, 0], np.zeros(len(q))]) / rho[:, None]
    assert np.abs(np.einsum("ij,ij->i", d.dir1[:, 0], around)).max() < 0.1  # k1 runs around the tube
