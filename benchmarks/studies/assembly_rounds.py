"""What the sub-assembly registrations (group rounds) cost in one assembly of a large set.

    reassemble break spot --pieces 100 --style cells --seed 0 --out /tmp/spot100
    python -m benchmarks.studies.assembly_rounds /tmp/spot100 --jobs 2

The set is segmented and its first pairs registered as ``run`` does (candidate pairs from
``retrieval.min_fragments`` fragments), then assembled twice from those pairs: without
the group rounds (``assembly.group_rounds`` = 0, as the assemblies that only decide which
fragments ask for partners run) and with the defaults. Reported: seconds, fragments in
the main assembly, sub-assemblies, and the touching pairs among the registered ones
(contact >= 5 % of the smaller break, the ground truth's). Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("puzzle", type=Path, help="a puzzle folder (ground_truth.json, fragments/)")
    parser.add_argument("--jobs", type=int, default=2)
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    from benchmarks.studies.retrieval_cues import truth_share
    from reassemble import assembly
    from reassemble.config import Config
    from reassemble.inputs import load_fragments
    from reassemble.pipeline import reassemble

    gt = json.loads((args.puzzle / "ground_truth.json").read_text())
    t0 = time.perf_counter()
    meshes, _ = load_fragments([args.puzzle / "fragments"])  # read as run reads them
    names = sorted(meshes)
    result = reassemble(meshes, Config(), assemble=False, jobs=args.jobs)
    matching = time.perf_counter() - t0
    share = truth_share(gt, [f.name for f in result.fragments])
    touching = sum(share[i, j] >= 0.05 for i, j in result.pairs)
    print(f"{len(names)} fragments: {len(result.pairs)} pairs registered ({touching} of "
          f"{int((share >= 0.05).sum() // 2)} touching pairs) in {matching:.0f} s", flush=True)
    config = result.config
    surfaces, meshes = [f.surface for f in result.fragments], [f.mesh for f in result.fragments]
    rows = []
    for rounds in (0, config.assembly.group_rounds):
        t = time.perf_counter()
        a = assembly.assemble(surfaces, meshes, result.pairs, size=result.size,
                              params=dataclasses.replace(config.assembly, group_rounds=rounds),
                              reg_params=config.registration, seed=config.seed, jobs=args.jobs)
        seconds = time.perf_counter() - t
        row = [rounds, seconds, int(a.placed.sum()), int(len(np.unique(a.group))), len(a.merges)]
        print(f"group rounds {rounds}: {seconds:.0f} s, {row[2]} in the main assembly, {row[3]} sub-assemblies, "
              f"{row[4]} merges", flush=True)
        rows.append(row)
    bench.write(args.json, figures={"fragments": len(names), "pairs": len(result.pairs),
                                    "touching_registered": int(touching),
                                    "touching": int((share >= 0.05).sum() // 2), "matching_s": matching,
                                    "assemblies": [dict(zip(["group_rounds", "seconds", "main", "groups", "merges"],
                                                            r)) for r in rows]},
                tables=[table(f"{args.puzzle.name}: one assembly from the first {len(result.pairs)} registered pairs "
                              f"({touching} of them touching)",
                              ["group rounds", "seconds", "in the main assembly", "sub-assemblies", "merges"], rows,
                              ["d", ".0f", "d", "d", "d"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
