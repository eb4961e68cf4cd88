"""The third-party vessel set: thin-walled sherds with gaps between them, scored against the truth.

    python benchmarks/vessel.py                  # ../shared/data/meshes/vessel-TU_96_2-5-fragments
    python benchmarks/vessel.py FOLDER --jobs 2

The fragments are stored in their assembled pose (the truth is the identity for each). They
are moved by seeded random rigid motions first (so nothing can profit from the given pose),
reassembled with ``reassemble run``, and scored as ``reassemble eval`` does: strict part
accuracy (mean surface distance < 1 % of the object's diagonal), Breaking Bad part accuracy,
rotation errors, anchored on the largest placed fragment. Prints per fragment the
rotation and the mean distance from its true place.

With ``--diagnose``, also what the geometry says about the gaps between the pieces: the
mean displacement of each piece from its true place against the largest; the separation
``estimate_gap`` reads for every touching pair when started at the true pose; how far
mating keypoints' normals are from opposed (strip frames, and the descriptors' ball
normals they replace); and the contact and interpenetration of the assembled set refined
jointly with a given gap kept.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import header  # noqa: E402

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes" / "vessel-TU_96_2-5-fragments"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=Path, nargs="?", default=DEFAULT)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--gap", type=float, default=None, help="as run --gap (default: measured)")
    parser.add_argument("--diagnose", action="store_true", help="what the geometry says about the gaps")
    args = parser.parse_args()
    header()
    from reassemble.geometry import invert_transform, make_transform, random_rotation, transform_points
    from reassemble.io import load_mesh, read_json, write_ply
    from reassemble.metrics import ScoringFragment, evaluate
    from reassemble.pipeline import MatchConfig, run_to_folder

    rng = np.random.default_rng(args.seed)
    files = sorted(p for p in args.folder.iterdir() if p.suffix.lower() in {".obj", ".ply", ".stl", ".off"})
    meshes = {p.stem: load_mesh(p) for p in files}
    allv = np.vstack([m.vertices for m in meshes.values()])
    size = float(np.linalg.norm(np.ptp(allv, axis=0)))
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
                      config=MatchConfig(gap=args.gap))
        elapsed = time.perf_counter() - t
        pred = read_json(Path(tmp) / "out" / "transforms.json", what="transforms")["fragments"]
        report = read_json(Path(tmp) / "out" / "report.json", what="report")
        fragments = [ScoringFragment(n, transform_points(invert_transform(truth[n]), meshes[n].vertices),
                                     meshes[n].faces, truth[n]) for n in sorted(meshes)]
        pred = {n: {"transform": np.asarray(v["transform"]), "placed": v["placed"]} for n, v in pred.items()}
        scores = evaluate(fragments, pred, bbox_min=allv.min(axis=0), bbox_max=allv.max(axis=0), seed=args.seed)
    res = scores["alignments"]["anchor_largest"]
    print(f"{'fragment':<20s} {'placed':>6s} {'rot deg':>8s} {'dist/diag':>9s} {'strict':>6s}")
    for name, f in res["fragments"].items():
        print(f"{name:<20s} {str(f['placed']):>6s} {f['rotation_error_deg']:>8.2f} {f['chamfer_mean_over_diag']:>9.4f} "
              f"{str(f['correct_strict']):>6s}")
    s = res["summary"]
    print(f"strict part acc {s['part_acc_strict']:.3f}, BB part acc {s['part_acc']:.3f}, geodesic rot RMSE "
          f"{s['rot_geodesic_rmse_deg']:.2f} deg, solved {s['solved']}; gap {report['summary'].get('gap')} x size; "
          f"run {elapsed:.1f} s (--jobs {args.jobs})")
    b = scores["alignments"]["best_anchor"]
    print(f"anchored on the best fragment instead ({b['anchor']}): strict part acc "
          f"{b['summary']['part_acc_strict']:.3f}")
    if args.diagnose:
        diagnose({n: (m.vertices, m.faces) for n, m in meshes.items()}, size=size, seed=args.seed, jobs=args.jobs)
    return 0


def diagnose(meshes: dict, *, size: float, seed: int, jobs: int) -> None:
    """The gap study, on the pieces in their given (assembled) pose."""
    from reassemble.assembly import AssemblyParams, _evaluate, _spheres, assemble, refine
    from reassemble.geometry import invert_transform, make_scene, transform_points
    from reassemble.pipeline import match_pairs, prepare_fragments, registration_params
    from scipy.spatial import cKDTree

    from reassemble.registration import estimate_gap
    from reassemble.shells import wall_thickness, walls

    frags, ref = prepare_fragments(meshes, seed=seed, jobs=jobs)
    params = registration_params(frags, size=ref)
    results = match_pairs(frags, size=ref, params=params, seed=seed, jobs=jobs)
    surfaces = [f.surface for f in frags]
    A = assemble(surfaces, [f.mesh for f in frags], results, size=ref, params=AssemblyParams(), reg_params=params,
                 seed=seed)
    tol = params.tolerance * ref
    print("median wall thickness / fragment diagonal:")
    for f in frags:
        median = walls(wall_thickness(f.vertices, f.faces))[1]
        print(f"  {f.name:<20s} {median / np.linalg.norm(np.ptp(f.vertices, axis=0)):.3f}")
    anchor = int(np.argmax([s.area for s in surfaces]))
    print(f"displacement from the true place against {frags[anchor].name} (mesh units; diagonal {size:.3g}):")
    for k, f in enumerate(frags):
        T = invert_transform(A.T_group_fragment[anchor]) @ A.T_group_fragment[k]
        print(f"  {f.name:<20s} {np.round((transform_points(T, f.vertices) - f.vertices).mean(axis=0), 3)}")
    print("estimate_gap started at the true pose, touching pairs (mesh units; strip samples within 4 % of the size):")
    for (i, j), res in sorted(results.items()):
        if res.touching:
            _, g = estimate_gap(surfaces[i], surfaces[j], np.eye(4), tol=tol, max_gap=0.08 * ref,
                                normal_angle=params.normal_angle)
            d = cKDTree(surfaces[j].samples).query(surfaces[i].samples, distance_upper_bound=0.04 * ref)[0]
            print(f"  {frags[i].name} - {frags[j].name}: {g:.3f} (the strips' median distance there: "
                  f"{np.median(d[np.isfinite(d)]):.3f})")
    print("normals of mating strip keypoints at the true pose (median angle from exactly opposed, degrees):")
    for (i, j), res in sorted(results.items()):
        if res.touching:
            si, sj = surfaces[i], surfaces[j]
            d, near = cKDTree(sj.keypoints).query(si.keypoints, distance_upper_bound=0.04 * ref)
            ok = np.isfinite(d)
            # keypoints are face centres: the descriptors' (ball) normals there, for comparison
            ball = [frags[k].descriptors.normal[cKDTree(frags[k].vertices[frags[k].faces].mean(axis=1)).query(
                surfaces[k].keypoints)[1], 0] for k in (i, j)]

            def opposed(a, b):
                return np.degrees(np.arccos(np.clip(-np.einsum("ij,ij->i", a, b), -1.0, 1.0)))

            print(f"  {frags[i].name} - {frags[j].name}: strip frames "
                  f"{np.median(opposed(si.keypoint_normals[ok], sj.keypoint_normals[near[ok]])):.1f}, "
                  f"descriptor normals {np.median(opposed(ball[0][ok], ball[1][near[ok]])):.1f}")
    scenes = [make_scene(*f.mesh) for f in frags]
    centres, radii = _spheres(surfaces)
    pairs = [(p, q) for p in range(len(frags)) for q in range(p + 1, len(frags))]
    print("joint refinement of the assembled set keeping a gap (fraction of the reference size):")
    for gap in (0.0, 0.005, 0.01, 0.015):
        T = refine(A.T_group_fragment, surfaces, tol=tol, normal_angle=params.normal_angle, anchor=anchor,
                   gap=gap * ref)
        ev = _evaluate(pairs, T, surfaces, scenes, tol=tol, reg_params=params, centres=centres, radii=radii,
                       cache={}, gap=gap * ref)
        print(f"  gap {gap:.3f}: contact {sum(v[1] for v in ev.values()):.1f}, "
              f"interpenetration {sum(v[2] for v in ev.values()):.1f} (mesh units squared)")


if __name__ == "__main__":
    raise SystemExit(main())
