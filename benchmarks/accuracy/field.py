"""`reassemble run` (defaults) on the field sets, per fracture style and mesh kind, validation first.

The validation half first, the tuning half beside it.

    python -m benchmarks.accuracy.field --sets puzzles --shared ../shared --jobs 1
    python -m benchmarks.accuracy.field --sets puzzles --halves validation --max-pieces 4 --clean-only --resume
    python -m benchmarks.accuracy.field --report          # the tables of benchmarks/results/field.json

The sets (``data_synth.sets``: field-validation, field-tuning; split by mesh) live in
``SETS/field-validation`` and ``SETS/field-tuning``; the selected puzzles not there yet are
built first (``python -m data_synth.make_sets`` builds a whole set). Each half runs through
``reassemble bench`` (:func:`reassemble.bench.bench`: each puzzle a task on a Dask
LocalCluster of ``--jobs`` workers, solved in a child process by ``run``'s pipeline with its
defaults, ``--timeout`` per puzzle, ``--results DIR`` keeps bench's resumable
``results.jsonl``) and is scored as ``reassemble eval`` does, anchored on the largest placed
fragment: strict part accuracy (mean chamfer under 1 % of the diagonal) and solved (every
fragment strict-correct). The segmentation F1 is area-weighted over the puzzle's faces, the
run's own fracture labels (``fracture_k`` of its ``analysis.npz``: after the assembly)
against the generator's exact ones, computed in the puzzle's process by bench's ``extra``
hook (:func:`segmentation_scores`); "F1 segmented" scores the segmentation's labels the
run matched with (``segmented_k``), before the assembly. Time per fragment: wall-clock of
reading and solving (not of scoring) and the CPU time of solving, over the puzzle's
fragments. ``--baseline`` also runs
Open3D's textbook FPFH + RANSAC + ICP (``reassemble.baseline``, its own pool of processes,
not bench: it is not ``run``'s pipeline) on the puzzles of at most ``--baseline-max-pieces``.
Figures go to ``benchmarks/results/field.json`` (a benchmark record,
:mod:`benchmarks.common`: rewritten after each half; ``--resume`` skips puzzles already in
it; every puzzle's row names the commit it ran at).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import add_setting_option, fpfh_baseline, machine_line, match_config, start, table

REPO = Path(__file__).resolve().parents[2]
ALIGN = "anchor_largest"
HALVES = {"validation": "field-validation", "tuning": "field-tuning"}


def style_label(spec) -> str:
    return spec.style if spec.roughness is None else f"{spec.style} r{spec.roughness:g}"


def segmentation_f1(meshes: dict, predicted: dict, puzzle) -> dict:
    """Area-weighted precision, recall and F1 of a run's fracture labels over a puzzle.

    Parameters
    ----------
    meshes : name -> (vertices, faces), the fragments as the run read them (``load_fragments``)
    predicted : name -> (faces,) bool, the run's fracture labels (fragments missing here are
        left out)
    puzzle : :class:`reassemble.puzzle.PuzzleFiles` read with its labels

    Where the loader changed a fragment's faces, the true labels are carried over by nearest
    face centre.
    """
    from scipy.spatial import cKDTree

    from reassemble.geometry import face_areas

    truth, pred, area = [], [], []
    for name, (v, f) in meshes.items():
        if name not in predicted:
            continue
        base = name.split(".")[0]  # 'stem.2': the second body of a file split in bodies
        gt_mesh, gt_lab = puzzle.meshes[base], puzzle.labels[base]
        if len(gt_mesh.faces) == len(f) and np.allclose(gt_mesh.vertices[gt_mesh.faces].mean(axis=1),
                                                        v[f].mean(axis=1)):
            lab = gt_lab
        else:
            tree = cKDTree(gt_mesh.vertices[gt_mesh.faces].mean(axis=1))
            lab = gt_lab[tree.query(v[f].mean(axis=1))[1]]
        truth.append(lab == 1)
        pred.append(np.asarray(predicted[name], bool))
        area.append(face_areas(v, f))
    if not truth:
        raise ValueError("no fracture labels from the solver to score")
    t, p, a = np.concatenate(truth), np.concatenate(pred), np.concatenate(area)
    tp = float(a[t & p].sum())
    precision = tp / max(float(a[p].sum()), 1e-300)
    recall = tp / max(float(a[t].sum()), 1e-300)
    return {"precision": precision, "recall": recall,
            "f1": 2 * precision * recall / max(precision + recall, 1e-300)}


def segmentation_scores(*, bench_set, meshes: dict, predicted: dict) -> dict:
    """Bench's ``extra`` hook: the solved puzzle's :func:`segmentation_f1` (in its own process)."""
    from reassemble.puzzle import read_puzzle

    puzzle = read_puzzle(Path(bench_set.path) / "ground_truth.json")
    out = segmentation_f1(meshes, {n: p["fracture"] for n, p in predicted.items() if "fracture" in p}, puzzle)
    segmented = {n: p["segmented"] for n, p in predicted.items() if "segmented" in p}
    if segmented:  # the segmentation's own labels, before the assembly refined them
        out["segmented_f1"] = segmentation_f1(meshes, segmented, puzzle)["f1"]
    return out


def field_solver(meshes: dict, *, config) -> tuple[dict, dict]:
    """Bench's solver (``run``'s pipeline, :func:`reassemble.bench.pipeline_solver`), with the
    CPU seconds of the solve in its info (bench records wall-clock only)."""
    from reassemble.bench import pipeline_solver

    cpu = time.process_time()
    predicted, info = pipeline_solver(meshes, config=config)
    return predicted, {**info, "cpu_s": round(time.process_time() - cpu, 3)}


def row(rec: dict) -> dict:
    """A puzzle's line of bench's ``results.jsonl`` as this benchmark's row."""
    if rec["error"]:
        # a failure is a figure too: the puzzle counts as unsolved. Its process's CPU time is not
        # known (it may have been killed): the wall-clock of its single-threaded solve stands in
        spent = float(rec.get("time_s") or 0.0)
        return {"name": rec["set"], "error": rec["error"], "fragments": rec["pieces"], "time": spent, "cpu": spent,
                "part_acc_strict": 0.0, "solved": False, "f1": 0.0, "precision": 0.0, "recall": 0.0, "placed": 0,
                "segmented_f1": 0.0}
    s, t = rec["metrics"][ALIGN], rec["timings_s"]
    return {"name": rec["set"], "time": t["load"] + t["solve"], "cpu": rec["solver"]["cpu_s"],
            "fragments": rec["pieces"], "placed": rec["placed"], "part_acc_strict": s["part_acc_strict"],
            "solved": bool(s["solved"]), "rot_rmse_deg": s["rot_geodesic_rmse_deg"], **rec["extra"]}


