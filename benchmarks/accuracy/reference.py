"""High-accuracy reference values of the integral invariants V_r, P_r, D2_r.

For a solid D bounded by a surface, a point p on the surface and a radius r:
V_r = vol(ball(p, r) ∩ D), P_r = ∫_{ball ∩ D} |x - p|^2, D2_r = ∫_ball dist(x, surface)^2.

Sphere (radius Rs, query point at distance D from the centre, any D > 0): closed forms.
V is the lens volume; P = ∫_0^r ρ^2 A(ρ) dρ and D2 = ∫ (s - Rs)^2 a(s) ds, where the
area of the sphere of radius ρ about p inside the solid, A(ρ) = 2πρ^2 (1 + μ(ρ)), and
the area of the sphere of radius s about the centre inside the ball, a(s), are
polynomials on each piece between their kinks: Gauss-Legendre on each piece is exact.

Any implicit surface (the exact torus; the sphere, to validate): V and P by slicing the
ball into spheres about p, V = ∫_0^r A(ρ) dρ, P = ∫_0^r ρ^2 A(ρ) dρ. A(ρ) is smooth
(analytic) in ρ for ρ below the reach, so Gauss-Legendre in ρ converges exponentially;
A(ρ) = ρ^2 ∫_0^{2π} dφ ∫ 1_inside sin θ dθ, where θ is the angle from the inward normal
at p: the inside arcs of each meridian are found exactly (sign changes on a θ grid,
then bisection to rounding) and sin θ integrated over them in closed form; the inside
region's boundary θ_b(φ) is smooth and periodic, so the trapezoid rule in φ converges
exponentially too. (Integrating along rays first instead, as in :func:`vp_rays`, leaves
a kink on the sphere of directions - where the ray's exit crosses ρ = r - that limits
any direction rule to algebraic convergence: it is kept as an independent cross-check.)
D2: dist^2 = sdf^2 is smooth in the ball when r is below the reach, so a product rule
- Gauss-Legendre in ρ and in cos θ, trapezoid in φ - converges exponentially.

Every result carries an error estimate: the difference from the same computation at
about 2/3 of the nodes in every direction.

    python -m benchmarks.accuracy.reference        # validation against the sphere's closed forms
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np


# ---------------------------------------------------------------------------------------
# implicit surfaces: signed distance (negative inside) and its gradient


@dataclass(frozen=True)
class ImplicitSphere:
    R: float = 1.0

    def sdf(self, x: np.ndarray) -> np.ndarray:
        return np.sqrt(np.einsum("...i,...i->...", x, x)) - self.R

    def grad(self, x: np.ndarray) -> np.ndarray:
        return x / np.linalg.norm(x, axis=-1, keepdims=True)

    @property
    def reach(self) -> float:
        return self.R


@dataclass(frozen=True)
class ImplicitTorus:
    """Torus about the z axis: tube radius a around the circle of radius R in z = 0."""

    R: float = 1.0
    a: float = 0.45

    def sdf(self, x: np.ndarray) -> np.ndarray:
        return np.hypot(np.hypot(x[..., 0], x[..., 1]) - self.R, x[..., 2]) - self.a

    def grad(self, x: np.ndarray) -> np.ndarray:
        q = np.hypot(x[..., 0], x[..., 1])
        dr = q - self.R
        n = np.hypot(dr, x[..., 2])
        return np.stack([dr / n * x[..., 0] / q, dr / n * x[..., 1] / q, x[..., 2] / n], axis=-1)

    @property
    def reach(self) -> float:
        return min(self.a, self.R - self.a)


@dataclass
class Reference:
    """Reference integrals at n points and m radii, with estimated absolute quadrature errors."""

    V: np.ndarray
    P: np.ndarray
    D2: np.ndarray
    err_V: np.ndarray
    err_P: np.ndarray
    err_D2: np.ndarray
    seconds: float = 0.0

    def max_relative_errors(self) -> tuple[float, float, float]:
        return (float(np.max(self.err_V / np.abs(self.V))), float(np.max(self.err_P / np.abs(self.P))),
                float(np.max(self.err_D2 / np.abs(self.D2))))


# ---------------------------------------------------------------------------------------
# sphere: closed forms


def lens_volume(Rs, D, r):
    """vol(ball(c, Rs) ∩ ball(p, r)) with |p - c| = D (any D >= 0)."""
    Rs, D, r = np.broadcast_arrays(np.asarray(Rs, float), np.asarray(D, float), np.asarray(r, float))
    out = np.empty(Rs.shape)
    small = np.minimum(Rs, r)
    contained = D <= np.abs(Rs - r)
    apart = D >= Rs + r
    lens = ~contained & ~apart
    out[contained] = 4.0 * np.pi / 3.0 * small[contained] ** 3
    out[apart] = 0.0
    Rl, Dl, rl = Rs[lens], D[lens], r[lens]
    out[lens] = (np.pi * (Rl + rl - Dl) ** 2
                 * (Dl * Dl + 2 * Dl * rl - 3 * rl * rl + 2 * Dl * Rl + 6 * rl * Rl - 3 * Rl * Rl) / (12 * Dl))
    return out


_GL8 = np.polynomial.legendre.leggauss(8)


def _gauss_pieces(f, breaks):
    """∫ f over consecutive pieces [breaks[i], breaks[i+1]] by 8-point Gauss-Legendre
    (exact for the polynomials of degree <= 15 that f is on each piece)."""
    x, w = _GL8
    total = 0.0
    for lo, hi in zip(breaks[:-1], breaks[1:]):
        if hi > lo:
            t = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
            total += 0.5 * (hi - lo) * float(np.dot(w, f(t)))
    return total


def sphere_moment(Rs: float, D: float, r: float, k: int) -> float:
    """∫_{ball(p,r) ∩ ball(c,Rs)} |x - p|^(k-2) dx with |p - c| = D > 0 (k = 2: V, k = 4: P).

    The area of the sphere of radius ρ about p inside the ball of radius Rs is
    2πρ^2 (1 + μ), μ = clip((Rs^2 - D^2 - ρ^2) / (2ρD), -1, 1); between the kinks
    ρ = |Rs - D| and Rs + D, ρ^k (1 + μ) = ρ^(k-1) (Rs - D + ρ)(Rs + D - ρ) / (2D), a polynomial.
    """
    lo, hi = abs(Rs - D), Rs + D
    total = 0.0
    if D < Rs:  # p inside: whole spheres up to Rs - D
        a = min(r, lo)
        total += 4.0 * np.pi * a ** (k + 1) / (k + 1)
    total += _gauss_pieces(lambda t: 2 * np.pi * t ** (k - 1) * (Rs - D + t) * (Rs + D - t) / (2 * D),
                           [min(r, lo), min(r, hi)])
    return total


def sphere_d2(Rs: float, D: float, r: float) -> float:
    """∫_{ball(p, r)} (|x - c| - Rs)^2 dx with |p - c| = D.

    Shells |x - c| = s: the area inside the ball is 2πs^2 (1 - ν), ν = clip((s^2 + D^2 - r^2)/(2sD)),
    which is π s (r^2 - (s - D)^2) / D for |D - r| < s < D + r, and 4πs^2 for s < r - D.
    """
    total = 0.0
    if D < r:  # the centre is in the ball: whole shells up to r - D
        total += _gauss_pieces(lambda s: 4 * np.pi * s * s * (s - Rs) ** 2, [0.0, r - D])
    total += _gauss_pieces(lambda s: np.pi * s * (r * r - (s - D) ** 2) / D * (s - Rs) ** 2,
                           [abs(D - r), D + r])
    return total


def sphere_reference(points: np.ndarray, radii, Rs: float = 1.0, centre=(0.0, 0.0, 0.0)) -> Reference:
    """Closed-form V, P, D2 for the ball of radius Rs about centre, at any points (off the centre)."""
    t0 = time.perf_counter()
    D = np.linalg.norm(np.asarray(points, float) - np.asarray(centre, float), axis=1)
    radii = np.atleast_1d(np.asarray(radii, float))
    V = lens_volume(Rs, D[:, None], radii[None, :])
    P = np.array([[sphere_moment(Rs, d, r, 4) for r in radii] for d in D]).reshape(len(D), len(radii))
    D2 = np.array([[sphere_d2(Rs, d, r) for r in radii] for d in D]).reshape(len(D), len(radii))
    eps = np.finfo(float).eps
    return Reference(V, P, D2, 64 * eps * V, 64 * eps * P, 64 * eps * D2, time.perf_counter() - t0)


# ---------------------------------------------------------------------------------------
# implicit surfaces: spherical slicing (V, P) and product rule (D2)


def _frames(surface, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = surface.grad(points)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    t1 = np.cross(n, e)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return n, t1, t2


def _inside_measure(surface, p, n, t1, t2, rho, phi, n_theta: int, iters: int = 56):
    """∫_0^π 1[p + ρ u(θ, φ) inside] sin θ dθ for each (point, ρ, φ); θ from the inward normal.

    p, n, t1, t2 : (c, 3); rho : (c, nr) (per point, radius-scaled nodes); phi : (nphi,).
    Returns (c, nr, nphi), and the largest number of crossings found on one meridian.
    """
    theta = np.linspace(0.0, np.pi, n_theta + 1)
    cphi, sphi = np.cos(phi), np.sin(phi)
    # meridian direction m(φ) in the tangent plane: (c, nphi, 3)
    m = cphi[None, :, None] * t1[:, None, :] + sphi[None, :, None] * t2[:, None, :]

    def point(th):  # th broadcastable to (c, nr, nphi, k): positions (c, nr, nphi, k, 3)
        u = (np.cos(th)[..., None] * (-n)[:, None, None, None, :]
             + np.sin(th)[..., None] * m[:, None, :, None, :])
        return p[:, None, None, None, :] + rho[:, :, None, None, None] * u

    s = surface.sdf(point(theta[None, None, None, :]))  # (c, nr, nphi, n_theta + 1)
    inside = s < 0
    cos_t = np.cos(theta)
    seg = cos_t[:-1] - cos_t[1:]  # ∫ sin over each cell
    total = (inside[..., :-1] & inside[..., 1:]) @ seg  # cells with no crossing, inside
    change = inside[..., :-1] != inside[..., 1:]
    crossings = int(change.sum(axis=-1).max())
    idx = np.nonzero(change)
    lo = theta[idx[3]].copy()
    hi = theta[idx[3] + 1].copy()
    lo_inside = inside[idx[0], idx[1], idx[2], idx[3]]
    pc, nc, mc = p[idx[0]], n[idx[0]], m[idx[0], idx[2]]
    rc = rho[idx[0], idx[1]]

    def sdf_at(th):
        x = pc + rc[:, None] * (np.cos(th)[:, None] * (-nc) + np.sin(th)[:, None] * mc)
        return surface.sdf(x)

    for _ in range(iters):  # bisection: the bracket shrinks to rounding
        mid = 0.5 * (lo + hi)
        mid_inside = sdf_at(mid) < 0
        same = mid_inside == lo_inside
        lo = np.where(same, mid, lo)
        hi = np.where(same, hi, mid)
    root = 0.5 * (lo + hi)
    part = np.where(lo_inside, cos_t[idx[3]] - np.cos(root), np.cos(root) - cos_t[idx[3] + 1])
    np.add.at(total, idx[:3], part)
    return total, crossings


def _vp_slicing(surface, points, r, n_rho, n_phi, n_theta, chunk=8):
    x, w = np.polynomial.legendre.leggauss(n_rho)
    rho = 0.5 * r * (x + 1.0)
    wr = 0.5 * r * w
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    n, t1, t2 = _frames(surface, points)
    V = np.empty(len(points))
    P = np.empty(len(points))
    most = 0
    for s in range(0, len(points), chunk):
        sl = slice(s, s + chunk)
        c = len(points[sl])
        meas, cr = _inside_measure(surface, points[sl], n[sl], t1[sl], t2[sl],
                                   np.broadcast_to(rho, (c, n_rho)), phi, n_theta)
        most = max(most, cr)
        A = rho**2 * meas.sum(axis=-1) * (2.0 * np.pi / n_phi)  # (c, n_rho)
        V[sl] = A @ wr
        P[sl] = A @ (wr * rho**2)
    return V, P, most


def _d2_product(surface, points, r, n_rho, n_mu, n_phi, chunk=8):
    x, w = np.polynomial.legendre.leggauss(n_rho)
    rho = 0.5 * r * (x + 1.0)
    wr = 0.5 * r * w * rho**2
    mu, wmu = np.polynomial.legendre.leggauss(n_mu)
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    st = np.sqrt(1.0 - mu * mu)
    u = np.stack([np.outer(st, np.cos(phi)), np.outer(st, np.sin(phi)),
                  np.broadcast_to(mu[:, None], (n_mu, n_phi))], axis=-1)  # (n_mu, n_phi, 3)
    wdir = np.broadcast_to(wmu[:, None] * (2.0 * np.pi / n_phi), (n_mu, n_phi))
    out = np.empty(len(points))
    for s in range(0, len(points), chunk):
        p = points[s:s + chunk]
        xq = p[:, None, None, None, :] + rho[None, :, None, None, None] * u[None, None]
        d2 = surface.sdf(xq) ** 2  # (c, n_rho, n_mu, n_phi)
        out[s:s + chunk] = np.einsum("cijk,i,jk->c", d2, wr, wdir)
    return out


def implicit_reference(surface, points: np.ndarray, radii, *, n_rho: int = 48, n_phi: int = 192,
                       n_theta: int = 32, n_mu: int = 48, n_phi_d2: int = 96,
                       with_error: bool = True) -> Reference:
    """V, P, D2 of an implicit surface at points on it, radii below the surface's reach.

    The error estimate is |result - result at 2/3 of the nodes| (exponential convergence:
    the estimate bounds the error of the coarse rule, far above that of the fine one).
    """
    t0 = time.perf_counter()
    points = np.asarray(points, float)
    radii = np.atleast_1d(np.asarray(radii, float))
    if np.any(radii >= surface.reach):
        raise ValueError(f"radii must be below the reach {surface.reach}")
    shape = (len(points), len(radii))
    out = {k: np.empty(shape) for k in ("V", "P", "D2", "eV", "eP", "eD2")}
    for j, r in enumerate(radii):
        V, P, crossings = _vp_slicing(surface, points, r, n_rho, n_phi, n_theta)
        if crossings > 1:
            raise RuntimeError(f"a meridian crossed the surface {crossings} times at r={r}: refine n_theta")
        D2 = _d2_product(surface, points, r, n_rho, n_mu, n_phi_d2)
        out["V"][:, j], out["P"][:, j], out["D2"][:, j] = V, P, D2
        if with_error:
            V2, P2, _ = _vp_slicing(surface, points, r, (2 * n_rho) // 3, (2 * n_phi) // 3, n_theta)
            D22 = _d2_product(surface, points, r, (2 * n_rho) // 3, (2 * n_mu) // 3, (2 * n_phi_d2) // 3)
            out["eV"][:, j], out["eP"][:, j], out["eD2"][:, j] = abs(V - V2), abs(P - P2), abs(D2 - D22)
        else:
            out["eV"][:, j] = out["eP"][:, j] = out["eD2"][:, j] = np.nan
    return Reference(out["V"], out["P"], out["D2"], out["eV"], out["eP"], out["eD2"], time.perf_counter() - t0)


def torus_reference(points: np.ndarray, radii, R: float = 1.0, a: float = 0.45, **kw) -> Reference:
    """V, P, D2 of the exact torus at points on it (see :func:`implicit_reference`)."""
    return implicit_reference(ImplicitTorus(R, a), points, radii, **kw)


# ---------------------------------------------------------------------------------------
# cross-check: integrate along rays first (ray-torus quartic, solved for all rays at once)


def fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0**0.5) * i
    s = np.sqrt(1.0 - z * z)
    return np.column_stack([s * np.cos(phi), s * np.sin(phi), z])


def vp_rays(torus: ImplicitTorus, p: np.ndarray, r: float, directions: np.ndarray) -> tuple[float, float]:
    """V and P at one point by equal-weight direction quadrature of the exact radial integrals.

    Along p + ρu, |x|^2 = ρ^2 + 2bρ + |p|^2 (b = p·u) and the torus is
    (|x|^2 + R^2 - a^2)^2 - 4R^2 (x^2 + y^2) = 0, a quartic in ρ; its roots in ρ/r are the
    eigenvalues of the companion matrices (batched), polished by Newton steps; inside
    intervals are decided at the midpoints and ∫ρ^2, ∫ρ^4 taken in closed form.
    """
    R, a = torus.R, torus.a
    u = directions
    b = u @ p
    c = p @ p + R * R - a * a
    w0 = p[0] ** 2 + p[1] ** 2
    w1 = p[0] * u[:, 0] + p[1] * u[:, 1]
    w2 = u[:, 0] ** 2 + u[:, 1] ** 2
    # monic quartic in t = ρ / r
    c3 = 4 * b / r
    c2 = (4 * b * b + 2 * c - 4 * R * R * w2) / r**2
    c1 = (4 * b * c - 8 * R * R * w1) / r**3
    c0 = np.full_like(b, (c * c - 4 * R * R * w0) / r**4)
    comp = np.zeros((len(u), 4, 4))
    comp[:, 0, :] = -np.stack([c3, c2, c1, c0], axis=1)
    comp[:, 1, 0] = comp[:, 2, 1] = comp[:, 3, 2] = 1.0
    ev = np.linalg.eigvals(comp)
    t = ev.real.copy()
    real = np.abs(ev.imag) < 1e-6
    for _ in range(3):
        f = (((t + c3[:, None]) * t + c2[:, None]) * t + c1[:, None]) * t + c0[:, None]
        df = ((4 * t + 3 * c3[:, None]) * t + 2 * c2[:, None]) * t + c1[:, None]
        t = np.where(np.abs(df) > 1e-12, t - f / np.where(df == 0, 1, df), t)
    t = np.where(real & (t > 0) & (t < 1), t, 1.0)
    br = np.sort(np.concatenate([np.zeros((len(u), 1)), t, np.ones((len(u), 1))], axis=1), axis=1)
    mid = 0.5 * (br[:, :-1] + br[:, 1:])
    inside = torus.sdf(p + r * mid[..., None] * u[:, None, :]) < 0
    V = (inside * (br[:, 1:] ** 3 - br[:, :-1] ** 3)).sum() * r**3 / 3
    P = (inside * (br[:, 1:] ** 5 - br[:, :-1] ** 5)).sum() * r**5 / 5
    return 4 * np.pi / len(u) * V, 4 * np.pi / len(u) * P


# ---------------------------------------------------------------------------------------


def _validate() -> None:
    """Print the reference's own accuracy checks (this module run as a script)."""
    from benchmarks.common import start
    from data_synth.shapes import torus_curvatures

    start()
    rng = np.random.default_rng(0)
    print("1. closed forms: lens volume vs piecewise-exact Gauss (V), D2 on a huge sphere vs the plane's 4 pi r^5/15")
    worst = 0.0
    for Rs, D, r in [(1.0, 1.0, 0.3), (1.0, 0.999, 0.1), (1.0, 1.003, 0.2), (0.5, 0.7, 0.4), (1.0, 0.1, 0.5)]:
        worst = max(worst, abs(sphere_moment(Rs, D, r, 2) / lens_volume(Rs, D, r) - 1))
    d2_plane = sphere_d2(1e6, 1e6, 0.2) / (4 * np.pi * 0.2**5 / 15) - 1
    print(f"   max relative difference, V: {worst:.1e}; D2 (R = 1e6): {d2_plane:.1e}")

    print("2. slicing (V, P) and product rule (D2) on the implicit sphere vs the closed forms")
    print("   Rs    r     max rel err V   P        D2        (estimated: V, P, D2)")
    for Rs, r in [(1.0, 0.1), (1.0, 0.5), (0.3, 0.2)]:
        pts = rng.normal(size=(20, 3))
        pts *= Rs / np.linalg.norm(pts, axis=1, keepdims=True)
        num = implicit_reference(ImplicitSphere(Rs), pts, [r])
        ref = sphere_reference(pts, [r], Rs)
        e = [np.max(np.abs(getattr(num, k) / getattr(ref, k) - 1)) for k in ("V", "P", "D2")]
        est = num.max_relative_errors()
        print(f"   {Rs:<5g} {r:<5g} {e[0]:.1e}        {e[1]:.1e}  {e[2]:.1e}   ({est[0]:.0e}, {est[1]:.0e}, {est[2]:.0e})")

    print("3. torus R=1, a=0.45, 50 random surface points")
    torus = ImplicitTorus(1.0, 0.45)
    uu, vv = rng.uniform(0, 2 * np.pi, (2, 50))
    rho = 1 + 0.45 * np.cos(vv)
    pts = np.column_stack([rho * np.cos(uu), rho * np.sin(uu), 0.45 * np.sin(vv)])
    radii = [0.05, 0.1, 0.2]
    ref = torus_reference(pts, radii)
    ev, ep, ed = ref.max_relative_errors()
    print(f"   {ref.seconds:.1f} s for 50 points x 3 radii (with the error estimate); estimated max relative "
          f"error: V {ev:.1e}, P {ep:.1e}, D2 {ed:.1e}")
    H, K2 = torus_curvatures(pts, 1.0, 0.45)
    from reassemble.descriptors import curvature_difference_sq, mean_curvature
    for j, r in enumerate(radii):
        print(f"   r={r:<5g} H(V_ref) - H: RMS {np.sqrt(np.mean((mean_curvature(ref.V[:, j], r) - H) ** 2)):.2e}; "
              f"K2(D2_ref) - K2: RMS {np.sqrt(np.mean((curvature_difference_sq(ref.D2[:, j], r) - K2) ** 2)):.2e}"
              f"  (Taylor truncation: ~r^2)")
    print("4. ray integration (Fibonacci directions, vectorized quartic) vs slicing, first 5 points, r = 0.2")
    for n_dirs in (20_000, 100_000):
        dirs = fibonacci_sphere(n_dirs)
        t = time.perf_counter()
        vp = np.array([vp_rays(torus, p, 0.2, dirs) for p in pts[:5]])
        dt = (time.perf_counter() - t) / 5
        eV = np.max(np.abs(vp[:, 0] / ref.V[:5, 2] - 1))
        eP = np.max(np.abs(vp[:, 1] / ref.P[:5, 2] - 1))
        print(f"   {n_dirs:>7d} directions ({dt:.2f} s/point): max rel difference V {eV:.1e}, P {eP:.1e}")


if __name__ == "__main__":
    _validate()
