"""Cost of the occupancy grids: ray parity (clean closed solids) against the winding number.

    python -m benchmarks.speed.occupancy                    # spot, loop-subdivided once (92k faces)
    python -m benchmarks.speed.occupancy --levels 0 --repeat 1

The grids are those ``integral_invariants`` builds for 8 radii from 2 % to 10 % of the
diagonal (geometric) at the default resolution (one grid per octave of r / h). For each
surface the seconds of all its grids are summed, the median of ``--repeat`` rounds:

- ``clean, parity``: the closed mesh through ``voxelize.occupancy`` (today's path, kept for
  every clean closed solid);
- ``clean, winding``: the same mesh through ``voxelize.winding_occupancy``, and how far its
  grids are from parity's (max |difference| over voxels);
- ``open``: three round holes, each 10 % of the diagonal across (the loader's surface of
  an open scan);
- ``overlap``: the mesh and a copy moved by a fifth of its diagonal, as the loader leaves
  them (``repair.repair_surface``: the faces inside the other removed, the seams open).
Each line gives the ratio to ``clean, parity``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from benchmarks.common import add_json_option, start, table


def _grids(vertices: np.ndarray):
    from reassemble.descriptors import DescriptorParams
    from reassemble.descriptors.voxelize import make_grid

    params = DescriptorParams()
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    radii = diag * 0.02 * 5 ** (np.arange(8) / 7)
    level = np.floor(np.log2(radii / radii.min()) + 1e-9).astype(int)
    grids = []
    for lev in np.unique(level):
        h = radii.min() * 2.0**lev / params.resolution
        grids.append(make_grid(lo, hi, h=h, margin=0.5 * radii[level == lev].max() + 4 * h))
    return grids


def _time(fn, grids, repeat: int) -> tuple[float, list]:
    runs, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = [fn(g) for g in grids]
        runs.append(time.perf_counter() - t)
    return statistics.median(runs), out


def _time_winding(scene, v, f, grids, repeat: int) -> tuple[float, list]:
    """The winding-number grids as ``integral_invariants`` builds them: one hierarchy for
    all of a surface's grids, its construction timed with them."""
    from reassemble.descriptors.closest import MeshDistance
    from reassemble.descriptors.voxelize import winding_occupancy
    from reassemble.repair import WindingNumber

    runs, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        winding, distance = WindingNumber(v, f), MeshDistance(v, f)
        out = [winding_occupancy(scene, v, f, g, winding=winding, distance=distance) for g in grids]
        runs.append(time.perf_counter() - t)
    return statistics.median(runs), out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default="spot")
    parser.add_argument("--levels", type=int, default=1, help="loop subdivisions of the mesh (default 1)")
    parser.add_argument("--repeat", type=int, default=3)
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    import trimesh

    from reassemble.descriptors.closest import MeshDistance
    from reassemble.descriptors.voxelize import occupancy
    from reassemble.files import load_mesh, resolve_mesh_path
    from reassemble.geometry import make_scene
    from reassemble.repair import repair_surface

    m = load_mesh(resolve_mesh_path(args.mesh))
    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    if args.levels:
        tm = tm.subdivide_loop(args.levels)
    v, f = np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64)
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    grids = _grids(v)
    print(f"{args.mesh}, {len(f)} faces; grids: {', '.join('x'.join(map(str, g.shape)) for g in grids)} "
          f"({sum(g.size for g in grids) / 1e6:.1f} M voxels)")

    scene = make_scene(v, f)
    make_scene(v[:3], f[:1])  # Open3D's first scene, apart
    distance = MeshDistance(v, f)
    base, parity = _time(lambda g: occupancy(scene, distance, g), grids, args.repeat)
    print(f"{'surface':<16s} {'faces':>7s} {'seconds':>8s} {'ratio':>6s}")
    print(f"{'clean, parity':<16s} {len(f):7d} {base:8.2f} {1.0:6.2f}")
    rows = [["clean, parity", len(f), base, 1.0, ""]]
    t, wind = _time_winding(scene, v, f, grids, args.repeat)
    diff = max(float(np.abs(a - b).max()) for a, b in zip(parity, wind))
    print(f"{'clean, winding':<16s} {len(f):7d} {t:8.2f} {t / base:6.2f}   max |winding - parity| {diff:.2g}")
    rows.append(["clean, winding", len(f), t, t / base, f"max |winding - parity| {diff:.2g}"])

    rng = np.random.default_rng(0)
    c = v[f].mean(axis=1)
    cut = np.zeros(len(f), bool)
    centres = []
    while len(centres) < 3:
        p = c[rng.integers(len(c))]
        if all(np.linalg.norm(p - q) > 0.3 * diag for q in centres):
            centres.append(p)
            cut |= np.linalg.norm(c - p, axis=1) < 0.05 * diag
    fo = f[~cut]
    so = make_scene(v, fo)
    t, _ = _time_winding(so, v, fo, grids, args.repeat)
    print(f"{'open (3 holes)':<16s} {len(fo):7d} {t:8.2f} {t / base:6.2f}")
    rows.append(["open (3 holes)", len(fo), t, t / base, ""])

    shift = np.array([0.2 * diag, 0.0, 0.0])
    v2 = np.vstack([v, v + shift])
    f2 = repair_surface(v2, np.vstack([f, f + len(v)])).faces
    s2 = make_scene(v2, f2)
    grids2 = _grids(v2)
    t2, par2 = _time(lambda g: occupancy(s2, g), grids2, 1)  # a reference cost on these larger grids
    t, _ = _time_winding(s2, v2, f2, grids2, args.repeat)
    print(f"{'overlap':<16s} {len(f2):7d} {t:8.2f} {t / t2:6.2f}   (ratio to parity on its own grids, "
          f"{t2:.2f} s)")
    rows.append(["overlap", len(f2), t, t / t2, f"ratio to parity on its own grids ({t2:.2f} s)"])
    bench.write(args.json, figures={"mesh": args.mesh, "levels": args.levels, "repeat": args.repeat,
                                    "voxels": sum(g.size for g in grids), "rows": rows},
                tables=[table(f"Occupancy grids of 8 radii, {args.mesh} ({len(f)} faces): seconds, median of "
                              f"{args.repeat}", ["surface", "faces", "seconds", "ratio to parity", "note"],
                              rows, ["", "d", ".2f", ".2f", ""])],
                headline=[("occupancy cost of an open mesh (winding number) / a clean one (ray parity)",
                           f"{rows[2][3]:.2f}x")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
