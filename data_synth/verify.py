"""Checks that a synthetic puzzle is what it claims: closed fragments, conserved volume,
zero gaps when put back, and labels that cover exactly the cut faces (and, for fragments
written as unions of cells, interior faces that come in opposite pairs)."""

from __future__ import annotations

import numpy as np

from reassemble.geometry import face_areas, face_normals, make_scene, signed_volume, transform_points
from reassemble.pipeline import PuzzleFiles


def _point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Exact (float64) distance from each point (k, 3) to its own triangle (k, 3, 3)."""
    A, B, C = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(B - A, C - A)
    nn = np.einsum("ij,ij->i", n, n)
    t = np.einsum("ij,ij->i", p - A, n) / np.where(nn > 0, nn, 1.0)
    q = p - n * t[:, None]  # projection onto the plane, used where it falls inside
    inside = nn > 0
    for X, Y in ((A, B), (B, C), (C, A)):
        inside &= np.einsum("ij,ij->i", np.cross(Y - X, q - X), n) >= 0
    best = np.where(inside, np.linalg.norm(p - q, axis=1), np.inf)
    for X, Y in ((A, B), (B, C), (C, A)):
        e = Y - X
        s = np.einsum("ij,ij->i", p - X, e) / np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
        s = np.clip(s, 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (X + e * s[:, None]), axis=1))
    return best


class _Surface:
    """Distances to a mesh: open3d finds the nearest triangle, the distance to it is exact.

    open3d works in float32, which on long thin triangles is off by ~1e-5 of their size:
    too coarse to show that fragments meet with zero gap.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, *, exact_below: float):
        from scipy.spatial import cKDTree

        self.tri = vertices[faces]
        self.scene = make_scene(vertices, faces)
        self.exact_below = exact_below
        centers = self.tri.mean(axis=1)
        self.reach = float(np.linalg.norm(self.tri - centers[:, None], axis=2).max())
        self.tree = cKDTree(centers)

    def distance(self, points: np.ndarray) -> np.ndarray:
        import open3d as o3d

        ans = self.scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
        ids = ans["primitive_ids"].numpy().astype(np.int64)
        d32 = np.linalg.norm(ans["points"].numpy() - points, axis=1)
        d = np.minimum(d32, _point_triangle_distance(points, self.tri[ids]))
        # where float32 picked the wrong triangle, try every triangle within reach
        # (float32 misses seen up to ~200x the tolerance on long thin CAD triangles)
        for i in np.flatnonzero((d > self.exact_below) & (d < 1000 * self.exact_below)):
            near = self.tree.query_ball_point(points[i], d[i] + self.reach)
            p = np.broadcast_to(points[i], (len(near), 3))
            d[i] = min(d[i], float(_point_triangle_distance(p, self.tri[near]).min()))
        return d


