"""Time, peak memory and accuracy of ``reassemble run`` against the number of fragments.

    python -m benchmarks.speed.scale                              # spot, cells, 10 and 20 pieces
    python -m benchmarks.speed.scale --pieces 10,20,50 --timeout 60 --work /tmp/scale
    python -m benchmarks.speed.scale --pieces 20,50 --set retrieval.min_fragments=16   # candidate pairs

Each puzzle is ``reassemble break MESH --pieces N --style cells --seed S`` (the style that
makes 50-200 pieces; a bundled mesh), then ``reassemble run`` on its fragments with
``--jobs``, in a fresh process whose whole process tree's resident memory is sampled
twice a second (the peak of the sum of their proportional set sizes: the
pool's workers count, their shared pages once), then ``reassemble eval``.
A run over ``--timeout`` minutes is stopped and recorded as not finished, with its time.
``--set`` options go to every run (``reassemble run --set``), and are in the record.
The record gives, per n, the seconds of each step (``report.json``), the pairs
registered, the peak memory and the strict part accuracy, and the slope of log time
against log n between the smallest and each larger n that finished (issue 23's target:
at most 1.3).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.common import add_json_option, start, table


PRIMARY = "anchor_largest"  # the frame every accuracy benchmark scores in (reassemble.bench.PRIMARY)


def _watch(cmd: list[str], *, timeout: float) -> tuple[int | None, float, float]:
    """(return code or None when stopped at ``timeout`` seconds, seconds, peak GB of the process tree)."""
    import psutil

    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peak = 0.0
    top = psutil.Process(proc.pid)
    while proc.poll() is None:
        try:
            tree = [top] + top.children(recursive=True)
            peak = max(peak, sum(_memory(p) for p in tree) / 1e9)
        except psutil.Error:
            pass
        if time.perf_counter() - t0 > timeout:
            for p in [top] + top.children(recursive=True):
                try:
                    p.kill()
                except psutil.Error:
                    pass
            proc.wait()
            return None, time.perf_counter() - t0, peak
        time.sleep(0.5)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: {proc.stderr.strip().splitlines()[-1]}")
    return proc.returncode, time.perf_counter() - t0, peak


def _memory(process) -> int:
    """Bytes of a process's proportional set size (its shared pages split among their users,
    so a pool's forked workers are not counted many times), else its resident size."""
    try:
        return process.memory_full_info().pss
    except AttributeError:
        return process.memory_info().rss


def one(n: int, *, mesh: str, style: str, seed: int, jobs: int, timeout: float, work: Path,
        settings: list[str] = ()) -> dict:
    """Break, run and score one puzzle of ``n`` pieces."""
    cli = [sys.executable, "-m", "reassemble"]
    puzzle = work / f"{mesh}_{style}_{n:03d}p_s{seed}"
    t0 = time.perf_counter()
    if not (puzzle / "ground_truth.json").exists():
        subprocess.run(cli + ["break", mesh, "--pieces", str(n), "--style", style, "--seed", str(seed), "--out",
                              str(puzzle)], check=True, capture_output=True)
    breaking = time.perf_counter() - t0
    out = work / (f"{puzzle.name}_run" + "".join(f"_{x}" for x in settings))
    rc, seconds, peak = _watch(cli + ["run", str(puzzle / "fragments"), "--out", str(out), "--force", "--jobs",
                                      str(jobs), "--seed", str(seed)] + [a for x in settings for a in ("--set", x)],
                               timeout=timeout)
    row = {"pieces": n, "break_s": breaking, "run_s": seconds, "peak_gb": peak, "finished": rc is not None}
    if rc is None:
        return row
    report = json.loads((out / "report.json").read_text())
    pairs = json.loads((out / "pairs.json").read_text())
    score = json.loads(subprocess.run(cli + ["eval", str(out / "transforms.json"), str(puzzle / "ground_truth.json"),
                                             "--json"], check=True, capture_output=True, text=True).stdout)
    row.update(timings=report["summary"]["timings_s"], pairs=len(pairs["pairs"]),
               strict=score["alignments"][PRIMARY]["summary"]["part_acc_strict"],
               placed=int(sum(t["placed"] for t in json.loads((out / "transforms.json").read_text())
                              ["fragments"].values())))
    return row


def slopes(rows: list[dict]) -> list[float | None]:
    """Per row, the slope of log run time against log n from the first (smallest) finished row."""
    import numpy as np

    done = [r for r in rows if r["finished"]]
    if not done:
        return [None] * len(rows)
    first = done[0]
    return [float(np.log(r["run_s"] / first["run_s"]) / np.log(r["pieces"] / first["pieces"]))
            if r["finished"] and r["pieces"] != first["pieces"] else None for r in rows]


def main() -> int:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default="spot", help="a bundled mesh name or a mesh file")
    parser.add_argument("--style", default="cells")
    parser.add_argument("--pieces", default="10,20", help="comma-separated piece counts")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=60.0, help="minutes per run before it is stopped")
    parser.add_argument("--work", type=Path, default=None, help="keep the puzzles and runs here (reused)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.NAME=VALUE",
                        help="an option of every run (reassemble run --set; repeatable)")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for n in sorted(int(x) for x in args.pieces.split(",")):
            row = one(n, mesh=args.mesh, style=args.style, seed=args.seed, jobs=args.jobs,
                      timeout=60.0 * args.timeout, work=work, settings=args.set)
            rows.append(row)
            done = (f"strict {row['strict']:.3f}, {row['placed']} placed, {row['pairs']} pairs, "
                    f"steps {row['timings']}") if row["finished"] else "NOT FINISHED"
            print(f"{n:4d} pieces: run {row['run_s']:7.1f} s, peak {row['peak_gb']:.2f} GB, {done}", flush=True)
    for row, s in zip(rows, slopes(rows)):
        row["slope"] = s
    options = "".join(f", --set {x}" for x in args.set)
    bench.write(args.json, figures={"mesh": args.mesh, "style": args.style, "seed": args.seed, "jobs": args.jobs,
                                    "settings": args.set, "runs": rows},
                tables=[table(f"reassemble run on {args.mesh} broken into cells (seed {args.seed}), --jobs {args.jobs}"
                              + options,
                              ["pieces", "finished", "run s", "pairs s", "assembly s", "pairs registered",
                               "peak GB", "strict part accuracy", "slope from the smallest"],
                              [[r["pieces"], r["finished"], r["run_s"], r.get("timings", {}).get("pairs"),
                                r.get("timings", {}).get("assembly"), r.get("pairs"), r["peak_gb"],
                                r.get("strict"), r["slope"]] for r in rows],
                              ["d", "", ".0f", ".0f", ".0f", "", ".2f", ".3f", ".2f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
