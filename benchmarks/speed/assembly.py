"""End-to-end time of `reassemble run` against fragment count and mesh size.

    python -m benchmarks.speed.assembly                       # spot, 10 and 20 pieces, ~10k faces each, --jobs 2
    python -m benchmarks.speed.assembly --pieces 5,10,20 --cut-edge 0.004 --jobs 2
    python -m benchmarks.speed.assembly --view                # also time `reassemble view` on the result

Breaks a bundled mesh (`reassemble break`, cut-surface edge length --cut-edge of the
diagonal: 0.0055 gives ~10k faces per fragment at 10 pieces of the cow), then times the
real command line, `python -m reassemble run FRAGMENTS --out DIR --jobs J --quiet`, from
process start to written files (imports and worker start-up included), and scores it.
With --view, then times `python -m reassemble view OUT --quiet` the same way (all
pictures and report.html) and reports the pictures and the page's size. Run it on an
idle machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default="spot")
    parser.add_argument("--pieces", default="10,20")
    parser.add_argument("--cut-edge", type=float, default=0.0055)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--view", action="store_true", help="also time `reassemble view` on each result")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    from reassemble.pipeline import break_to_folder, evaluate_files, read_puzzle
    from reassemble.synth import BreakParams

    print(f"{'puzzle':<24s} {'faces/frag':>10s} {'run s':>7s} {'prepare':>8s} {'pairs':>6s} {'assembly':>8s} "
          f"{'placed':>6s} {'strict':>6s} {'solved':>6s}" + (f" {'view s':>6s} {'pictures':>8s} {'html MB':>7s}"
                                                              if args.view else ""))
    rows = []
    for n in (int(p) for p in args.pieces.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            puzzle = Path(tmp) / "puzzle"
            break_to_folder(args.mesh, puzzle, params=BreakParams(pieces=n, cut_edge=args.cut_edge), seed=args.seed)
            faces = np.mean([len(m.faces) for m in read_puzzle(puzzle / "ground_truth.json",
                                                               with_labels=False).meshes.values()])
            t = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "reassemble", "run", str(puzzle / "fragments"), "--out",
                                   str(Path(tmp) / "out"), "--jobs", str(args.jobs), "--quiet",
                                   "--seed", str(args.seed)], capture_output=True, text=True)
            elapsed = time.perf_counter() - t
            if proc.returncode:
                print(proc.stderr)
                return 1
            report = json.loads((Path(tmp) / "out" / "report.json").read_text())
            s = evaluate_files(Path(tmp) / "out" / "transforms.json", puzzle / "ground_truth.json")
            s = s["alignments"]["anchor_largest"]["summary"]
            t_ = report["summary"]["timings_s"]
            view = ""
            row = {"puzzle": args.mesh + f"_{n:02d}p_s{args.seed}", "fragments": n, "faces": float(faces),
                   "run": elapsed, **{k: t_[k] for k in ("prepare", "pairs", "assembly")},
                   "placed": report["summary"]["placed"], "strict": s["part_acc_strict"], "solved": bool(s["solved"])}
            if args.view:
                t = time.perf_counter()
                proc = subprocess.run([sys.executable, "-m", "reassemble", "view", str(Path(tmp) / "out"), "--quiet"],
                                      capture_output=True, text=True)
                if proc.returncode:
                    print(proc.stderr)
                    return 1
                pictures = len(list((Path(tmp) / "out" / "pictures").rglob("*.png")))
                mb = (Path(tmp) / "out" / "report.html").stat().st_size / 1e6
                row.update(view=time.perf_counter() - t, pictures=pictures, html_mb=mb)
                view = f" {row['view']:>6.1f} {pictures:>8d} {mb:>7.1f}"
            rows.append(row)
            print(f"{args.mesh + f'_{n:02d}p_s{args.seed}':<24s} {faces:>10.0f} {elapsed:>7.1f} {t_['prepare']:>8.1f} "
                  f"{t_['pairs']:>6.1f} {t_['assembly']:>8.1f} {report['summary']['placed']:>6d} "
                  f"{s['part_acc_strict']:>6.3f} {str(s['solved']):>6s}" + view, flush=True)
    cols = ["puzzle", "faces each", "`run` s", "prepare", "pairs", "assembly", "placed", "solved"]
    fmts = ["", ".0f", ".1f", ".1f", ".1f", ".1f", "d", ""]
    if args.view:
        cols, fmts = cols + ["`view` s", "pictures", "report.html MB"], fmts + [".1f", "d", ".1f"]
    bench.write(args.json, figures={"puzzles": rows, "jobs": args.jobs, "cut_edge": args.cut_edge},
                tables=[table(f"`python -m reassemble run FRAGMENTS --jobs {args.jobs}` from process start to written "
                              f"files ({args.mesh} broken with --cut-edge {args.cut_edge})", cols,
                              [[x["puzzle"], x["faces"], x["run"], x["prepare"], x["pairs"], x["assembly"], x["placed"],
                                "yes" if x["solved"] else "no"]
                               + ([x["view"], x["pictures"], x["html_mb"]] if args.view else []) for x in rows], fmts)],
                headline=[(f"`run` on {x['fragments']} fragments of ~{x['faces'] / 1000:.0f}k faces, --jobs {args.jobs}",
                           f"{x['run']:.0f} s, {'solved' if x['solved'] else 'not solved'}") for x in rows])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
