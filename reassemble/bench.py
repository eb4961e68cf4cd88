"""``reassemble bench``: solve and score every fracture set of a dataset, on Dask distributed.

A *set* is a folder holding two or more mesh files: either pieces in assembled pose
(Breaking Bad's ``category/object/fractured_k/piece_*.obj``; the truth is the identity)
or a puzzle written by ``reassemble break`` (its ``ground_truth.json`` is the truth).
Pieces in assembled pose are given seeded random poses and shuffled names, as ``break``
does, solved with ``run``'s pipeline (:func:`pipeline.reassemble`, one process) and scored
with :func:`metrics.evaluate`.

:func:`discover`, :func:`select`, :func:`summarize`, :func:`summary_markdown` and the
plots are pure; :func:`run_set` is the task one Dask worker runs per set (it never
raises: an error is part of its record); :func:`bench` is the orchestrator (cluster,
``results.jsonl``, progress bar, summaries). Each set is one task: a ``LocalCluster``
(one single-threaded worker process per core) or an existing cluster's scheduler.
A task solves its set in a child process forked from a clean, preloaded fork server, so
that a set over its time or memory limit can be killed without killing the worker.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import time
import traceback
from pathlib import Path

import numpy as np

from . import __version__
from .errors import ReassembleError, first_line
from .files import MESH_SUFFIXES

log = logging.getLogger(__name__)

RESULTS_FORMAT = "reassemble-bench/1"
PRIMARY = "anchor_largest"  # the literature's frame: the largest piece anchored at its true pose
ANCHOR_FREE = "best_anchor"  # the anchor most favourable to the prediction: no anchor choice penalized
BINS = ((2, 5), (6, 10), (11, 20))
ROTATION_EDGES = (0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 45.0, 90.0, 180.0)  # histogram bins, degrees
CHOICES = (
    "Scoring (docs/method/metrics.md): 1000 surface points per piece, object scaled to a unit bounding box "
    "(longest side 1); prediction moved so the largest piece (by area) sits at its true pose "
    "(`anchor_largest`), as Jigsaw, PuzzleFusion++ and GARF anchor it. "
    "PA: Breaking Bad part accuracy (mean squared chamfer sum < 0.01, multi_part_assembly's calc_part_acc); "
    "RMSE(R): Euler 'zyx' angles, degrees (rot_metrics 'rmse'); RMSE(T): piece centroids, unit-box units "
    "(trans_metrics 'rmse'); CD: shape chamfer, squared, unit box (shape_cd_loss at test time). "
    "Strict PA: mean unsquared chamfer < 1 % of the bounding-box diagonal; geodesic: rotation angle of "
    "R_true^T R_pred. Anchor-free: the same with the anchor piece most favourable to the prediction. "
    "A set that failed (error, timeout) counts with part accuracy 0 and unsolved; the error figures "
    "(RMSE, CD) are means over the sets scored. Every figure is a mean over sets of the per-set figure."
)


@dataclasses.dataclass(frozen=True)
class BenchSet:
    """One fracture set of a dataset (see :func:`discover`).

    Attributes
    ----------
    id : its folder relative to the dataset, '/'-separated ('.' for the dataset itself)
    path : its folder
    kind : 'assembled' (pieces in assembled pose) or 'puzzle' (a ``ground_truth.json``)
    pieces : number of pieces
    category : the folders above object/fracture ('everyday/BeerBottle' in
        ``everyday/BeerBottle/<object>/fractured_0``), None in a shallower tree
    """

    id: str
    path: str
    kind: str
    pieces: int
    category: str | None


def _meshes_in(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)


def discover(root: str | Path) -> list[BenchSet]:
    """Every fracture set below ``root``, sorted by id.

    A folder with a ``ground_truth.json`` is a puzzle (its ``fragments/`` folder is not a
    set of its own); any other folder with two or more mesh files is a set in assembled
    pose. Folders whose names start with '.' or '_' (caches) are skipped.
    """
    root = Path(root)
    if not root.is_dir():
        raise ReassembleError(f"{root}: no such folder (expected a dataset: folders of fragment meshes)")
    sets = []
    for folder, dirs, _ in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith((".", "_")))
        folder = Path(folder)
        rel = folder.relative_to(root)
        parts = rel.parts
        category = "/".join(parts[:-2]) if len(parts) >= 3 else None
        if (folder / "ground_truth.json").is_file():
            dirs[:] = []  # its fragments/ belong to it
            try:
                with open(folder / "ground_truth.json") as fh:
                    pieces = len(json.load(fh).get("fragments", {}))
            except (OSError, ValueError, AttributeError):
                pieces = 0  # unreadable: run_set records the error
            sets.append(BenchSet(rel.as_posix(), str(folder), "puzzle", pieces, category))
            continue
        meshes = _meshes_in(folder)
        if len(meshes) >= 2:
            sets.append(BenchSet(rel.as_posix(), str(folder), "assembled", len(meshes), category))
    return sorted(sets, key=lambda s: s.id)


def select(sets: list[BenchSet], *, pieces: tuple[int, int] = (2, 20), limit: int | None = None,
           seed: int = 0) -> list[BenchSet]:
    """The sets with ``pieces[0] <= pieces <= pieces[1]``; with ``limit``, a seeded random
    sample of that many of them (the same sample for the same seed), in id order."""
    chosen = [s for s in sets if pieces[0] <= s.pieces <= pieces[1]]
    if limit is not None and limit < len(chosen):
        keep = np.random.default_rng(seed).permutation(len(chosen))[:limit]
        chosen = [chosen[k] for k in sorted(keep)]
    return chosen


def _qualified(fn) -> str | None:
    return None if fn is None else f"{fn.__module__}.{fn.__qualname__}"


def options_key(config, *, n_points: int, solver=None, extra=None) -> str:
    """What a set's result depends on besides the set: the version, the Config (seed and
    settings), the points per piece, the solver and the extra scores. A rerun skips sets with
    this key. The pieces filter, limit, timeout and workers select or schedule sets: they are
    not in it."""
    from .config import to_dict

    what = {"version": __version__, "config": to_dict(config), "n_points": n_points, "solver": _qualified(solver)}
    if extra is not None:  # only when given: the keys of runs without extra scores stay as they were
        what["extra"] = _qualified(extra)
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:16]


def set_seed(seed: int, set_id: str) -> int:
    """The seed of one set's poses: from the run's seed and the set's id (not its position)."""
    return int.from_bytes(hashlib.sha256(f"{seed}:{set_id}".encode()).digest()[:8], "little")


