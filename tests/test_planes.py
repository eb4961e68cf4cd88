"""Planar break faces: found on noisy samples, and the placement they give is the true one."""

import numpy as np

from reassemble.geometry import make_transform, random_rotation, rotation_angle_deg, transform_points
from reassemble.planes import planar_patches, plane_placements


def _cut(rng, n=4000, noise=0.0):
    """Area-uniform samples of a plane cut through a ring (two separate 2 x 0.5 rectangles on
    z = 0, 3 apart) and of a rough, curved remainder above it; normals +z on the cut."""
    cut = rng.uniform([-0.25, -1.0], [0.25, 1.0], size=(n // 2, 2))
    cut[: n // 4, 0] += 3.0  # the second crossing of the ring
    cut = np.column_stack([cut, noise * rng.standard_normal(n // 2)])
    theta = rng.uniform(0, np.pi, n // 2)
    dome = np.column_stack([1.5 + 1.2 * np.cos(theta), rng.uniform(-1, 1, n // 2), 0.3 + 1.2 * np.sin(theta)])
    dome_n = np.column_stack([np.cos(theta), np.zeros(n // 2), np.sin(theta)])
    normals = np.vstack([np.tile([0.0, 0.0, 1.0], (n // 2, 1)), dome_n])
    if noise:  # face normals of a noisy mesh stray by tens of degrees
        normals = normals + 0.3 * rng.standard_normal(normals.shape)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return np.vstack([cut, dome]), normals, 2.0 / (n // 2)  # the cut's area is 2


def test_a_plane_cut_in_two_places_is_one_patch_under_noise():
    rng = np.random.default_rng(0)
    points, normals, area = _cut(rng, noise=0.003)
    patches = planar_patches(points, normals, area, tol=0.01, min_area=0.2, rng=np.random.default_rng(1))
    assert len(patches) >= 1
    p = patches[0]
    assert abs(p.area - 2.0) < 0.05 * 2.0, p.area
    assert abs(abs(p.normal[2]) - 1.0) < 1e-3 and p.normal[2] > 0
    assert np.allclose(p.centre, [1.5, 0.0, 0.0], atol=0.05)
    assert np.allclose(p.spread, [1.5, np.sqrt(4 / 12)], rtol=0.05)  # two strips 3 apart; 2 long


def test_a_curved_surface_gives_only_strips_flat_within_the_tolerance():
    rng = np.random.default_rng(0)
    points, normals, area = _cut(rng)
    curved = points[:, 2] > 0.1  # half a cylinder of radius 1.2, length 2
    tol, radius = 0.01, 1.2
    # a strip of the cylinder within tol of a plane is at most 2 sqrt(2 R (2 tol)) wide
    widest = 2 * np.sqrt(2 * radius * 2 * tol) * 2.0
    patches = planar_patches(points[curved], normals[curved], area, tol=tol, min_area=0.1,
                             rng=np.random.default_rng(1))
    assert all(p.area < 1.1 * widest for p in patches), [p.area for p in patches]


def test_the_mates_planes_give_the_true_placement():
    rng = np.random.default_rng(0)
    points, normals, area = _cut(rng, noise=0.002)
    # the mate: the same cut, its outward normals opposed, in its own frame
    T_target_source = make_transform(random_rotation(rng), rng.normal(size=3))
    on_cut = points[:, 2] < 0.1
    mate = transform_points(T_target_source, points[on_cut])
    mate_n = -normals[on_cut] @ T_target_source[:3, :3].T
    find = dict(tol=0.01, min_area=0.2)
    src = planar_patches(points, normals, area, rng=np.random.default_rng(1), **find)
    tgt = planar_patches(mate, mate_n, area, rng=np.random.default_rng(2), **find)
    found = plane_placements(src, tgt)
    errors = [(rotation_angle_deg(T[:3, :3], T_target_source[:3, :3]),
               np.linalg.norm(T[:3, 3] - T_target_source[:3, 3])) for T in found]
    best = min(errors)
    assert best[0] < 1.0 and best[1] < 0.05, errors
    assert len(found) == 2  # distinct principal axes: the true turn and the half turn


def test_a_small_face_among_many_larger_ones_is_found():
    # a CAD part's break face can be smaller than a dozen of its design faces: twelve
    # squares of area 1 on planes of different directions, and a 0.3 x 0.3 one (under 1 %
    # of the samples); three random samples fall on it together almost never
    rng = np.random.default_rng(0)
    points, normals = [], []
    directions = [random_rotation(rng) for _ in range(13)]
    for k, R in enumerate(directions):
        side = 1.0 if k < 12 else 0.3
        m = int(round(3000 * side**2))
        flat = np.column_stack([rng.uniform(0, side, (m, 2)), np.zeros(m)])
        points.append(flat @ R.T + 5.0 * rng.normal(size=3))
        normals.append(np.tile(R[:, 2], (m, 1)))
    points, normals = np.vstack(points), np.vstack(normals)
    patches = planar_patches(points, normals, 1.0 / 3000, tol=0.005, min_area=0.05, max_patches=16,
                             rng=np.random.default_rng(1))
    small = [p for p in patches if abs(p.area - 0.09) < 0.02]
    assert len(small) == 1, [round(p.area, 3) for p in patches]
    assert abs(abs(small[0].normal @ directions[12][:, 2]) - 1.0) < 1e-6
    assert len(patches) == 13


def test_batched_overlaps_equal_one_turn_at_a_time():
    # the batched images and FFTs give every turn's overlap and shift exactly as one
    # histogram2d image and one fftconvolve per turn
    from scipy.ndimage import gaussian_filter
    from scipy.signal import fftconvolve

    from reassemble.planes import _overlaps

    rng = np.random.default_rng(3)
    a = rng.normal(size=(700, 2)) * [1.5, 0.6]
    b = rng.normal(size=(900, 2)) * [0.6, 1.5]
    reach = max(np.abs(a).max(), np.abs(b).max())
    for cells, blur in ((48, False), (150, True)):
        angles = np.radians(np.arange(0.0, 360.0, 7.0))
        h = 2 * reach / cells
        size = cells + 3
        edges = (np.arange(size + 1) - size / 2) * h

        def image(points):
            img = (np.histogram2d(points[:, 0], points[:, 1], bins=(edges, edges))[0] > 0).astype(float)
            return gaussian_filter(img, 1.0) if blur else img

        got = _overlaps(a, b, angles, reach=reach, cells=cells, blur=blur)
        for (peak, angle, shift), t in zip(got, angles):
            c, s = np.cos(t), np.sin(t)
            corr = fftconvolve(image(b), image(a @ np.array([[c, s], [-s, c]]))[::-1, ::-1], mode="full")
            k = np.unravel_index(int(np.argmax(corr)), corr.shape)
            assert angle == t and peak == corr[k]
            if not blur:  # (blurred: the peak is refined between cells)
                assert np.array_equal(shift, (np.array(k, float) - (size - 1)) * h)
