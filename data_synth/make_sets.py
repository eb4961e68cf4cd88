"""Build a regression puzzle set from seeds.

    python -m data_synth.make_sets smoke --out puzzles/smoke
    python -m data_synth.make_sets bench --out puzzles/bench --jobs 2

Each puzzle is a ``reassemble break`` output folder; ``index.json`` lists them. Puzzles
already built (same spec) are kept, so an interrupted build resumes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from reassemble.errors import ReassembleError
from reassemble.files import write_json
from reassemble.pipeline import break_to_folder
from reassemble.synth import BreakParams

from .sets import SETS, PuzzleSpec


def build_one(spec: PuzzleSpec, root: Path, force: bool = False) -> dict:
    out = root / spec.name
    gt = out / "ground_truth.json"
    params = BreakParams(pieces=spec.pieces, noise=spec.noise, chips=spec.chips, decimate=spec.decimate)
    if gt.is_file() and not force:
        saved = json.loads(gt.read_text())
        # every break parameter, not only the name's: a set made by an older generator
        # (other defaults, or a parameter since added) is not the set the figures are for
        if saved.get("seed") == spec.seed and saved.get("parameters") == params.to_dict():
            return {"name": spec.name, "seconds": 0.0, "cached": True}
    t0 = time.perf_counter()
    break_to_folder(spec.mesh, out, params=params, seed=spec.seed, force=True)
    return {"name": spec.name, "seconds": time.perf_counter() - t0, "cached": False}


def build_set(name: str, root: Path, *, jobs: int = 1, force: bool = False) -> list[dict]:
    specs = SETS[name]()
    root.mkdir(parents=True, exist_ok=True)
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as pool:
            results = list(pool.map(build_one, specs, [root] * len(specs), [force] * len(specs)))
    else:
        results = [build_one(s, root, force) for s in specs]
    index = [
        dict(dataclasses.asdict(s), name=s.name, ground_truth=f"{s.name}/ground_truth.json")
        for s in specs
    ]
    write_json(root / "index.json", {"set": name, "puzzles": index})
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m data_synth.make_sets", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("set", choices=sorted(SETS))
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--force", action="store_true", help="rebuild puzzles that exist")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    try:
        results = build_set(args.set, args.out, jobs=args.jobs, force=args.force)
    except ReassembleError as exc:
        print(f"make_sets: error: {exc}", file=sys.stderr)
        return 2
    built = [r for r in results if not r["cached"]]
    print(f"{args.set}: {len(results)} puzzles in {args.out}/ ({len(built)} built, "
          f"{len(results) - len(built)} kept) in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