def check_puzzle(puzzle: PuzzleFiles, original_vertices: np.ndarray, original_faces: np.ndarray) -> dict:
    """Measure a puzzle against the mesh it was broken from (scaled as the puzzle says).

    Returns
    -------
    dict with
        volume_rel_error : |sum of fragment volumes - original| / original
        max_gap_over_diag : largest distance of a fracture-face centroid, put back by the
            ground truth, to the other fragments' surfaces, over the object diagonal
        original_off_surface_over_diag : largest distance of an original-surface vertex
            to the original mesh, over the diagonal
        fracture_area_on_original : share of fracture area in faces lying wholly (vertices
            and centroid) on the original surface (should be ~0)
        original_area_in_contact : share of original-surface area touching another fragment
        interior_area_unpaired : share of interior-face area (label 2) whose centroid is not
            on another interior face of the same fragment facing the other way (should be 0;
            0 when there are no interior faces)
    """
    gt = puzzle.ground_truth
    scale = gt["parameters"]["scale"]
    ov = np.asarray(original_vertices, float) * scale
    diag = float(np.linalg.norm(ov.max(axis=0) - ov.min(axis=0)))
    tol = 1e-6 * diag
    original_scene = _Surface(ov, np.asarray(original_faces), exact_below=tol)
    world = {}
    for name, mesh in puzzle.meshes.items():
        T = np.asarray(gt["fragments"][name]["transform"])
        world[name] = (transform_points(T, mesh.vertices), mesh.faces, puzzle.labels[name])
    total_volume = sum(signed_volume(v, f) for v, f, _ in world.values())
    original_volume = signed_volume(ov, np.asarray(original_faces))
    scenes = {n: _Surface(v, f, exact_below=tol) for n, (v, f, _) in world.items()}

    max_gap = 0.0
    off_surface = 0.0
    frac_on_orig = frac_area = 0.0
    orig_in_contact = orig_area = 0.0
    unpaired = interior_area = 0.0
    for name, (v, f, lab) in world.items():
        areas = face_areas(v, f)
        centroids = v[f].mean(axis=1)
        others = [scenes[o] for o in world if o != name]
        d_other = np.min([s.distance(centroids) for s in others], axis=0)
        frac = lab == 1
        if frac.any():
            max_gap = max(max_gap, float(d_other[frac].max()))
            # a fracture face lying wholly on the original surface would be a wrong label
            # (slivers along the rim touch it with one edge, which is fine)
            used = np.unique(f[frac])
            on = np.zeros(len(v), bool)
            on[used] = original_scene.distance(v[used]) < tol
            d_orig = original_scene.distance(centroids[frac])
            wholly = on[f[frac]].all(axis=1) & (d_orig < tol)
            frac_on_orig += float(areas[frac][wholly].sum())
            frac_area += float(areas[frac].sum())
        orig = lab == 0
        if orig.any():
            used = np.unique(f[orig])
            off_surface = max(off_surface, float(original_scene.distance(v[used]).max()))
            orig_in_contact += float(areas[orig][d_other[orig] < tol].sum())
            orig_area += float(areas[orig].sum())
        inner = np.flatnonzero(lab == 2)
        if len(inner):
            normals = face_normals(v, f)
            # each interior face against the interior faces of the other orientation
            for sign in (1.0, -1.0):
                side = inner[normals[inner] @ np.array([0.577, 0.578, 0.577]) * sign > 0]
                other = inner[normals[inner] @ np.array([0.577, 0.578, 0.577]) * sign <= 0]
                if len(side) == 0:
                    continue
                if len(other) == 0:
                    unpaired += float(areas[side].sum())
                    continue
                d = _Surface(v, f[other], exact_below=tol).distance(centroids[side])
                unpaired += float(areas[side][d > tol].sum())
            interior_area += float(areas[inner].sum())
    return {
        "volume_rel_error": abs(total_volume - original_volume) / original_volume,
        "max_gap_over_diag": max_gap / diag,
        "original_off_surface_over_diag": off_surface / diag,
        "fracture_area_on_original": frac_on_orig / max(frac_area, 1e-300),
        "original_area_in_contact": orig_in_contact / max(orig_area, 1e-300),
        "interior_area_unpaired": unpaired / interior_area if interior_area else 0.0,
    }


LIMITS = {"volume_rel_error": 1e-5, "max_gap_over_diag": 1e-6, "original_off_surface_over_diag": 1e-6,
          "fracture_area_on_original": 1e-4, "original_area_in_contact": 1e-4, "interior_area_unpaired": 1e-6}


def main(argv: list[str] | None = None) -> int:
    """Check every clean puzzle of a built set folder against the mesh it was broken from
    (``<set>/_sources/<mesh>`` where the set has one, else the bundled mesh)."""
    import argparse
    import json
    from pathlib import Path

    from reassemble.files import load_mesh, resolve_mesh_path
    from reassemble.pipeline import read_puzzle

    parser = argparse.ArgumentParser(prog="python -m data_synth.verify", description=main.__doc__)
    parser.add_argument("root", type=Path, help="a set folder built by data_synth.make_sets")
    args = parser.parse_args(argv)
    worst: dict[str, dict[str, float]] = {}
    failed = 0
    sources: dict[str, tuple] = {}
    for gt_path in sorted(args.root.glob("*/ground_truth.json")):
        gt = json.loads(gt_path.read_text())
        if gt["parameters"]["noise"] > 0:  # noise moves vertices off the exact surfaces
            continue
        name = gt["source"]["mesh"]
        if name not in sources:
            path = args.root / "_sources" / name
            m = load_mesh(path if path.is_file() else resolve_mesh_path(Path(name).stem))
            sources[name] = (m.vertices, m.faces)
        checks = check_puzzle(read_puzzle(gt_path), *sources[name])
        style = gt["parameters"].get("style", "fractal")
        bad = [k for k, v in checks.items() if v > LIMITS[k]]
        failed += bool(bad)
        for k, v in checks.items():
            worst.setdefault(style, {})[k] = max(worst.get(style, {}).get(k, 0.0), v)
        print(f"{gt_path.parent.name:<44s} " + " ".join(f"{v:.1e}" for v in checks.values())
              + (f"  OVER: {', '.join(bad)}" if bad else ""), flush=True)
    print("\nworst per style (limits: " + ", ".join(f"{k} {v:g}" for k, v in LIMITS.items()) + ")")
    for style, w in sorted(worst.items()):
        print(f"  {style:<8s} " + ", ".join(f"{k} {v:.1e}" for k, v in w.items()))
    print(f"{failed} puzzle(s) over a limit")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
