"""Build a puzzle set (or break given meshes) and check every puzzle exactly.

    python -m benchmarks.studies.synth_check puzzles/bench              # the bench set (built if missing)
    python -m benchmarks.studies.synth_check held_out --meshes a.obj b.stl   # meshes never seen, 2-20 pieces

For each puzzle: fragments closed, volume conserved, zero gaps when put back, labels
exactly the cut faces, and eval of the truth = perfect. Prints the worst figure of each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table
from data_synth.make_sets import build_set
from data_synth.sets import SETS
from data_synth.verify import check_puzzle
from reassemble.errors import ReassembleError
from reassemble.files import load_mesh, read_json, resolve_mesh_path
from reassemble.pipeline import break_to_folder, evaluate_files, read_puzzle
from reassemble.synth import BreakParams


def check_dir(puzzle_dir: Path, mesh_path: Path) -> dict:
    puzzle = read_puzzle(puzzle_dir / "ground_truth.json")
    for name in puzzle.meshes:
        load_mesh(puzzle_dir / "fragments" / f"{name}.ply", require_closed=True)
    mesh = load_mesh(mesh_path)
    checks = check_puzzle(puzzle, mesh.vertices, mesh.faces)
    noisy = puzzle.ground_truth["parameters"]["noise"] > 0
    if noisy:  # noise moves vertices off the exact surfaces: only volume is not checked exactly
        checks = {k: v for k, v in checks.items() if k in ("fracture_area_on_original",)}
    report = evaluate_files(puzzle_dir / "ground_truth.json", puzzle_dir / "ground_truth.json")
    checks["truth_part_acc_strict"] = report["alignments"]["as_given"]["summary"]["part_acc_strict"]
    return checks


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root", type=Path, help="puzzle set folder (named after the set) or output folder")
    parser.add_argument("--set", choices=sorted(SETS), help="set to build (default: the folder's name)")
    parser.add_argument("--meshes", nargs="*", type=Path, help="break these meshes into 2..20 pieces instead")
    parser.add_argument("--jobs", type=int, default=2)
    add_json_option(parser)
    args = parser.parse_args()
    run = start()
    t0 = time.perf_counter()
    todo: list[tuple[Path, Path]] = []
    if args.meshes:
        for mesh in args.meshes:
            for pieces in (2, 4, 8, 12, 20):
                out = args.root / f"{mesh.stem}_{pieces:02d}p"
                try:
                    t = time.perf_counter()
                    break_to_folder(mesh, out, params=BreakParams(pieces=pieces), seed=pieces, force=True)
                    print(f"  broke {mesh.name} into {pieces} in {time.perf_counter() - t:.1f} s")
                except ReassembleError as exc:
                    print(f"  {mesh.name} x {pieces}: refused: {exc}")
                    continue
                todo.append((out, mesh))
    else:
        name = args.set or args.root.name
        results = build_set(name, args.root, jobs=args.jobs)
        built = [r["seconds"] for r in results if not r["cached"]]
        if built:
            print(f"built {len(built)} puzzles: {np.mean(built):.2f} s mean, {np.max(built):.2f} s max each")
        index = read_json(args.root / "index.json", what="a puzzle set index")
        todo = [(args.root / p["name"], resolve_mesh_path(p["mesh"])) for p in index["puzzles"]]
    worst: dict[str, float] = {}
    for puzzle_dir, mesh_path in todo:
        checks = check_dir(puzzle_dir, mesh_path)
        for k, v in checks.items():
            worst[k] = min(worst.get(k, 1.0), v) if k.startswith("truth") else max(worst.get(k, 0.0), v)
    print(f"checked {len(todo)} puzzles in {time.perf_counter() - t0:.0f} s; worst over all:")
    limits = {"volume_rel_error": 1e-5, "max_gap_over_diag": 1e-6, "original_off_surface_over_diag": 1e-6,
              "fracture_area_on_original": 1e-4, "original_area_in_contact": 1e-4, "truth_part_acc_strict": 1.0}
    ok = True
    rows = []
    for k, v in worst.items():
        good = v >= limits[k] if k.startswith("truth") else v <= limits[k]
        ok &= good
        rows.append([k, v, limits[k], "ok" if good else "FAIL"])
        print(f"  {k:34s} {v:.3g}   (limit {limits[k]:g}) {'ok' if good else 'FAIL'}")
    run.write(args.json, figures={"puzzles": len(todo), "worst": worst, "limits": limits, "ok": bool(ok)},
              tables=[table(f"Exact checks of {len(todo)} puzzles: the worst figure of each", ["check", "worst", "limit",
                                                                                              "verdict"],
                            rows, ["", ".3g", "g", ""])])
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