def _baseline(gt_path: Path, seed: int) -> dict:
    score, elapsed = fpfh_baseline(gt_path, seed=seed)
    s = score["alignments"][ALIGN]["summary"]
    return {"part_acc_strict": s["part_acc_strict"], "solved": bool(s["solved"]), "time": elapsed}


def _group(rows: list[dict]) -> dict:
    """Means over puzzles: F1, strict part accuracy, solved share, time per fragment."""
    if not rows:
        return {"puzzles": 0}
    frags = sum(r["fragments"] for r in rows)
    g = {"puzzles": len(rows), "fragments": frags,
         "f1": float(np.mean([r["f1"] for r in rows])),
         "segmented_f1": (float(np.mean([r["segmented_f1"] for r in rows]))
                          if all("segmented_f1" in r for r in rows) else None),
         "part_acc_strict": float(np.mean([r["part_acc_strict"] for r in rows])),
         "solved": float(np.mean([r["solved"] for r in rows])),
         "s_per_fragment": float(sum(r["time"] for r in rows) / frags),
         "cpu_s_per_fragment": float(sum(r["cpu"] for r in rows) / frags),
         "errors": sum("error" in r for r in rows)}
    base = [r["baseline"] for r in rows if "baseline" in r]
    if base:
        g["baseline"] = {"puzzles": len(base), "part_acc_strict": float(np.mean([b["part_acc_strict"] for b in base])),
                         "solved": float(np.mean([b["solved"] for b in base])),
                         "ours_part_acc_strict_same_puzzles": float(np.mean(
                             [r["part_acc_strict"] for r in rows if "baseline" in r]))}
    return g