def posed_set(bench_set: BenchSet, *, config, seed: int):
    """The set as ``run`` sees it, and its truth.

    Returns
    -------
    meshes : name -> (vertices, faces), read as ``run`` reads them (repaired), in random poses
    truth : list of :class:`metrics.ScoringFragment`, the pieces as read (not repaired)
    bbox_min, bbox_max : (3,) the assembled object's bounding box
    """
    from .files import load_mesh
    from .geometry import transform_points
    from .inputs import load_fragments
    from .metrics import ScoringFragment
    from .synth import BreakParams, _pose

    folder = Path(bench_set.path)
    if bench_set.kind == "puzzle":
        from .puzzle import read_puzzle

        puzzle = read_puzzle(folder / "ground_truth.json", with_labels=False)
        gt = puzzle.ground_truth
        files = sorted({(folder / e.get("file", f"fragments/{n}.ply")).parent for n, e in gt["fragments"].items()})
        meshes, _ = load_fragments(files, fill_holes=config.fill_holes, split=config.split_bodies)
        truth = [ScoringFragment(n, m.vertices, m.faces, np.asarray(gt["fragments"][n]["transform"], float))
                 for n, m in sorted(puzzle.meshes.items())]
        return meshes, truth, np.array(gt["object"]["bbox_min"], float), np.array(gt["object"]["bbox_max"], float)
    solids, _ = load_fragments([folder], fill_holes=config.fill_holes)
    raw = {p.stem: load_mesh(p, require_closed=False, weld=False) for p in _meshes_in(folder)}
    stems = sorted(raw)
    allv = np.vstack([raw[s].vertices for s in stems])
    bbox_min, bbox_max = allv.min(axis=0), allv.max(axis=0)
    rng = np.random.default_rng(seed)
    width = max(2, len(str(len(stems) - 1)))
    names = {s: f"fragment_{k:0{width}d}" for s, k in zip(stems, rng.permutation(len(stems)))}
    world = [(names[s], raw[s].vertices, raw[s].faces, np.zeros(len(raw[s].faces), np.int8)) for s in stems]
    posed = _pose(world, params=BreakParams(pieces=len(stems)), diag=float(np.linalg.norm(bbox_max - bbox_min)),
                  pose_rng=rng, noise_rng=rng)
    T = {fr.name: fr.T_world_fragment for fr in posed}
    truth = [ScoringFragment(fr.name, fr.vertices, fr.faces, fr.T_world_fragment) for fr in posed]
    meshes = {}
    for stem, (v, f) in solids.items():
        name = names.get(stem)
        if name is not None:
            meshes[name] = (transform_points(np.linalg.inv(T[name]), v), f)
    return dict(sorted(meshes.items())), truth, bbox_min, bbox_max


