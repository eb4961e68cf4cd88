"""What keeping freed memory in the process (``allocator.retain_freed_memory``) saves.

    python -m benchmarks.speed.allocator                  # torus 3 pieces and cow 4 pieces, 3 rounds
    python -m benchmarks.speed.allocator --repeat 1

Each puzzle (``reassemble break`` of a bundled mesh) is run end to end (``run_to_folder``,
one process, seed 0) in a fresh interpreter, with the C library's default allocator
(``system``) and with the setting the command line makes (``retained``), the two
interleaved ``--repeat`` times. Per run: wall seconds, user and system CPU seconds,
minor page faults and peak resident memory of the process (``getrusage``); the table
gives the medians, and whether both settings wrote the same ``transforms.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import add_json_option, start, table

PUZZLES = (("torus", 3, 0), ("spot_low_resolution", 4, 1))
MODES = ("system", "retained")

_CHILD = """
import json, resource, sys
from reassemble.allocator import retain_freed_memory
from reassemble.pipeline import run_to_folder
if sys.argv[1] == "retained":
    assert retain_freed_memory()
run_to_folder([sys.argv[2]], sys.argv[3], seed=0, jobs=1, force=True)
r = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"user": r.ru_utime, "sys": r.ru_stime, "minflt": r.ru_minflt, "maxrss_mb": r.ru_maxrss / 1024}))
"""


def _run(mode: str, fragments: Path, out: Path) -> dict:
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _CHILD, mode, str(fragments), str(out)], capture_output=True,
                          text=True, check=True)
    row = json.loads(proc.stdout.strip().splitlines()[-1])
    row["wall"] = time.perf_counter() - t
    row["transforms"] = (out / "transforms.json").read_text()
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    add_json_option(parser)
    args = parser.parse_args(argv)
    run = start()
    from reassemble.puzzle import break_to_folder
    from reassemble.synth import BreakParams

    rows, figures = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for mesh, pieces, seed in PUZZLES:
            name = f"{mesh}_{pieces:02d}p_s{seed}"
            puzzle = Path(tmp) / name
            break_to_folder(mesh, puzzle, params=BreakParams(pieces=pieces), seed=seed)
            runs = {m: [] for m in MODES}
            for _ in range(args.repeat):
                for mode in MODES:
                    runs[mode].append(_run(mode, puzzle / "fragments", Path(tmp) / f"{name}_{mode}"))
            same = len({r["transforms"] for rs in runs.values() for r in rs}) == 1
            med = {m: {k: statistics.median(r[k] for r in rs) for k in ("wall", "user", "sys", "minflt", "maxrss_mb")}
                   for m, rs in runs.items()}
            figures[name] = {"median": med, "same_transforms": same,
                             "wall_ratio": med["retained"]["wall"] / med["system"]["wall"]}
            for m in MODES:
                v = med[m]
                rows.append([name, m, v["wall"], v["user"], v["sys"], int(v["minflt"]), v["maxrss_mb"],
                             v["wall"] / med["system"]["wall"], "yes" if same else "NO"])
                print(f"{name:28s} {m:9s} wall {v['wall']:6.1f} s  user {v['user']:6.1f}  sys {v['sys']:6.1f}  "
                      f"faults {int(v['minflt']):8d}  peak {v['maxrss_mb']:6.0f} MB", flush=True)
    cols = ["puzzle", "allocator", "wall s", "user s", "system s", "minor faults", "peak MB", "wall / system",
            "same transforms"]
    tab = table(f"One end-to-end run per process, median of {args.repeat}", cols, rows,
                ["", "", ".1f", ".1f", ".1f", "d", ".0f", ".2f", ""])
    ratios = [f["wall_ratio"] for f in figures.values()]
    run.write(args.json, figures=figures, tables=[tab],
              headline=[("wall time with freed memory kept (retained / system)",
                         " / ".join(f"{r:.2f}" for r in ratios))])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