def figures(rows: list[dict]) -> dict:
    """Groups by style, by kind and by style x kind, each clean and noisy apart."""
    out: dict = {}
    for noise in ("clean", "noisy"):
        sel = [r for r in rows if (r["noise"] > 0) == (noise == "noisy")]
        out[noise] = {
            "all": _group(sel),
            "by_style": {s: _group([r for r in sel if r["style"] == s]) for s in sorted({r["style"] for r in sel})},
            "by_kind": {k: _group([r for r in sel if r["kind"] == k]) for k in sorted({r["kind"] for r in sel})},
            "by_style_kind": {f"{s} / {k}": _group([r for r in sel if r["style"] == s and r["kind"] == k])
                              for s in sorted({r["style"] for r in sel}) for k in sorted({r["kind"] for r in sel})
                              if any(r["style"] == s and r["kind"] == k for r in sel)},
        }
    return out


def _cell(g: dict | None) -> str:
    if not g or not g.get("puzzles"):
        return f"{'-':>33s}"
    return (f"{g['puzzles']:>3d} {g['f1']:>6.3f} {g['part_acc_strict']:>6.3f} {g['solved']:>6.2f} "
            f"{g['cpu_s_per_fragment']:>7.1f}")


def print_tables(figs: dict) -> None:
    cols = "  n     F1 strict solved cpu s/f"
    for noise in ("clean", "noisy"):
        for block in ("all", "by_style", "by_kind", "by_style_kind"):
            if not any(h.get(noise, {}).get("all", {}).get("puzzles") for h in figs.values()):
                continue
            keys = ["all"] if block == "all" else sorted({k for h in figs.values() for k in h.get(noise, {}).get(block, {})})
            print(f"\n{noise}, {block.replace('_', ' ')}:   VALIDATION {cols}   | tuning {cols}")
            for k in keys:
                cells = []
                for half in ("validation", "tuning"):
                    h = figs.get(half, {}).get(noise, {})
                    cells.append(_cell(h.get("all") if block == "all" else h.get(block, {}).get(k)))
                print(f"  {k:<36s} {cells[0]}   | {cells[1]}")
    for half, h in figs.items():
        for noise in ("clean", "noisy"):
            b = h.get(noise, {}).get("all", {}).get("baseline")
            if b:
                print(f"\nbaseline (Open3D FPFH + RANSAC + ICP), {half} {noise}, {b['puzzles']} puzzles: strict "
                      f"{b['part_acc_strict']:.3f}, solved {b['solved']:.2f} (ours on the same: "
                      f"{b['ours_part_acc_strict_same_puzzles']:.3f})")


def tables(figs: dict) -> list[dict]:
    """The record's tables: per noise level, by style and by mesh kind, validation first."""
    cols = ["n", "F1", "F1 segmented", "strict", "solved", "cpu s/fragment"]
    out = []
    for noise in ("clean", "noisy"):
        for block in ("all", "by_style", "by_kind"):
            halves = [h for h in ("validation", "tuning") if figs.get(h, {}).get(noise, {}).get("all", {}).get("puzzles")]
            if not halves:
                continue
            keys = ["all"] if block == "all" else sorted(
                {k for h in halves for k in figs[h][noise].get(block, {})})
            rows = []
            for k in keys:
                row = [k]
                for h in halves:
                    g = figs[h][noise]["all"] if block == "all" else figs[h][noise][block].get(k)
                    row += ([g["puzzles"], g["f1"], g.get("segmented_f1"), g["part_acc_strict"], g["solved"],
                             g["cpu_s_per_fragment"]] if g and g.get("puzzles") else [None] * 6)
                b = (figs[halves[0]][noise]["all"] if block == "all" else figs[halves[0]][noise][block].get(k) or {})
                row.append(b.get("baseline", {}).get("part_acc_strict"))
                rows.append(row)
            columns = ["group"] + [f"{h} {c}" for h in halves for c in cols] + [f"{halves[0]} FPFH strict"]
            formats = [""] + ["d", ".3f", ".3f", ".3f", ".2f", ".1f"] * len(halves) + [".3f"]
            title = f"Field set, {noise}, {'all puzzles' if block == 'all' else block.replace('_', ' ')}"
            out.append(table(title, columns, rows, formats))
    return out


def headline(figs: dict) -> list[tuple[str, str]]:
    g = figs.get("validation", {}).get("clean", {}).get("all", {})
    if not g.get("puzzles"):
        return []
    return [(f"field validation half, clean ({g['puzzles']} puzzles): segmentation F1 / strict part accuracy",
             f"{g['f1']:.2f} / {g['part_acc_strict']:.2f}")]