def pipeline_solver(meshes: dict, *, config) -> tuple[dict, dict]:
    """``run``'s pipeline (:func:`pipeline.reassemble`, one process).

    Returns
    -------
    predicted : name -> ``{"transform": (4, 4) T_world_fragment, "placed": bool, "fracture":
        (faces,) bool, "segmented": (faces,) bool}``, the fracture faces the run found after
        its assembly and those its segmentation labelled (``analysis.npz``'s ``fracture_k``
        and ``segmented_k``; a solver that does not segment may leave them out)
    info : what ``report.json`` says of the run: its steps' seconds, the gap it used (a
        fraction of the reference size), the most Taubin iterations a fragment was matched with
        and, when the run segmented again, ``fallback`` (as in ``report.json``)
    """
    from .pipeline import reassemble

    result = reassemble(meshes, config, jobs=1)
    predicted = {f.name: {"transform": result.T_world[k], "placed": bool(result.assembly.placed[k]),
                          "fracture": result.fracture[k], "segmented": np.asarray(f.segmentation.fracture, bool)}
                 for k, f in enumerate(result.fragments)}
    info = {"timings_s": {k: round(v, 3) for k, v in result.timings.items()},
            "gap": round(float(result.config.registration.gap), 6),
            "smoothing": int(max(f.smoothing for f in result.fragments))}
    if result.fallback is not None:  # which segmentations were tried, and which assembly was kept
        info["fallback"] = result.fallback
    return predicted, info


def _solve_and_score(bench_set: BenchSet, *, config, n_points: int, solver, extra=None) -> dict:
    """Pose, solve and score one set (raises on any failure); with ``extra``, its scores too."""
    from .metrics import evaluate

    seed = set_seed(config.seed, bench_set.id)
    t0 = time.perf_counter()
    meshes, truth, bbox_min, bbox_max = posed_set(bench_set, config=config, seed=seed)
    t1 = time.perf_counter()
    predicted, info = (solver or pipeline_solver)(meshes, config=config)
    t2 = time.perf_counter()
    score = evaluate(truth, predicted, bbox_min=bbox_min, bbox_max=bbox_max, n_points=n_points, seed=config.seed)
    t3 = time.perf_counter()
    primary = score["alignments"][PRIMARY]
    record = {"pieces": len(truth), "placed": score["n_placed"], "anchor": primary.get("anchor"),
              "metrics": {mode: a["summary"] for mode, a in score["alignments"].items()},
              "rotation_errors_deg": [round(f["rotation_error_deg"], 6) for f in primary["fragments"].values()],
              "timings_s": {"load": round(t1 - t0, 3), "solve": round(t2 - t1, 3), "score": round(t3 - t2, 3)},
              "solver": info}
    if extra is not None:  # here, in the set's process: the solver's arrays never travel back
        record["extra"] = extra(bench_set=bench_set, meshes=meshes, predicted=predicted)
    return {**record, "peak_rss_mb": _peak_rss_mb()}


