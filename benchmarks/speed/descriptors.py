"""Speed and memory of the integral invariants, and how they grow with mesh size and r/h.

    python -m benchmarks.speed.descriptors            # spot, loop-subdivided to 46k .. 737k vertices
    python -m benchmarks.speed.descriptors --big      # also 2.9M vertices

8 radii from 2 % to 10 % of the bounding-box diagonal (geometric), all vertices queried,
default settings; V/P (volume descriptors) and D2 timed separately. Each configuration
runs in a fresh process so peak memory is its own; V/P figures are the median of three
calls after a start-up call on a tiny mesh (imports, Open3D's first scene), which is
reported apart, as is the first call (first touch of the memory).

``reassemble describe`` end to end (start-up, reading and checking the mesh, all default
arrays, writing the .npz): an ellipsoid of 163 842 vertices (icosphere of 7 subdivisions,
axes 1, 0.6, 0.4), the same 8 radii, the whole process's wall time, median of three.
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

from benchmarks.common import ROOT, add_json_option, start, table

CHILD = r"""
import json, resource, sys, time
import numpy as np, trimesh
from reassemble.files import load_mesh
from reassemble.descriptors import DescriptorParams, integral_invariants
levels, d2, res = int(sys.argv[1]), sys.argv[2] == "1", float(sys.argv[3])
m = load_mesh(sys.argv[4])
tm = trimesh.Trimesh(m.vertices, m.faces)
for _ in range(abs(levels)):
    tm = tm.subdivide_loop(1)
V, F = np.asarray(tm.vertices), np.asarray(tm.faces)
if levels < 0:  # 100k vertices: quadric decimation of the 184k-vertex subdivision
    import open3d as o3d
    om = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    om = om.simplify_quadric_decimation(200_000)
    V, F = np.asarray(om.vertices), np.asarray(om.triangles)
diag = float(np.linalg.norm(np.ptp(V, axis=0)))
radii = diag * 0.02 * 5 ** (np.arange(8) / 7)
# one-time costs (imports, Open3D's first scene, loading the compiled D2 kernels: numba
# compiles them once per installation) on a tiny mesh, timed apart
t = time.perf_counter()
integral_invariants(m.vertices, m.faces, [0.5 * diag], params=DescriptorParams(with_d2=d2))
warmup = time.perf_counter() - t
runs = []
for _ in range(3):  # the median of three: single runs vary by 20 % here
    t = time.perf_counter()
    d = integral_invariants(V, F, radii, params=DescriptorParams(with_d2=d2, resolution=res))
    runs.append((time.perf_counter() - t, d.timings))
total, timings = sorted(runs, key=lambda x: x[0])[len(runs) // 2]
print(json.dumps({"vertices": len(V), "seconds": total, "timings": timings, "warmup": warmup,
                  "first": runs[0][0], "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
"""


def run(levels: int, d2: bool, res: float, mesh: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(levels), "1" if d2 else "0", str(res), mesh],
                         capture_output=True, text=True)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def describe_end_to_end(repeat: int = 3) -> dict:
    """Wall time of ``reassemble describe`` on the ellipsoid, whole process, median of ``repeat``."""
    import numpy as np
    import trimesh

    radii = ",".join(f"{0.02 * 5 ** (k / 7):.5f}" for k in range(8))
    with tempfile.TemporaryDirectory() as tmp:
        mesh = trimesh.creation.icosphere(subdivisions=7)
        mesh.vertices *= np.array([1.0, 0.6, 0.4])
        mesh.export(Path(tmp) / "ellipsoid.ply")
        runs = []
        for _ in range(repeat):
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "reassemble", "describe", str(Path(tmp) / "ellipsoid.ply"),
                            "--radii", radii, "--relative", "--out", str(Path(tmp) / "out.npz"), "--force"],
                           check=True, capture_output=True)
            runs.append(time.perf_counter() - t)
    return {"vertices": len(mesh.vertices), "seconds": statistics.median(runs), "runs": runs}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--big", action="store_true", help="include 2.9M vertices")
    parser.add_argument("--no-d2", action="store_true", help="time only V/P")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    mesh = str(ROOT / "reassemble" / "data" / "meshes" / "spot.obj")
    print("mesh: spot.obj loop-subdivided (100k: decimated from 184k); radii 2-10 % of the diagonal,")
    print("8 geometric; all vertices queried; one-time imports and Open3D start-up timed apart")
    print(f"{'vertices':>9} {'part':>5} {'seconds':>8} {'peak GB':>8}  stages")
    sizes, resolutions = [], []
    for levels in ([1, -2, 2, 3, 4] if args.big else [1, -2, 2, 3]):
        for d2 in ([False] if args.no_d2 else [False, True]):
            r = run(levels, d2, 8.0, mesh)
            if "error" in r:
                print(f"  {levels} subdivisions, d2={d2}: {r['error']}")
                continue
            sizes.append({"d2": d2, **r})
            stages = ", ".join(f"{k} {v:.2f}" for k, v in r["timings"].items() if k != "total")
            print(f"{r['vertices']:>9} {'V+D2' if d2 else 'V,P':>5} {r['seconds']:8.2f} {r['peak_gb']:8.2f}  {stages}"
                  f"  (first call {r['first']:.2f} s; start-up {r['warmup']:.2f} s)", flush=True)
    print("\nr/h (voxels per radius of the occupancy grids), V/P only, 184k vertices:")
    for res in (6.0, 8.0, 12.0, 16.0):
        r = run(2, False, res, mesh)
        if "error" in r:
            print(f"  resolution {res:4.0f}: {r['error']}")
            continue
        print(f"  resolution {res:4.0f}: {r['seconds']:6.2f} s, peak {r['peak_gb']:.2f} GB", flush=True)
        resolutions.append({"resolution": res, **r})
    e2e = describe_end_to_end()
    print(f"\nreassemble describe end to end, ellipsoid {e2e['vertices']} vertices: {e2e['seconds']:.2f} s "
          f"(runs {', '.join(f'{x:.2f}' for x in e2e['runs'])})")
    by_n: dict[int, dict] = {}
    for x in sizes:
        by_n.setdefault(x["vertices"], {})["d2" if x["d2"] else "vp"] = x
    rows = [[n, d["vp"]["seconds"] if "vp" in d else None, d["d2"]["seconds"] if "d2" in d else None,
             max(x["peak_gb"] for x in d.values())] for n, d in sorted(by_n.items())]
    bench.write(args.json, figures={"sizes": sizes, "resolutions": resolutions, "describe": e2e},
                tables=[table("spot.obj subdivided; 8 radii 2-10 % of the diagonal, all vertices (median of three "
                              "calls after start-up)", ["vertices", "V, P, H, H_rob s", "with D2, K2 s", "peak GB"],
                              [[a, "-" if b is None else b, "-" if c is None else c, d] for a, b, c, d in rows],
                              ["d", ".1f", ".1f", ".1f"]),
                        table("Voxels per radius (r/h), V and P only", ["resolution", "vertices", "seconds", "peak GB"],
                              [[x["resolution"], x["vertices"], x["seconds"], x["peak_gb"]] for x in resolutions],
                              ["g", "d", ".2f", ".2f"]),
                        table("reassemble describe end to end (start-up, reading, all default arrays, writing), "
                              "8 radii 2-10 % of the diagonal, median of three", ["mesh", "vertices", "seconds"],
                              [["ellipsoid", e2e["vertices"], e2e["seconds"]]], ["", "d", ".1f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
