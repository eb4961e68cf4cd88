"""What every benchmark shares: its provenance (machine, command, commit) and its JSON record.

A benchmark calls :func:`start` first, which prints the machine and the exact command, and
ends with :meth:`Run.write`, which writes ``benchmarks/results/<name>.json`` (or ``--json
PATH``): the provenance, the date, the figures and the tables ``python -m benchmarks.report``
turns into ``docs/results.md``. No figure is copied by hand.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PACKAGES = ("numpy", "scipy", "scikit-learn", "trimesh", "manifold3d", "open3d-cpu", "open3d", "pillow")


def machine() -> dict:
    """CPU model, cores, RAM, OS, Python and the versions of the key packages."""
    from importlib import metadata

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
    except (ValueError, OSError, AttributeError):
        mem = None
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return {"cpu": cpu, "cores": os.cpu_count(), "usable_cores": usable,
            "ram_gib": None if mem is None else round(mem, 1),
            "os": platform.platform(), "python": platform.python_version(), "packages": versions}


def machine_line(m: dict | None = None) -> str:
    m = machine() if m is None else m
    mem = "?" if m["ram_gib"] is None else f"{m['ram_gib']:.0f}"
    return f"machine: {m['cpu']}, {m['cores']} cores, {mem} GiB; Python {m['python']} on {m['os']}"


def git_state() -> dict:
    """The commit of the working tree and whether tracked files (other than the records) differ from it."""
    def git(*args):
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                              check=True).stdout.strip()
    try:
        commit = git("rev-parse", "HEAD")
        # the records themselves do not change what is measured
        dirty = bool(git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)benchmarks/results"))
    except (OSError, subprocess.CalledProcessError):
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": dirty}


def benchmark_name() -> str:
    """``accuracy.segmentation`` for ``python -m benchmarks.accuracy.segmentation``."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None and spec.name.startswith("benchmarks."):
        return spec.name[len("benchmarks."):]
    path = Path(sys.argv[0]).resolve()
    try:
        return ".".join(path.relative_to(ROOT / "benchmarks").with_suffix("").parts)
    except ValueError:
        return path.stem


def command_line() -> str:
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    prog = f"python -m {spec.name}" if spec is not None else f"python {os.path.relpath(sys.argv[0])}"
    return " ".join([prog] + [shlex.quote(a) for a in sys.argv[1:]])


def add_json_option(parser) -> None:
    parser.add_argument("--json", type=Path, default=None, metavar="PATH",
                        help="write the results here (default benchmarks/results/<name>.json)")


def table(title: str, columns: list[str], rows: list[list], formats: list[str] | None = None) -> dict:
    """A table for ``docs/results.md``: raw values, and a format spec per column ('' = str)."""
    return {"title": title, "columns": list(columns), "rows": [list(r) for r in rows],
            "formats": list(formats) if formats is not None else [""] * len(columns)}


class Run:
    """One run of a benchmark: its provenance, captured at the start, and its JSON record."""

    def __init__(self):
        self.name = benchmark_name()
        self.command = command_line()
        self.machine = machine()
        self.git = git_state()
        self.started = datetime.datetime.now(datetime.timezone.utc)
        self.t0 = time.perf_counter()
        self.load_start = _load()

    def write(self, path: Path | None, *, figures: dict, tables: list[dict] = (),
              headline: list[tuple[str, str]] = ()) -> Path:
        """Write the record (atomically) and say where; ``headline``: (what, figure) rows for the README."""
        path = Path(path) if path is not None else RESULTS / f"{self.name}.json"
        record = {"format": "reassemble-benchmark/1", "benchmark": self.name, "command": self.command,
                  "commit": self.git["commit"], "dirty": self.git["dirty"],
                  "date": self.started.strftime("%Y-%m-%dT%H:%M:%SZ"),
                  "seconds": round(time.perf_counter() - self.t0, 1),
                  "machine": self.machine, "load_average": [self.load_start, _load()],
                  "headline": [list(h) for h in headline], "tables": list(tables), "figures": figures}
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(record, indent=1, default=_plain, allow_nan=True) + "\n")
        tmp.replace(path)
        shown = os.path.relpath(path) if path.resolve().is_relative_to(Path.cwd()) else path
        print(f"results: {shown}")
        return path