def _peak_rss_mb() -> float | None:
    """The most resident memory this process has held, MB (Linux, macOS)."""
    try:
        import resource
        import sys

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return round(peak / (2**20 if sys.platform == "darwin" else 2**10), 1)
    except (ImportError, OSError):
        return None


def _child(conn, fn, kwargs) -> None:
    import threading

    from tqdm import tqdm

    from .allocator import retain_freed_memory

    retain_freed_memory()  # as `reassemble run` does
    # tqdm's default lock is a named POSIX semaphore, registered with multiprocessing's resource
    # tracker; a child killed at its timeout never unlinks it, and the tracker warns of a "leaked
    # semaphore" when the run ends. No other process draws this one's bars: a thread lock will do.
    tqdm.set_lock(threading.RLock())
    try:
        conn.send(("ok", fn(**kwargs)))
    except BaseException as exc:  # noqa: BLE001 - everything goes back to the parent as text
        conn.send(("error", _error_text(exc)))
    finally:
        conn.close()


def _error_text(exc: BaseException) -> str:
    msg = first_line(exc)
    if isinstance(exc, ReassembleError):
        return msg
    where = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
    at = f" (at {Path(where[0].filename).name}:{where[0].lineno})" if where else ""
    return f"{type(exc).__name__}: {msg}{at}"


def _worker_memory_limit() -> float | None:
    try:
        from distributed import get_worker

        limit = get_worker().memory_manager.memory_limit
        return float(limit) if limit else None
    except (ImportError, ValueError, AttributeError):
        return None


# imported once by the fork server, not again by every set's process: reading a mesh the first
# time imports the mesh libraries (measured 0.8 s of a 0.9 s read of a 2-piece set)
PRELOAD = ["reassemble.pipeline", "reassemble.bench", "reassemble.inputs", "trimesh", "igl", "manifold3d", "open3d",
           "scipy.ndimage", "scipy.optimize", "scipy.sparse", "scipy.fft"]


def _in_child(fn, kwargs: dict, *, timeout: float | None, memory_limit: float | None) -> dict:
    """``fn(**kwargs)`` in a process forked from a preloaded fork server; killed past
    ``timeout`` seconds or ``memory_limit`` bytes of resident memory."""
    import multiprocessing

    import psutil

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, kwargs), daemon=True)
    proc.start()
    send.close()
    deadline = None if not timeout else time.monotonic() + timeout
    try:
        watched = psutil.Process(proc.pid)
        while not receive.poll(0.2):
            if deadline is not None and time.monotonic() > deadline:
                raise _Stopped(f"timeout ({timeout:g} s)")
            if memory_limit is not None:
                try:
                    rss = watched.memory_info().rss
                except psutil.NoSuchProcess:
                    continue
                if rss > memory_limit:
                    raise _Stopped(f"memory limit ({rss / 2**30:.1f} GiB > {memory_limit / 2**30:.1f} GiB)")
        try:
            status, value = receive.recv()
        except EOFError:
            proc.join(5)
            raise _Stopped(f"crashed (the solving process ended with exit code {proc.exitcode})") from None
        # let it end by itself: killed now, while it runs its exit handlers, it would leave what
        # they release (semaphores, temporary files) to the resource tracker, which warns of leaks
        proc.join(5)
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join(5)
        receive.close()
    if status == "error":
        raise _Stopped(value)
    return value


class _Stopped(Exception):
    """A set that did not finish: its one-line reason."""


