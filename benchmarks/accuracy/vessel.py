"""The third-party vessel set: thin-walled sherds with gaps between them, scored against the truth.

    python -m benchmarks.accuracy.vessel --shared ../shared   # data/meshes/vessel-TU_96_2-5-fragments in it
    python -m benchmarks.accuracy.vessel FOLDER --jobs 2

The fragments are stored in their assembled pose (the truth is the identity for each). They
are moved by seeded random rigid motions first (so nothing can profit from the given pose),
reassembled with ``reassemble run``, and scored as ``reassemble eval`` does: strict part
accuracy (mean surface distance < 1 % of the object's diagonal), Breaking Bad part accuracy,
rotation errors, anchored on the largest placed fragment. Prints per fragment the
rotation and the mean distance from its true place.

The given pose is an exploded view, and it is scored against twice: as given, and as the
"closed reference", found from the given meshes alone: a thrown pot is a surface of
revolution, and moving the pieces (translations, the largest fixed) so that all walls lie
on one surface of revolution (``closed_reference``) closes the gaps. Strict accuracy
against the given pose is bounded by the gaps for any assembly whose pieces touch.

With ``--diagnose``, also what the geometry says about the gaps: how far the vertices of
neighbouring pieces are from each other's surface in both poses (no layer lost at the break
shows as contact once closed); the closed reference against an exploded view (every piece
pushed out by one distance from one centre along its centroid's direction); and how far
mating strip keypoints' normals are from opposed (strip frames, and the descriptors' ball
normals they replace).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

SHARED_PATH = ("data", "meshes", "vessel-TU_96_2-5-fragments")  # under --shared


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=Path, nargs="?", help="default: the one under --shared")
    parser.add_argument("--shared", type=Path, help="the third-party data folder (../shared)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--gap", type=float, default=None, help="as run --gap (default: measured)")
    parser.add_argument("--diagnose", action="store_true", help="what the geometry says about the gaps")
    add_json_option(parser)
    args = parser.parse_args()
    if args.folder is None:
        if args.shared is None:
            parser.error("give FOLDER or --shared DIR (the folder holding data/meshes)")
        args.folder = args.shared.joinpath(*SHARED_PATH)
    run = start()
    from reassemble.geometry import face_areas, invert_transform, make_transform, random_rotation, transform_points
    from reassemble.files import load_mesh, read_json, write_ply
    from reassemble.metrics import ScoringFragment, evaluate
    from reassemble.pipeline import Config, run_to_folder

    rng = np.random.default_rng(args.seed)
    files = sorted(p for p in args.folder.iterdir() if p.suffix.lower() in {".obj", ".ply", ".stl", ".off"})
    meshes = {p.stem: load_mesh(p) for p in files}
    allv = np.vstack([m.vertices for m in meshes.values()])
    size = float(np.linalg.norm(np.ptp(allv, axis=0)))
    anchor = max(meshes, key=lambda n: face_areas(meshes[n].vertices, meshes[n].faces).sum())
    t = time.perf_counter()
    shifts, rms_given, rms_fit = closed_reference({n: (m.vertices, m.faces) for n, m in meshes.items()},
                                                   anchor=anchor)
    print(f"closed reference (one surface of revolution, {time.perf_counter() - t:.1f} s): the pieces' walls "
          f"off the common profile by {rms_given:.3f} units RMS as given, {rms_fit:.3f} after moving the 4 "
          f"non-anchor pieces by " + ", ".join(f"{np.linalg.norm(v):.2f}" for n, v in shifts.items() if n != anchor)
          + f" units (diagonal {size:.3g})")
    with tempfile.TemporaryDirectory() as tmp:
        moved_dir = Path(tmp) / "moved"
        moved_dir.mkdir()
        truth = {}
        for name, m in meshes.items():
            T_fragment_given = make_transform(random_rotation(rng), rng.normal(0, size, 3))
            write_ply(moved_dir / f"{name}.ply", transform_points(T_fragment_given, m.vertices), m.faces)
            truth[name] = invert_transform(T_fragment_given)  # T_world_fragment, world = the given pose
        t = time.perf_counter()
        run_to_folder([moved_dir], Path(tmp) / "out", seed=args.seed, jobs=args.jobs,
                      config=Config(gap=args.gap))
        elapsed = time.perf_counter() - t
        pred = read_json(Path(tmp) / "out" / "transforms.json", what="transforms")["fragments"]
        report = read_json(Path(tmp) / "out" / "report.json", what="report")
    pred = {n: {"transform": np.asarray(v["transform"]), "placed": v["placed"]} for n, v in pred.items()}
    scores = {}
    for ref, offset in (("given pose", dict.fromkeys(meshes, np.zeros(3))), ("closed reference", shifts)):
        T_world = {n: make_transform(np.eye(3), offset[n]) @ truth[n] for n in meshes}
        fragments = [ScoringFragment(n, transform_points(invert_transform(truth[n]), meshes[n].vertices),
                                     meshes[n].faces, T_world[n]) for n in sorted(meshes)]
        world = np.vstack([m.vertices + offset[n] for n, m in meshes.items()])
        scores[ref] = evaluate(fragments, pred, bbox_min=world.min(axis=0), bbox_max=world.max(axis=0),
                               seed=args.seed)["alignments"]["anchor_largest"]
    print(f"run {elapsed:.1f} s (--jobs {args.jobs}), gap {report['summary'].get('gap')} x size; "
          f"anchored on the largest fragment ({scores['given pose']['anchor']})")
    print(f"{'fragment':<20s} {'placed':>6s} {'rot deg':>8s}   {'dist/diag (strict) from the given pose':>38s}"
          f"   {'from the closed reference':>25s}")
    for name in sorted(meshes):
        g, c = (scores[r]["fragments"][name] for r in ("given pose", "closed reference"))
        print(f"{name:<20s} {str(g['placed']):>6s} {g['rotation_error_deg']:>8.2f}   "
              f"{g['chamfer_mean_over_diag']:>30.4f} ({'yes' if g['correct_strict'] else 'no':>3s})   "
              f"{c['chamfer_mean_over_diag']:>17.4f} ({'yes' if c['correct_strict'] else 'no':>3s})")
    for ref, res in scores.items():
        s = res["summary"]
        print(f"against the {ref}: strict part acc {s['part_acc_strict']:.3f}, BB part acc {s['part_acc']:.3f}, "
              f"geodesic rot RMSE {s['rot_geodesic_rmse_deg']:.2f} deg, solved {s['solved']}")
    if args.diagnose:
        diagnose({n: (m.vertices, m.faces) for n, m in meshes.items()}, shifts, anchor=anchor, size=size,
                 seed=args.seed, jobs=args.jobs)
    summary = {ref: {k: res["summary"][k] for k in ("part_acc_strict", "part_acc", "rot_geodesic_rmse_deg", "solved")}
               for ref, res in scores.items()}
    placed = sum(bool(scores["given pose"]["fragments"][n]["placed"]) for n in meshes)
    run.write(args.json, figures={"fragments": len(meshes), "placed": placed, "run_seconds": elapsed,
                                  "gap": report["summary"].get("gap"), "scores": summary,
                                  "closed_reference_rms": {"given": rms_given, "fitted": rms_fit}},
              tables=[table(f"{args.folder.name}: {placed} of {len(meshes)} placed, `run` {elapsed:.0f} s "
                            f"(--jobs {args.jobs}, seed {args.seed})",
                            ["scored against", "strict part acc", "BB part acc", "rotation RMSE deg", "solved"],
                            [[ref, s["part_acc_strict"], s["part_acc"], s["rot_geodesic_rmse_deg"],
                              "yes" if s["solved"] else "no"] for ref, s in summary.items()],
                            ["", ".3f", ".3f", ".2f", ""])])
    return 0


def revolution_residual(points: np.ndarray, weights: np.ndarray, axis_point: np.ndarray, axis_dir: np.ndarray,
                        *, degree: int, h_scale: tuple[float, float]) -> np.ndarray:
    """Weighted radii about a line minus the best polynomial profile r(h) of ``degree``: (n,)."""
    q = points - axis_point
    h = q @ axis_dir
    r = np.linalg.norm(q - np.outer(h, axis_dir), axis=1)
    A = np.vander((h - h_scale[0]) / h_scale[1], degree + 1)
    coef = np.linalg.lstsq(A * weights[:, None], r * weights, rcond=None)[0]
    return (r - A @ coef) * weights


def closed_reference(meshes: dict, *, anchor: str, degree: int = 8) -> tuple[dict, float, float]:
    """Translations that put every piece's wall on one surface of revolution with the anchor's.

    A thrown pot is a surface of revolution. The wall's mid-surface (face centres moved
    inward by half the wall, ``shells.wall_thickness``) of every piece, one common axis and
    profile (radius a polynomial of the height), and per piece but ``anchor`` a translation,
    fitted by least squares from the given pose; nothing of the reassembly is used.

    Returns
    -------
    shifts : {name: (3,)} translations (the anchor's zero)
    rms_given, rms_fit : float, RMS radius residual (mesh units) at the given pose and fitted
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    from reassemble.geometry import face_areas, face_normals
    from reassemble.shells import wall_thickness, walls

    names = sorted(meshes)
    pts, wts = [], []
    for name in names:
        v, f = meshes[name]
        t = wall_thickness(v, f)
        wall, median = walls(t)
        wall &= t < 3 * median
        pts.append(v[f[wall]].mean(axis=1) - face_normals(v, f)[wall] * t[wall, None] / 2)
        wts.append(np.sqrt(face_areas(v, f)[wall]))
    weights = np.concatenate(wts)
    weights /= np.sqrt(np.sum(weights**2))
    moving = [k for k, n in enumerate(names) if n != anchor]
    centre = np.vstack(pts).mean(axis=0)

    def unpack(x, e):
        b1 = np.cross(e, [1.0, 0.0, 0.0] if abs(e[0]) < 0.9 else [0.0, 1.0, 0.0])
        b1 /= np.linalg.norm(b1)
        b2 = np.cross(e, b1)
        return centre + x[2] * b1 + x[3] * b2, Rotation.from_rotvec(x[0] * b1 + x[1] * b2).apply(e)

    def residual(x, e, h_scale):
        p, a = unpack(x, e)
        shifted = [pts[k] + (x[4 + 3 * moving.index(k):7 + 3 * moving.index(k)] if k in moving else 0.0)
                   for k in range(len(names))]
        return revolution_residual(np.vstack(shifted), weights, p, a, degree=degree, h_scale=h_scale)

    best = None
    for e in np.eye(3):  # the initial axis direction: the coordinate axis that fits best
        h = np.vstack(pts) @ e
        h_scale = (float(h.mean()), float(h.std()))
        # the axis (two tilts, two offsets) for the pieces as given, then the pieces free too
        given = least_squares(lambda x: residual(np.r_[x, np.zeros(3 * len(moving))], e, h_scale), np.zeros(4))
        fit = least_squares(residual, np.r_[given.x, np.zeros(3 * len(moving))], args=(e, h_scale))
        if best is None or fit.cost < best[0].cost:
            best = (fit, given)
    fit, given = best
    shifts = {n: (fit.x[4 + 3 * moving.index(k):7 + 3 * moving.index(k)] if k in moving else np.zeros(3))
              for k, n in enumerate(names)}
    # the weights are normalized: the norm of the residual is the area-weighted RMS
    return shifts, float(np.linalg.norm(given.fun)), float(np.linalg.norm(fit.fun))


def diagnose(meshes: dict, shifts: dict, *, anchor: str, size: float, seed: int, jobs: int) -> None:
    """What the geometry says about the gaps (pieces moved apart, or material lost) and the strips' normals."""
    from scipy.optimize import least_squares
    from scipy.spatial import cKDTree

    from reassemble.geometry import make_scene
    from reassemble.pipeline import prepare_fragments
    from reassemble.shells import wall_thickness, walls

    names = sorted(meshes)
    print("median wall thickness / fragment diagonal, median edge (mesh units, and / the set's diagonal):")
    for n in names:
        v, f = meshes[n]
        edge = float(np.median(np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2)))
        print(f"  {n:<20s} {walls(wall_thickness(v, f))[1] / np.linalg.norm(np.ptp(v, axis=0)):.3f}, "
              f"{edge:.3f} ({edge / size:.2%})")
    touching = []
    print("vertices within 1.5 units of another piece: distance to its surface, 10/50/90th percentile "
          "(mesh units), given pose -> closed reference:")
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            row = []
            for shift, near in ((dict.fromkeys(names, 0.0), 1.5), (shifts, 0.3)):
                scene = make_scene(meshes[b][0] + shift[b], meshes[b][1])
                q = (meshes[a][0] + shift[a]).astype(np.float32)
                d = scene.compute_distance(q).numpy()
                row.append(d[d < near])
            if min(len(r) for r in row) > 20:
                touching.append((a, b))
                print(f"  {a} - {b}: " + " -> ".join(str(np.round(np.percentile(r, [10, 50, 90]), 3)) for r in row))
    # an exploded view: every piece pushed out by s from a centre c along its centroid's direction
    cents = {n: meshes[n][0].mean(axis=0) + shifts[n] for n in names}
    given_minus_closed = np.array([-shifts[n] for n in names])

    def explode(x):
        u = np.array([cents[n] - x[1:] for n in names])
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        u -= u[names.index(anchor)]
        return (x[0] * u - given_minus_closed).ravel()

    fit = least_squares(explode, np.r_[0.01 * size, np.mean(list(cents.values()), axis=0)])
    res = np.linalg.norm(fit.fun.reshape(-1, 3), axis=1)
    print(f"given pose = closed reference, every piece pushed out from {np.round(fit.x[1:], 2)} by "
          f"{fit.x[0]:.3f} units ({fit.x[0] / size:.2%} of the diagonal): residual per piece (units) "
          + ", ".join(f"{n} {r:.3f}" for n, r in zip(names, res)))
    frags, ref = prepare_fragments({n: (meshes[n][0] + shifts[n], meshes[n][1]) for n in names}, seed=seed, jobs=jobs)
    by_name = {f.name: f for f in frags}
    print("normals of mating strip keypoints in the closed reference (median angle from exactly opposed, degrees):")

    def opposed(u, v):
        return np.degrees(np.arccos(np.clip(-np.einsum("ij,ij->i", u, v), -1.0, 1.0)))

    for a, b in touching:
        fa, fb = by_name[a], by_name[b]
        d, near = cKDTree(fb.surface.keypoints).query(fa.surface.keypoints, distance_upper_bound=0.01 * ref)
        ok = np.isfinite(d)
        # keypoints are face centres: the descriptors' (ball) normals there, for comparison
        ball = [f.descriptors.normal[cKDTree(f.vertices[f.faces].mean(axis=1)).query(f.surface.keypoints)[1], 0]
                for f in (fa, fb)]
        print(f"  {a} - {b}: strip frames "
              f"{np.median(opposed(fa.surface.keypoint_normals[ok], fb.surface.keypoint_normals[near[ok]])):.1f}, "
              f"descriptor normals {np.median(opposed(ball[0][ok], ball[1][near[ok]])):.1f}")


if __name__ == "__main__":
    raise SystemExit(main())