def _parser() -> argparse.ArgumentParser:
    from data_synth.make_sets import add_field_options

    parser = argparse.ArgumentParser(prog="python -m benchmarks.accuracy.field", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_field_options(parser)
    parser.add_argument("--halves", default="validation,tuning", help="which halves, in this order")
    parser.add_argument("--styles", default=None, help="comma-separated styles (e.g. cells,'fractal r0.01')")
    parser.add_argument("--kinds", default=None, help="comma-separated mesh kinds")
    parser.add_argument("--meshes", default=None, help="comma-separated meshes")
    parser.add_argument("--max-pieces", type=int, default=20)
    parser.add_argument("--clean-only", action="store_true")
    parser.add_argument("--noisy-only", action="store_true")
    parser.add_argument("--baseline", action="store_true", help="also the Open3D textbook pipeline")
    parser.add_argument("--baseline-max-pieces", type=int, default=8)
    parser.add_argument("--jobs", type=int, default=1, help="puzzles run at once (bench's workers; each run uses "
                        "one process)")
    parser.add_argument("--timeout", type=float, default=0, help="seconds per puzzle, then it counts as failed "
                        "(default 0: none)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seed-shift", type=int, default=0, metavar="S",
                        help="break every selected puzzle again with its seed + S: new cuts of the same meshes, "
                             "styles and piece counts (more puzzles to study a half on; they are built beside "
                             "the set's own)")
    add_setting_option(parser)
    parser.add_argument("--results", type=Path, default=None, metavar="DIR",
                        help="keep reassemble bench's results here, DIR/<half>/results.jsonl (a rerun with the "
                        "same options resumes; default a temporary folder)")
    parser.add_argument("--json", "--out", dest="out", type=Path,
                        default=REPO / "benchmarks" / "results" / "accuracy.field.json",
                        help="the record (default benchmarks/results/accuracy.field.json)")
    parser.add_argument("--resume", action="store_true", help="keep the puzzles already in --out")
    parser.add_argument("--report", action="store_true", help="only print the tables of --out, run nothing")
    return parser


def selected(args, halves: list[str]) -> tuple[list[tuple], list[dict]]:
    """The (half, spec, ground truth path) the options select, the missing ones built first;
    and the puzzles that could not be built."""
    from data_synth.make_sets import build_specs
    from data_synth.sets import FIELD_MESHES, SETS

    todo = []
    for half in halves:
        root = args.sets / HALVES[half]
        for spec in SETS[HALVES[half]]():
            spec = dataclasses.replace(spec, seed=spec.seed + args.seed_shift)
            kind = FIELD_MESHES[spec.mesh].kind
            if (spec.pieces > args.max_pieces or (args.clean_only and spec.noise) or (args.noisy_only and not spec.noise)
                    or (args.styles and style_label(spec) not in args.styles.split(","))
                    or (args.kinds and kind not in args.kinds.split(","))
                    or (args.meshes and spec.mesh not in args.meshes.split(","))):
                continue
            todo.append((half, spec, root / spec.name / "ground_truth.json"))
    not_generated: list[dict] = []
    for half in halves:  # the selected puzzles not built yet
        missing = [s for h, s, gt in todo if h == half and not gt.is_file()]
        if missing:
            print(f"building {len(missing)} puzzles of {HALVES[half]} in {args.sets / HALVES[half]} ...", flush=True)
            built = build_specs(missing, args.sets / HALVES[half], set_name=HALVES[half], jobs=max(1, args.jobs),
                                shared=args.shared, keep_going=True)
            for b in built:
                if "error" in b:
                    print(f"  not generated: {b['error']}", flush=True)
                    not_generated.append({"half": half, "name": b["name"], "error": b["error"]})
    return [t for t in todo if t[2].is_file()], not_generated


def run_half(root: Path, specs: list, *, config, args, results: Path) -> list[dict]:
    """The puzzles ``specs`` of one half through ``reassemble bench``, as this benchmark's rows
    (in the order of ``specs``), with the baseline's figures where asked."""
    from reassemble.bench import bench, options_key, read_results

    # this module's functions by its import name, not __main__'s (python -m): the set's process
    # unpickles them by name, and a __main__ there is not this module
    from benchmarks.accuracy import field

    hooks = {"solver": field.field_solver, "extra": field.segmentation_scores}
    bench(root, results, config=config, pieces=(2, 10**6), timeout=args.timeout or None, jobs=args.jobs,
          only={s.name for s in specs}, progress=True, **hooks)
    records = read_results(results / "results.jsonl", key=options_key(config, n_points=1000, **hooks))
    rows = [row(records[s.name]) for s in specs]
    todo = [k for k, s in enumerate(specs) if args.baseline and s.pieces <= args.baseline_max_pieces]
    if todo:
        with ProcessPoolExecutor(args.jobs) as pool:
            gts = [root / specs[k].name / "ground_truth.json" for k in todo]
            for k, b in zip(todo, pool.map(_baseline, gts, [args.seed] * len(todo))):
                rows[k]["baseline"] = b
    return rows


def _print_row(r: dict) -> None:
    base = f"  {r['baseline']['part_acc_strict']:>11.3f}" if "baseline" in r else ""
    err = f"  ERROR {r['error']}" if "error" in r else ""
    print(f"{r['half']:<10s} {r['name']:<44s} {r['fragments']:>5d} {r['placed']:>6d} {r['f1']:>6.3f} "
          f"{r['part_acc_strict']:>6.3f} {str(r['solved']):>6s} {r['time']:>7.1f} {r['cpu']:>7.1f}{base}{err}",
          flush=True)


def main(argv: list[str] | None = None) -> int:
    from data_synth.sets import FIELD_MESHES

    args = _parser().parse_args(argv)
    if args.report:
        saved = json.loads(args.out.read_text())
        print(f"{args.out}: {machine_line(saved['machine'])}\ncommand: {saved['command']}\ncommit: {saved['commit']}; "
              f"{len(saved['figures']['puzzles'])} puzzles")
        print_tables(saved["figures"]["halves"])
        return 0
    record = start()
    commit = record.git["commit"] + ("+changes" if record.git["dirty"] else "") if record.git["commit"] else "unknown"
    halves = [h.strip() for h in args.halves.split(",") if h.strip()]
    if any(h not in HALVES for h in halves):
        print(f"field: error: --halves takes {', '.join(HALVES)}", file=sys.stderr)
        return 2
    todo, not_generated = selected(args, halves)
    done: dict[tuple[str, str], dict] = {}
    if args.resume and args.out.is_file():
        saved = json.loads(args.out.read_text())
        done = {(r["half"], r["name"]): r for r in saved["figures"].get("puzzles", [])}
    rows = [done[(h, s.name)] for h, s, _ in todo if (h, s.name) in done]
    todo = [t for t in todo if (t[0], t[1].name) not in done]
    todo.sort(key=lambda t: (halves.index(t[0]), t[1].pieces))  # validation first, small puzzles first
    print(f"{len(todo)} puzzles to run ({len(rows)} kept from {args.out}); commit {commit}")

    def save() -> dict:
        figs = {h: figures([r for r in rows if r["half"] == h]) for h in halves if any(r["half"] == h for r in rows)}
        record.write(args.out, figures={"halves": figs, "puzzles": rows, "not_generated": not_generated},
                     tables=tables(figs), headline=headline(figs))
        return figs

    t0 = time.perf_counter()
    config = dataclasses.replace(match_config(None, tuple(args.setting)), seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        for half in halves:
            specs = [s for h, s, _ in todo if h == half]
            if not specs:
                continue
            new = run_half(args.sets / HALVES[half], specs, config=config, args=args,
                           results=(args.results or Path(tmp)) / half)
            print(f"{'half':<10s} {'puzzle':<44s} {'frags':>5s} {'placed':>6s} {'F1':>6s} {'strict':>6s} "
                  f"{'solved':>6s} {'wall s':>7s} {'cpu s':>7s}" + ("  fpfh strict" if args.baseline else ""))
            for spec, r in zip(specs, new):
                r.update(half=half, commit=commit, settings=list(args.setting), mesh=spec.mesh,
                         kind=FIELD_MESHES[spec.mesh].kind, style=style_label(spec), pieces=spec.pieces,
                         noise=spec.noise)
                _print_row(r)
            rows.extend(new)
            save()
    figs = save()
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}; figures in {args.out}")
    print_tables(figs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