def run_set(bench_set: BenchSet, *, config, n_points: int = 1000, timeout: float | None = None,
            solver=None, extra=None, isolate: bool = True) -> dict:
    """The task of one set: pose, solve, score; never raises.

    Parameters
    ----------
    bench_set : the set
    config : Config of the solve (``config.seed`` seeds the poses, with the set's id)
    n_points : surface points per piece for scoring
    timeout : seconds allowed for the set (None or 0: no limit)
    solver : ``solver(meshes, *, config) -> (predicted, info)`` as :func:`pipeline_solver`
        (a module-level function: it is pickled to the workers); default that one
    extra : ``extra(*, bench_set, meshes, predicted) -> dict``, more scores of a solved set,
        computed in the set's process with the meshes as solved and the solver's
        ``predicted`` (e.g. its ``fracture`` labels); kept as the record's ``extra``. A
        module-level function too; None: none
    isolate : solve in a child process (killed at the timeout, or past the Dask worker's
        memory limit); False solves in this process (then a timeout cannot be enforced)

    Returns
    -------
    dict
        the line of ``results.jsonl`` without its key: set, kind, category, pieces,
        ``error`` (None, or one line: 'timeout (600 s)', the exception...), time and, when
        scored, ``metrics`` per alignment, per-piece rotation errors and timings.
    """
    import multiprocessing

    record = {"set": bench_set.id, "kind": bench_set.kind, "category": bench_set.category,
              "pieces": bench_set.pieces, "seed": set_seed(config.seed, bench_set.id), "error": None}
    kwargs = dict(bench_set=bench_set, config=config, n_points=n_points, solver=solver, extra=extra)
    t0 = time.perf_counter()
    try:
        if isolate and not multiprocessing.current_process().daemon:
            record.update(_in_child(_solve_and_score, kwargs, timeout=timeout, memory_limit=_worker_memory_limit()))
        else:
            record.update(_solve_and_score(**kwargs))
    except _Stopped as exc:
        record["error"] = str(exc)
    except Exception as exc:  # noqa: BLE001 - a bad set is a result, not the end of the run
        record["error"] = _error_text(exc)
    record["time_s"] = round(time.perf_counter() - t0, 3)
    if record["error"] is None and timeout and record["time_s"] > timeout:
        record["error"] = f"timeout ({timeout:g} s)"  # not isolated: only noticed afterwards
    return record


def read_results(path: str | Path, *, key: str) -> dict[str, dict]:
    """The records of ``results.jsonl`` with ``key``, by set id (the last line of a set wins);
    a line cut short by a killed run is ignored."""
    out = {}
    path = Path(path)
    if not path.is_file():
        return out
    with open(path) as fh:
        for line in fh:
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if isinstance(rec, dict) and rec.get("key") == key and "set" in rec:
                out[rec["set"]] = rec
    return out


def _pieces_bin(n: int) -> str:
    for lo, hi in BINS:
        if lo <= n <= hi:
            return f"{lo}-{hi}"
    return f">{BINS[-1][1]}" if n > BINS[-1][1] else f"<{BINS[0][0]}"


def _group(records: list[dict]) -> dict:
    ok = [r for r in records if r.get("error") is None]
    n = len(records)
    times = [r["time_s"] for r in records if r.get("time_s") is not None]

    def share(mode, key):  # failed sets count as 0
        return sum(float(r["metrics"][mode][key]) for r in ok) / n if n else None

    def mean(mode, key):
        return float(np.mean([r["metrics"][mode][key] for r in ok])) if ok else None

    return {
        "sets": n, "failed": n - len(ok), "pieces": int(sum(r["pieces"] for r in records)),
        "part_acc": share(PRIMARY, "part_acc"), "rot_rmse_euler_deg": mean(PRIMARY, "rot_rmse_euler_deg"),
        "trans_rmse": mean(PRIMARY, "trans_rmse"), "shape_cd": mean(PRIMARY, "shape_cd"),
        "part_acc_strict": share(PRIMARY, "part_acc_strict"),
        "rot_geodesic_rmse_deg": mean(PRIMARY, "rot_geodesic_rmse_deg"),
        "solved": share(PRIMARY, "solved"),
        "part_acc_anchor_free": share(ANCHOR_FREE, "part_acc"),
        "part_acc_strict_anchor_free": share(ANCHOR_FREE, "part_acc_strict"),
        "time_s": float(np.mean(times)) if times else None,
    }


