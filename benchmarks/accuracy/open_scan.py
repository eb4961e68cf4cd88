"""Open scans: the Stanford bunny scan (holes in its base) and fragments scanned with holes.

    python -m benchmarks.accuracy.open_scan --shared ../shared    # data/meshes/stanford-bunny-scan in it
    python -m benchmarks.accuracy.open_scan MESH --pieces 4,8 --seeds 0,1,2

Two cases, each run with ``--fill-holes`` and scored with ``reassemble eval``:
- the open scan closed (``holes.fill_holes``), broken into pieces (``reassemble break``),
  and reassembled;
- every fragment of those puzzles "scanned" with holes: a disc of its original surface
  (radius ``--hole`` of the object's diagonal, at a seeded random place) removed, the
  fragments reassembled from the open meshes (without ``--fill-holes`` all are refused).
Prints per puzzle the holes closed, strict and Breaking Bad part accuracy, and time.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table
from data_synth.scans import punch_holes

SHARED_PATH = ("data", "meshes", "stanford-bunny-scan", "stanford-bunny.obj")  # under --shared


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mesh", type=Path, nargs="?", help="default: the one under --shared")
    parser.add_argument("--shared", type=Path, help="the third-party data folder (../shared)")
    parser.add_argument("--pieces", default="4,8")
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--hole", type=float, default=0.03, help="radius of the holes punched / diagonal")
    parser.add_argument("--fill-holes", type=float, default=0.25)
    parser.add_argument("--jobs", type=int, default=2)
    add_json_option(parser)
    args = parser.parse_args()
    if args.mesh is None:
        if args.shared is None:
            parser.error("give MESH or --shared DIR (the folder holding data/meshes)")
        args.mesh = args.shared.joinpath(*SHARED_PATH)
    run = start()
    from reassemble.errors import ReassembleError
    from reassemble.files import load_mesh
    from reassemble.pipeline import Config, break_to_folder, evaluate_files, run_to_folder
    from reassemble.synth import BreakParams

    scan = load_mesh(args.mesh, fill_holes=args.fill_holes)
    print(f"{args.mesh.name}: {len(scan.faces)} faces after closing {len(scan.filled_holes)} holes (extent / "
          f"diagonal: {', '.join(f'{s:.3f}' for s in scan.filled_holes)})")
    print(f"{'puzzle':<24s} {'case':<22s} {'strict':>6s} {'BB':>6s} {'solved':>6s} {'time s':>7s}")
    config = Config(fill_holes=args.fill_holes)
    totals: dict[str, list] = {}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for pieces in (int(x) for x in args.pieces.split(",")):
            for seed in (int(x) for x in args.seeds.split(",")):
                name = f"{args.mesh.stem}_{pieces}p_s{seed}"
                puzzle = tmp / name
                break_to_folder(args.mesh, puzzle, params=BreakParams(pieces=pieces), seed=seed,
                                fill_holes=args.fill_holes)
                scans = tmp / f"{name}_scans"
                punch_holes(puzzle, scans, radius=args.hole, seed=seed)
                try:
                    run_to_folder([scans], tmp / f"{name}_refused", seed=seed)
                    refused = False
                except ReassembleError:
                    refused = True
                for case, folder in (("closed scan, broken", puzzle / "fragments"),
                                     ("fragments with holes", scans)):
                    out = tmp / f"{name}_{case.split()[0]}"
                    t = time.perf_counter()
                    run_to_folder([folder], out, seed=seed, config=config, jobs=args.jobs)
                    elapsed = time.perf_counter() - t
                    s = evaluate_files(out / "transforms.json", puzzle / "ground_truth.json",
                                       seed=seed)["alignments"]["anchor_largest"]["summary"]
                    totals.setdefault(case, []).append(s)
                    rows.append({"puzzle": name, "pieces": pieces, "seed": seed, "case": case,
                                 "strict": s["part_acc_strict"], "part_acc": s["part_acc"],
                                 "solved": bool(s["solved"]), "time": elapsed,
                                 **({} if case.startswith("closed") else {"refused_without_fill_holes": refused})})
                    print(f"{name:<24s} {case:<22s} {s['part_acc_strict']:>6.3f} {s['part_acc']:>6.3f} "
                          f"{str(s['solved']):>6s} {elapsed:>7.1f}"
                          + ("" if case.startswith("closed") else f"  (without --fill-holes: "
                             f"{'refused' if refused else 'NOT refused'})"), flush=True)
    for case, ss in totals.items():
        print(f"{case}: strict part accuracy mean {np.mean([s['part_acc_strict'] for s in ss]):.3f}, "
              f"solved {sum(s['solved'] for s in ss)} of {len(ss)}")
    run.write(args.json, figures={"mesh": args.mesh.name, "faces": len(scan.faces), "holes_closed": scan.filled_holes,
                                  "puzzles": rows},
              tables=[table(f"{args.mesh.name} ({len(scan.filled_holes)} holes closed): strict and Breaking Bad part "
                            "accuracy per puzzle", ["puzzle", "case", "strict", "BB part acc", "solved", "time s",
                                                    "refused without --fill-holes"],
                            [[x["puzzle"], x["case"], x["strict"], x["part_acc"], "yes" if x["solved"] else "no",
                              x["time"], {True: "yes", False: "NO"}.get(x.get("refused_without_fill_holes"), "")]
                             for x in rows], ["", "", ".3f", ".3f", "", ".1f", ""])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
