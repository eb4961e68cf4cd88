"""What every benchmark prints first: the machine and the command, so figures can be rerun."""

from __future__ import annotations

import os
import platform
import sys


def machine_line() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError):
        mem = float("nan")
    return (f"machine: {cpu}, {os.cpu_count()} cores, {mem:.0f} GiB; "
            f"Python {platform.python_version()} on {platform.system()} {platform.machine()}")


def header() -> None:
    print(machine_line())
    print("command: " + " ".join([os.path.relpath(sys.argv[0])] + sys.argv[1:]))


def add_selection(parser, *, pieces: str) -> None:
    """The bench-set selection options every benchmark over the bench set takes."""
    from pathlib import Path

    from data_synth.sets import SETS

    parser.add_argument("root", type=Path, help="puzzle set folder (built if missing)")
    parser.add_argument("--set", default="bench", choices=sorted(SETS), help="which set (data_synth.sets; default bench)")
    parser.add_argument("--pieces", default=pieces)
    parser.add_argument("--seeds", default="0")
    parser.add_argument("--meshes", default=None, help="comma-separated subset of the bench meshes")
    parser.add_argument("--clean-only", action="store_true")
    parser.add_argument("--noisy-only", action="store_true")
    parser.add_argument("--jobs", type=int, default=1, help="puzzles run at once")
    parser.add_argument("--seed", type=int, default=0)


def select(args) -> list:
    """The puzzles of ``args.set`` the options select (the set is built in ``args.root`` first if missing)."""
    from data_synth.make_sets import build_set
    from data_synth.sets import SETS

    if not (args.root / "index.json").is_file():
        print(f"building the {args.set} set in {args.root} ...", flush=True)
        build_set(args.set, args.root, jobs=max(1, args.jobs))
    pieces = {int(p) for p in args.pieces.split(",")}
    seeds = {int(s) for s in args.seeds.split(",")}
    meshes = set(args.meshes.split(",")) if args.meshes else None
    return [s for s in SETS[args.set]() if s.pieces in pieces and s.seed in seeds
            and (meshes is None or s.mesh in meshes) and not (args.clean_only and s.noise)
            and not (args.noisy_only and not s.noise)]


def add_signature_radii(parser) -> None:
    parser.add_argument("--signature-radii", type=int, default=None,
                        help="signatures from this many of the finest descriptor radii "
                        "(Config.features.signature_radii; default Config's)")


def match_config(signature_radii: int | None):
    """Config with the benchmark's --signature-radii, or the default one."""
    from reassemble.config import Config, with_setting

    return Config() if signature_radii is None else with_setting(Config(), f"features.signature_radii={signature_radii}")


def described(gt_path, config, *, cache: bool = True):
    """The puzzle's :class:`pipeline.DescribedSet` under ``config``, cached beside the set.

    The cache (``<set>/_cache/<puzzle>-<key>.pkl``) is keyed by the fragments, the options
    the descriptors depend on and the source of the code computing them, so a change to
    any of them recomputes. Segmentation and matching studies then start in seconds.
    """
    import hashlib
    import inspect
    import pickle
    from pathlib import Path

    from reassemble import prepare
    from reassemble.pipeline import describe_fragments, read_puzzle

    gt_path = Path(gt_path)
    puzzle = read_puzzle(gt_path, with_labels=False)
    meshes = {n: (m.vertices, m.faces) for n, m in sorted(puzzle.meshes.items())}
    if not cache:
        return describe_fragments(meshes, config=config)
    code = Path(__file__).resolve().parents[1] / "reassemble"
    key = hashlib.sha256()
    for path in sorted(code.glob("descriptors/*.py")) + [code / "geometry.py"]:
        key.update(path.read_bytes())
    for fn in (describe_fragments, prepare._describe, prepare._smoothed_copies):
        key.update(inspect.getsource(fn).encode())
    key.update(repr((config.radii, config.denoise, config.describe)).encode())
    for v, f in meshes.values():
        key.update(v.tobytes())
        key.update(f.tobytes())
    path = gt_path.parent.parent / "_cache" / f"{gt_path.parent.name}-{key.hexdigest()[:16]}.pkl"
    if path.is_file():
        with open(path, "rb") as fh:
            return pickle.load(fh)
    out = describe_fragments(meshes, config=config)
    path.parent.mkdir(exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as fh:
        pickle.dump(out, fh, protocol=pickle.HIGHEST_PROTOCOL)
    tmp.replace(path)
    return out