def summarize(records: list[dict]) -> dict:
    """The tables of a run: overall, by piece-count bin, by category (when the tree has
    categories), by piece count; the errors; the metric choices (:data:`CHOICES`)."""
    by_bin: dict[str, list] = {}
    for r in records:
        by_bin.setdefault(_pieces_bin(r["pieces"]), []).append(r)
    order = [f"{lo}-{hi}" for lo, hi in BINS]
    bins = {b: _group(by_bin[b]) for b in sorted(by_bin, key=lambda b: (order.index(b) if b in order else 99, b))}
    cats: dict[str, list] = {}
    for r in records:
        if r.get("category"):
            cats.setdefault(r["category"], []).append(r)
    counts: dict[int, list] = {}
    for r in records:
        counts.setdefault(r["pieces"], []).append(r)
    errors: dict[str, int] = {}
    for r in records:
        if r.get("error"):
            kind = r["error"].split(" (")[0]
            errors[kind] = errors.get(kind, 0) + 1
    rot = np.concatenate([r.get("rotation_errors_deg", []) for r in records]) if records else np.zeros(0)
    hist, _ = np.histogram(np.clip(rot, 0, 180), bins=ROTATION_EDGES)
    return {"format": RESULTS_FORMAT, "version": __version__, "metrics": CHOICES, "overall": _group(records),
            "by_pieces_bin": bins, "by_category": {c: _group(cats[c]) for c in sorted(cats)},
            "by_pieces": {str(n): _group(counts[n]) for n in sorted(counts)},
            "rotation_histogram": {"edges_deg": list(ROTATION_EDGES), "counts": hist.tolist()},
            "errors": errors}


COLUMNS = (("sets", "sets", "d"), ("failed", "failed", "d"), ("PA", "part_acc", ".3f"),
           ("RMSE(R) deg", "rot_rmse_euler_deg", ".2f"), ("RMSE(T)", "trans_rmse", ".4f"),
           ("CD", "shape_cd", ".2e"), ("strict PA", "part_acc_strict", ".3f"),
           ("geodesic RMSE deg", "rot_geodesic_rmse_deg", ".2f"), ("solved", "solved", ".3f"),
           ("PA anchor-free", "part_acc_anchor_free", ".3f"),
           ("strict PA anchor-free", "part_acc_strict_anchor_free", ".3f"), ("time s", "time_s", ".1f"))


def _table(rows: dict[str, dict], first: str) -> list[str]:
    lines = ["| " + " | ".join([first] + [c[0] for c in COLUMNS]) + " |",
             "|" + "---|" * (len(COLUMNS) + 1)]
    for label, g in rows.items():
        cells = ["-" if g[key] is None else format(g[key], fmt) for _, key, fmt in COLUMNS]
        lines.append("| " + " | ".join([label] + cells) + " |")
    return lines


def summary_markdown(summary: dict, *, title: str = "reassemble bench") -> str:
    """``summary.md``: the table a paper prints, and how it was scored."""
    lines = [f"# {title}", "", f"reassemble {summary['version']}. {summary['metrics']}", ""]
    lines += _table({"all": summary["overall"], **{f"{b} pieces": g for b, g in summary["by_pieces_bin"].items()}},
                    "")
    if summary["by_category"]:
        lines += ["", "## By category", ""] + _table(summary["by_category"], "category")
    if summary["errors"]:
        lines += ["", "## Failed sets", ""] + [f"- {k}: {v}" for k, v in sorted(summary["errors"].items())]
    return "\n".join(lines) + "\n"


def _chart(title: str, labels: list[str], series: list[tuple[str, list[float], tuple]], *, ymax: float,
           ylabel: str, xlabel: str, size=(720, 440)):
    """A bar chart as a Pillow image: one group of bars per label, one bar per series."""
    from PIL import Image, ImageDraw

    from .viz.render import _font  # noqa: PLC2701 - the font the pictures use

    w, h = size
    img = Image.new("RGB", size, "white")
    d = ImageDraw.Draw(img)
    font = _font(14)
    left, right, top, bottom = 60, 20, 50, 70
    d.text((left, 8), title, fill="black", font=font)
    d.text((5, 28), ylabel, fill="gray", font=font)
    d.text((w - right - 8 * len(xlabel), h - bottom + 24), xlabel, fill="gray", font=font)
    d.line([(left, top), (left, h - bottom), (w - right, h - bottom)], fill="black")
    for k in range(5):
        y = h - bottom - (h - bottom - top) * k / 4
        d.line([(left - 4, y), (left, y)], fill="black")
        d.text((5, y - 7), f"{ymax * k / 4:.3g}", fill="black", font=font)
    slot = (w - left - right) / max(1, len(labels))
    bar = slot * 0.8 / max(1, len(series))
    for i, label in enumerate(labels):
        x0 = left + i * slot + slot * 0.1
        for j, (_, values, color) in enumerate(series):
            v = values[i]
            if v is None:  # no figure: no bar
                continue
            y = h - bottom - (h - bottom - top) * min(v, ymax) / ymax
            d.rectangle([x0 + j * bar, y, x0 + (j + 1) * bar - 1, h - bottom], fill=color)
        d.text((x0, h - bottom + 5), label, fill="black", font=font)
    x = left + 10
    for name, _, color in series:
        d.rectangle([x, h - 20, x + 12, h - 8], fill=color)
        d.text((x + 16, h - 22), name, fill="black", font=font)
        x += 20 + 9 * len(name)
    return img


