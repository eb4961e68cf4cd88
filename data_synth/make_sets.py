"""Build a regression puzzle set from seeds.

    python -m data_synth.make_sets smoke --out puzzles/smoke
    python -m data_synth.make_sets bench --out puzzles/bench --jobs 2
    python -m data_synth.make_sets field-validation --out puzzles/field-validation --jobs 2 --shared ../shared

Each puzzle is a ``reassemble break`` output folder; ``index.json`` lists them. Puzzles
already built (same spec) are kept, so an interrupted build resumes. The field sets break
meshes from ``--shared`` (a folder holding data/meshes; without it those meshes are skipped) too; every field
mesh is first written to ``<out>/_sources/<mesh>.ply`` as it is broken (simplified when
large, see ``data_synth.sets.FIELD_MAX_FACES``), which is also what the puzzles' ground
truth names as their source.
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

from .sets import FIELD_MAX_FACES, FIELD_MESHES, FIELD_TARGET_FACES, SETS, PuzzleSpec

DEFAULT_SHARED = None  # the third-party meshes are read only from a folder given as --shared


def break_params(spec: PuzzleSpec) -> BreakParams:
    return BreakParams(pieces=spec.pieces, noise=spec.noise, chips=spec.chips, decimate=spec.decimate,
                       style=spec.style, roughness=spec.roughness)


def build_one(spec: PuzzleSpec, root: Path, force: bool = False, mesh: str | Path | None = None) -> dict:
    """Break ``spec`` into ``root/<spec.name>``; ``mesh`` the file to break (default: the
    bundled mesh ``spec.mesh``)."""
    out = root / spec.name
    gt = out / "ground_truth.json"
    params = break_params(spec)
    if gt.is_file() and not force:
        saved = json.loads(gt.read_text())
        # every break parameter, not only the name's: a set made by an older generator
        # (other defaults, or a parameter since added) is not the set the figures are for
        if saved.get("seed") == spec.seed and saved.get("parameters") == params.to_dict():
            return {"name": spec.name, "seconds": 0.0, "cached": True}
    t0 = time.perf_counter()
    try:
        break_to_folder(mesh or spec.mesh, out, params=params, seed=spec.seed, force=True)
    except ReassembleError as exc:
        raise ReassembleError(f"{spec.name}: {exc}") from None
    return {"name": spec.name, "seconds": time.perf_counter() - t0, "cached": False}


def simplified(vertices, faces, target_faces: int):
    """A closed mesh simplified by manifold3d to at most about ``target_faces`` triangles:
    the largest error tolerance (bisection over 1e-5..1e-2 of the diagonal) that keeps at
    least that many. manifold3d keeps it a valid solid, which the booleans need."""
    import manifold3d as mf
    import numpy as np

    solid = mf.Manifold(mf.Mesh64(vert_properties=np.ascontiguousarray(vertices, dtype=np.float64),
                                  tri_verts=np.ascontiguousarray(faces, dtype=np.uint32)))
    diag = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    lo, hi = np.log(1e-5), np.log(1e-2)
    best = solid
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        small = solid.simplify(float(np.exp(mid)) * diag)
        if small.num_tri() >= target_faces:
            lo, best = mid, small
        else:
            hi = mid
    mesh = best.to_mesh64()
    return np.asarray(mesh.vert_properties)[:, :3].copy(), np.asarray(mesh.tri_verts, dtype=np.int64).copy()


def add_field_options(parser, *, sets: str = "SETS/field-validation, SETS/field-tuning") -> None:
    """``--sets`` (the folder of the field sets, built where missing) and ``--shared``, the
    options of everything that builds them."""
    parser.add_argument("--sets", type=Path, default=Path(__file__).resolve().parents[1] / "puzzles",
                        help=f"folder of the sets: {sets} (built if missing)")
    parser.add_argument("--shared", type=Path, default=DEFAULT_SHARED,
                        help="folder holding data/meshes, for the field sets' third-party meshes (without it "
                        "they are skipped)")


def prepare_source(mesh: str, root: Path, shared: Path | None) -> Path:
    """``root/_sources/<mesh>.ply``: the field mesh as broken (written once)."""
    from reassemble.files import load_mesh, resolve_mesh_path, write_ply

    from . import shapes

    out = root / "_sources" / f"{mesh}.ply"
    if out.is_file():
        return out
    source = FIELD_MESHES[mesh].source
    if source.startswith("shapes:"):
        vertices, faces = getattr(shapes, source.split(":", 1)[1])()
    else:
        if source.startswith("shared:"):
            if shared is None:
                raise ReassembleError(f"{mesh}: a third-party mesh that is not bundled (its license does not "
                                      "allow it): give --shared, the folder holding data/meshes")
            path = Path(shared) / "data" / "meshes" / source.split(":", 1)[1]
            if not path.is_file():
                raise ReassembleError(f"{path}: no such file (the field sets need --shared, the folder "
                                      "holding data/meshes)")
        else:
            path = resolve_mesh_path(source)
        data = load_mesh(path, require_closed=True)
        vertices, faces = data.vertices, data.faces
        if len(faces) > FIELD_MAX_FACES:
            vertices, faces = simplified(vertices, faces, FIELD_TARGET_FACES)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp.ply")
    write_ply(tmp, vertices, faces)
    tmp.replace(out)
    return out


def _build_or_note(spec: PuzzleSpec, root: Path, force: bool, mesh) -> dict:
    try:
        return build_one(spec, root, force, mesh)
    except ReassembleError as exc:
        return {"name": spec.name, "seconds": 0.0, "cached": False, "error": str(exc)}


def build_specs(specs: list[PuzzleSpec], root: Path, *, set_name: str, jobs: int = 1, force: bool = False,
                shared: Path | None = DEFAULT_SHARED, keep_going: bool = False) -> list[dict]:
    """Build these puzzles of the set ``set_name`` into ``root`` (kept where built already).

    ``keep_going``: a puzzle the generator cannot make gets an ``error`` entry instead of
    stopping the build.
    """
    root.mkdir(parents=True, exist_ok=True)
    meshes = [None] * len(specs)
    if set_name.startswith("field"):
        sources = {m: prepare_source(m, root, shared) for m in sorted({s.mesh for s in specs})}
        meshes = [sources[s.mesh] for s in specs]
    order = sorted(range(len(specs)), key=lambda k: -specs[k].pieces)  # the longest first
    args = ([specs[k] for k in order], [root] * len(specs), [force] * len(specs), [meshes[k] for k in order])
    build = _build_or_note if keep_going else build_one
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as pool:
            done = list(pool.map(build, *args))
    else:
        done = list(map(build, *args))
    results = [None] * len(specs)
    for k, r in zip(order, done):
        results[k] = r
    return results


def build_set(name: str, root: Path, *, jobs: int = 1, force: bool = False, shared: Path | None = DEFAULT_SHARED,
              keep_going: bool = False) -> list[dict]:
    """Build the set ``name`` into ``root`` and write its ``index.json`` (with
    ``keep_going``, puzzles the generator could not make are listed apart, not indexed)."""
    specs = SETS[name]()
    results = build_specs(specs, root, set_name=name, jobs=jobs, force=force, shared=shared, keep_going=keep_going)
    failed = {r["name"]: r["error"] for r in results if "error" in r}
    index = [
        dict(dataclasses.asdict(s), name=s.name, ground_truth=f"{s.name}/ground_truth.json")
        for s in specs if s.name not in failed
    ]
    extra = {"not_generated": failed} if failed else {}
    write_json(root / "index.json", {"set": name, "puzzles": index, **extra})
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m data_synth.make_sets", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("set", choices=sorted(SETS))
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--force", action="store_true", help="rebuild puzzles that exist")
    parser.add_argument("--shared", type=Path, default=DEFAULT_SHARED,
                        help="folder holding data/meshes, for the field sets (the field sets' third-party meshes; without it they are skipped)")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    try:
        results = build_set(args.set, args.out, jobs=args.jobs, force=args.force, shared=args.shared,
                            keep_going=True)
    except ReassembleError as exc:
        print(f"make_sets: error: {exc}", file=sys.stderr)
        return 2
    failed = [r for r in results if "error" in r]
    built = [r for r in results if not r["cached"] and "error" not in r]
    print(f"{args.set}: {len(results) - len(failed)} puzzles in {args.out}/ ({len(built)} built, "
          f"{len(results) - len(built) - len(failed)} kept) in {time.perf_counter() - t0:.1f} s")
    for r in failed:
        print(f"make_sets: error: not generated: {r['error']}", file=sys.stderr)
    return 2 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
