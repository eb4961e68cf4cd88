"""Time and peak memory of the integral invariants in one grid per radius and in tiles (--max-memory).

    python -m benchmarks.speed.tiling                 # ellipsoid (164k vertices) and spot (184k)
    python -m benchmarks.speed.tiling --fraction 0.25

8 radii from 2 % to 10 % of the bounding-box diagonal (geometric), all vertices queried,
default settings (D2 on). Each mesh runs untiled, then with ``max_memory`` set to
``--fraction`` of the largest grid's estimate (``tiles.BYTES_PER_VOXEL`` a voxel), each in a
fresh process so its peak resident memory is its own; the largest differences between the
two runs are reported as fractions of each array's largest value.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

from benchmarks.common import ROOT, add_json_option, start, table

CHILD = r"""
import ast, json, logging, resource, sys, time
import numpy as np, trimesh
from reassemble.files import load_mesh
from reassemble.descriptors import DescriptorParams, integral_invariants
from reassemble.descriptors.tiles import BYTES_PER_VOXEL
kind, max_memory, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
if kind == "ellipsoid":
    tm = trimesh.creation.icosphere(subdivisions=7)
    tm.vertices *= np.array([1.0, 0.6, 0.4])
else:
    m = load_mesh(sys.argv[4])
    tm = trimesh.Trimesh(m.vertices, m.faces).subdivide_loop(2)
V, F = np.asarray(tm.vertices), np.asarray(tm.faces)
diag = float(np.linalg.norm(np.ptp(V, axis=0)))
radii = diag * 0.02 * 5 ** (np.arange(8) / 7)
shapes = []
class Shapes(logging.Handler):
    def emit(self, record):
        msg = record.getMessage()
        if " grid" in msg:
            shapes.append(msg)
logging.getLogger("reassemble.descriptors.invariants").addHandler(Shapes())
logging.getLogger("reassemble.descriptors.invariants").setLevel(logging.INFO)
t = time.perf_counter()
d = integral_invariants(V, F, radii, params=DescriptorParams(max_memory=max_memory))
seconds = time.perf_counter() - t
np.savez(out, **{k: getattr(d, k) for k in ("V", "P", "H", "D2", "K2", "SA", "D", "SD2", "normal_area")})
grids = [ast.literal_eval(s.split(" grid")[0].split(" on a ")[1]) for s in shapes]
tiles = [int(s.split(" in ")[1].split()[0]) if " tiles of " in s else 1 for s in shapes]
print(json.dumps({"vertices": len(V), "seconds": seconds, "timings": d.timings, "tiles": tiles,
                  "largest_grid_bytes": max(int(np.prod(g)) for g in grids) * BYTES_PER_VOXEL,
                  "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
"""


def run(kind: str, max_memory: float, out: str) -> dict:
    mesh = str(ROOT / "reassemble" / "data" / "meshes" / "spot.obj")
    proc = subprocess.run([sys.executable, "-c", CHILD, kind, repr(max_memory), out, mesh], capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise SystemExit(proc.stderr.strip().splitlines()[-1])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def differences(a: str, b: str) -> dict:
    """The largest |a - b| of each array over its largest |a| (normals: the largest angle, degrees)."""
    import numpy as np

    out = {}
    with np.load(a) as x, np.load(b) as y:
        for key in x.files:
            if key == "normal_area":
                cos = np.clip(np.einsum("ijk,ijk->ij", x[key], y[key]), -1, 1)
                out["normal_deg"] = float(np.degrees(np.arccos(cos)).max())
            else:
                out[key] = float(np.abs(x[key] - y[key]).max() / np.abs(x[key]).max())
    return out


def main() -> int:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fraction", type=float, default=0.25, help="the limit, of the largest grid's estimate")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    rows, figures = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("ellipsoid", "spot"):
            whole = run(kind, 4e9, f"{tmp}/whole.npz")
            limit = args.fraction * whole["largest_grid_bytes"]
            tiled = run(kind, limit, f"{tmp}/tiled.npz")
            diff = differences(f"{tmp}/whole.npz", f"{tmp}/tiled.npz")
            figures.append({"mesh": kind, "untiled": whole, "tiled": tiled, "limit": limit, "differences": diff})
            for name, r in (("untiled", whole), (f"limit {limit / 1e6:.0f} MB", tiled)):
                print(f"{kind:9s} {r['vertices']:7d} {name:14s} {r['seconds']:6.1f} s  peak {r['peak_gb']:.2f} GB  "
                      f"tiles {r['tiles']}", flush=True)
                rows.append([kind, r["vertices"], name, sum(r["tiles"]), r["seconds"], r["peak_gb"]])
            print("  largest difference / largest value: " + ", ".join(f"{k} {v:.1e}" for k, v in diff.items()))
    bench.write(args.json, figures={"runs": figures},
                tables=[table(f"8 radii 2-10 % of the diagonal, D2 on, all vertices; tiled: --max-memory "
                              f"{args.fraction:g} of the largest grid's estimate",
                              ["mesh", "vertices", "limit", "occupancy grids or tiles", "seconds", "peak GB"], rows,
                              ["", "d", "", "d", ".1f", ".2f"]),
                        table("Tiled against untiled: largest difference over the array's largest value",
                              ["mesh"] + list(figures[0]["differences"]),
                              [[f["mesh"]] + list(f["differences"].values()) for f in figures],
                              [""] + [".1e"] * len(figures[0]["differences"]))])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