def plots(summary: dict) -> dict:
    """``pa_by_pieces.png`` (part accuracies by piece count) and ``rotation_errors.png``
    (histogram of the per-piece geodesic rotation errors), as Pillow images by file name."""
    counts = summary["by_pieces"]
    labels = list(counts)
    pa = _chart("Part accuracy by number of pieces", labels,
                [("Breaking Bad PA", [counts[n]["part_acc"] for n in labels], (70, 110, 200)),
                 ("strict PA", [counts[n]["part_acc_strict"] for n in labels], (230, 140, 40))],
                ymax=1.0, ylabel="share of pieces", xlabel="pieces in the set")
    hist = summary["rotation_histogram"]
    edges = hist["edges_deg"]
    bins = [f"{edges[k]:g}-{edges[k + 1]:g}" for k in range(len(edges) - 1)]
    top = max(hist["counts"] + [1])
    rot = _chart("Rotation error per piece (geodesic, degrees, largest piece anchored)", bins,
                 [("pieces", [float(c) for c in hist["counts"]], (70, 110, 200))], ymax=float(top),
                 ylabel="pieces", xlabel="degrees")
    return {"pa_by_pieces.png": pa, "rotation_errors.png": rot}


def _append(fh, record: dict) -> None:
    fh.write(json.dumps(record, default=_plain) + "\n")
    fh.flush()


def _plain(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON serializable: {type(x).__name__}")


def _cluster(*, jobs: int, scheduler: str | None, memory_limit):
    """A Dask client: of the cluster at ``scheduler``, or of a new ``LocalCluster`` with
    ``jobs`` single-threaded worker processes (non-daemonic, so that they may fork the
    processes that solve; a task that kills its worker is tried once more, then failed)."""
    import dask
    from distributed import Client, LocalCluster

    if not log.isEnabledFor(logging.INFO):  # the scheduler of a local cluster logs in this process
        logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler:
        from .parallel import connect

        return connect(scheduler), None
    # the scheduler serves HTTP even without its dashboard, on 8787 by default: a port another cluster
    # on the machine may hold (then Dask warns and takes another); ":0" takes a free one at once
    with dask.config.set({"distributed.worker.daemon": False, "distributed.scheduler.allowed-failures": 1,
                          "distributed.worker.memory.target": False, "distributed.worker.memory.spill": False}):
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                               dashboard_address=":0", scheduler_kwargs={"dashboard": False},
                               silence_logs=logging.ERROR)
        return Client(cluster), cluster