def _load() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except (OSError, AttributeError):
        return None


def _plain(x):
    """numpy scalars and arrays, paths and tuples as JSON values."""
    import numpy as np

    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON serializable: {type(x).__name__}")


def start() -> Run:
    """Print the machine and the command (so figures can be rerun) and start the record."""
    run = Run()
    print(machine_line(run.machine))
    print("command: " + run.command)
    commit = run.git["commit"] or "unknown"
    print(f"commit: {commit}" + (" (tree modified)" if run.git["dirty"] else ""))
    return run


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
    add_json_option(parser)


def select(args) -> list:
    """The puzzles of ``args.set`` the options select; those not built yet are built in
    ``args.root`` first (only the selected ones: a whole set takes an hour)."""
    from data_synth.make_sets import build_specs
    from data_synth.sets import SETS

    pieces = {int(p) for p in args.pieces.split(",")}
    seeds = {int(s) for s in args.seeds.split(",")}
    meshes = set(args.meshes.split(",")) if args.meshes else None
    specs = [s for s in SETS[args.set]() if s.pieces in pieces and s.seed in seeds
             and (meshes is None or s.mesh in meshes) and not (args.clean_only and s.noise)
             and not (args.noisy_only and not s.noise)]
    missing = [s for s in specs if not (args.root / s.name / "ground_truth.json").is_file()]
    if missing:
        print(f"building {len(missing)} puzzles of the {args.set} set in {args.root} ...", flush=True)
        build_specs(missing, args.root, set_name=args.set, jobs=max(1, args.jobs))
    return specs


def add_signature_radii(parser) -> None:
    parser.add_argument("--signature-radii", type=int, default=None,
                        help="signatures from this many of the finest descriptor radii "
                        "(Config.features.signature_radii; default Config's)")


def match_config(signature_radii: int | None, settings: tuple[str, ...] = ()):
    """Config with the benchmark's --signature-radii and --setting values, or the default one."""
    from reassemble.config import Config, with_setting

    config = Config() if signature_radii is None else with_setting(Config(), f"features.signature_radii={signature_radii}")
    for setting in settings:
        config = with_setting(config, setting)
    return config


def add_setting_option(parser) -> None:
    """``--setting SECTION.NAME=VALUE``: a configuration value for every run of the benchmark."""
    parser.add_argument("--setting", action="append", default=[], metavar="SECTION.NAME=VALUE",
                        help="a configuration value for every run, as `reassemble run --set` (repeatable)")


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
    code = ROOT / "reassemble"
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


def fpfh_baseline(gt_path, *, seed: int) -> tuple[dict, float]:
    """The Open3D textbook pipeline (:func:`reassemble.baseline.fpfh_assemble`) on a puzzle,
    scored like ours: (the score of :func:`reassemble.metrics.evaluate`, seconds)."""
    import numpy as np

    from reassemble.baseline import fpfh_assemble
    from reassemble.metrics import ScoringFragment, evaluate
    from reassemble.pipeline import read_puzzle, reference_size

    puzzle = read_puzzle(gt_path, with_labels=False)
    names = sorted(puzzle.meshes)
    meshes = [(puzzle.meshes[n].vertices, puzzle.meshes[n].faces) for n in names]
    t = time.perf_counter()
    poses = fpfh_assemble(meshes, voxel=reference_size(meshes) / 40, seed=seed)
    elapsed = time.perf_counter() - t
    truth = puzzle.ground_truth
    fragments = [ScoringFragment(n, *meshes[k], np.asarray(truth["fragments"][n]["transform"]))
                 for k, n in enumerate(names)]
    pred = {n: {"transform": poses[k], "placed": True} for k, n in enumerate(names)}
    score = evaluate(fragments, pred, bbox_min=np.array(truth["object"]["bbox_min"]),
                     bbox_max=np.array(truth["object"]["bbox_max"]))
    return score, elapsed