def bench(dataset: str | Path, out: str | Path, *, config, pieces: tuple[int, int] = (2, 20), limit: int | None = None,
          timeout: float | None = 600.0, jobs: int = 1, scheduler: str | None = None, memory_limit="auto",
          n_points: int = 1000, solver=None, extra=None, only=None, progress: bool = False) -> dict:
    """Solve and score every selected set of ``dataset``; write ``out/results.jsonl``,
    ``summary.json``, ``summary.md`` and the plots.

    Parameters
    ----------
    dataset : folder tree of sets (:func:`discover`)
    out : output folder (created; an existing ``results.jsonl`` is resumed)
    config : Config of every solve (``config.seed`` seeds the poses and the sample)
    pieces, limit : :func:`select`
    timeout : seconds per set (None or 0: none)
    jobs : worker processes of the local cluster (one thread each)
    scheduler : address of an existing Dask scheduler instead (``tcp://host:8786``)
    memory_limit : per local worker, bytes or Dask's 'auto' (the RAM shared by the workers)
    n_points : surface points per piece for scoring
    solver, extra : see :func:`run_set`
    only : if given, the ids of the sets to consider (before ``pieces`` and ``limit``)
    progress : a progress bar with an ETA on stderr

    Returns
    -------
    dict
        the summary, with ``ran`` (sets solved now) and ``skipped`` (found in results.jsonl).
    """
    from tqdm import tqdm

    sets = [s for s in discover(dataset) if only is None or s.id in only]
    sets = select(sets, pieces=pieces, limit=limit, seed=config.seed)
    if not sets:
        raise ReassembleError(f"{dataset}: no fracture sets of {pieces[0]}-{pieces[1]} pieces (a set is a folder "
                              f"with two or more mesh files, or a puzzle with a ground_truth.json)")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results = out / "results.jsonl"
    key = options_key(config, n_points=n_points, solver=solver, extra=extra)
    done = read_results(results, key=key)

    def again(rec):  # a set lost by the cluster, or over a shorter limit than this run's, is worth another try
        err = rec.get("error") or ""
        return rec.get("lost", False) or (err.startswith("timeout") and (not timeout or rec.get("timeout", 0) < timeout))

    todo = [s for s in sets if s.id not in done or again(done[s.id])]
    todo.sort(key=lambda s: -s.pieces)  # the biggest first: no worker left alone with one at the end
    log.info("%d sets, %d already in %s, %d to run", len(sets), len(sets) - len(todo), results, len(todo))
    if todo:
        client, cluster = _cluster(jobs=jobs, scheduler=scheduler, memory_limit=memory_limit)
        try:
            with open(results, "a") as fh, tqdm(total=len(todo), unit="set", disable=not progress,
                                                 desc="bench") as bar:
                for rec in _solved(client, todo, key=key, config=config, n_points=n_points, timeout=timeout,
                                   solver=solver, extra=extra):
                    _append(fh, rec)
                    done[rec["set"]] = rec
                    bar.update()
                    if rec["error"]:
                        bar.write(f"{rec['set']}: {rec['error']}")
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    summary = summarize([done[s.id] for s in sets if s.id in done])
    summary.update(dataset=str(dataset), key=key, ran=len(todo), skipped=len(sets) - len(todo),
                   options={"pieces": list(pieces), "limit": limit, "timeout": timeout or 0, "n_points": n_points,
                            "seed": config.seed})
    _write_summary(out, summary)
    return summary


def _solved(client, todo: list[BenchSet], *, key: str, config, n_points: int, timeout, solver, extra):
    """Each set's results line as its task finishes (in any order); a set the cluster lost
    is a line too, marked ``lost`` (a rerun tries it again)."""
    from distributed import as_completed

    futures = {client.submit(run_set, s, config=config, n_points=n_points, timeout=timeout, solver=solver,
                             extra=extra, pure=False, retries=1, key=f"bench-{key}-{k}"): s
               for k, s in enumerate(todo)}
    for future in as_completed(futures):
        s = futures[future]
        try:
            rec = future.result()
        except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker (a worker died twice): the run goes on
            rec = {"set": s.id, "kind": s.kind, "category": s.category, "pieces": s.pieces,
                   "seed": set_seed(config.seed, s.id), "error": _error_text(exc), "time_s": None, "lost": True}
        yield {"key": key, **rec, "timeout": timeout or 0}


def _write_summary(out: Path, summary: dict) -> None:
    """``summary.json``, ``summary.md`` and the plots, each written aside and moved into place."""
    from .files import write_json

    write_json(out / "summary.json", summary)
    (out / "summary.md.tmp").write_text(summary_markdown(summary))
    (out / "summary.md.tmp").replace(out / "summary.md")
    for name, img in plots(summary).items():
        img.save(out / f"{name}.tmp", format="PNG")
        (out / f"{name}.tmp").replace(out / name)
