"""`reassemble run` (defaults) on the field sets, per fracture style and mesh kind, validation first.

The validation half first, the tuning half beside it.

    python -m benchmarks.accuracy.field --sets puzzles --shared ../shared --jobs 1
    python -m benchmarks.accuracy.field --sets puzzles --halves validation --max-pieces 4 --clean-only --resume
    python -m benchmarks.accuracy.field --report          # the tables of benchmarks/results/field.json

The sets (``data_synth.sets``: field-validation, field-tuning; split by mesh) live in
``SETS/field-validation`` and ``SETS/field-tuning``; the selected puzzles not there yet are
built first (``python -m data_synth.make_sets`` builds a whole set). Per puzzle, in a
worker process, ``run_to_folder`` (the code behind ``reassemble run``) runs with its
defaults; its result is scored as ``reassemble eval`` does, anchored on the largest placed
fragment: strict part accuracy (mean chamfer under 1 % of the diagonal) and solved (every
fragment strict-correct). The segmentation F1 is area-weighted over the puzzle's faces,
the run's own fracture labels (its ``analysis.npz``) against the generator's exact ones.
Time per fragment: the run's wall-clock and CPU time over its fragments. ``--baseline``
also runs Open3D's textbook FPFH + RANSAC + ICP (``reassemble.baseline``) on the puzzles
of at most ``--baseline-max-pieces``. Figures go to ``benchmarks/results/field.json``
(a benchmark record, :mod:`benchmarks.common`: rewritten after every puzzle, so an
interrupted run keeps what it measured; ``--resume`` skips puzzles already in it; every
puzzle's row names the commit it ran at).
"""

from __future__ import annotations

import argparse
import json
import subprocess
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


def _segmentation_f1(frag_dir: Path, out: Path, puzzle) -> dict:
    """Area-weighted precision, recall and F1 of the run's fracture labels over the puzzle.

    The run's meshes are read as the run read them (``load_fragments``); where the loader
    changed a fragment's faces, the true labels are carried over by nearest face centre.
    """
    from scipy.spatial import cKDTree

    from reassemble.geometry import face_areas
    from reassemble.pipeline import load_fragments

    meshes, _ = load_fragments([frag_dir])
    with np.load(out / "analysis.npz") as z:
        names = [str(n) for n in z["names"]]
        predicted = {n: z[f"fracture_{k}"].astype(bool) for k, n in enumerate(names)}
    truth, pred, area = [], [], []
    for name, (v, f) in meshes.items():
        if name not in predicted:
            continue
        base = name.split(".")[0]
        gt_mesh, gt_lab = puzzle.meshes[base], puzzle.labels[base]
        if len(gt_mesh.faces) == len(f) and np.allclose(gt_mesh.vertices[gt_mesh.faces].mean(axis=1),
                                                        v[f].mean(axis=1)):
            lab = gt_lab
        else:
            tree = cKDTree(gt_mesh.vertices[gt_mesh.faces].mean(axis=1))
            lab = gt_lab[tree.query(v[f].mean(axis=1))[1]]
        truth.append(lab == 1)
        pred.append(predicted[name])
        area.append(face_areas(v, f))
    t, p, a = np.concatenate(truth), np.concatenate(pred), np.concatenate(area)
    tp = float(a[t & p].sum())
    precision = tp / max(float(a[p].sum()), 1e-300)
    recall = tp / max(float(a[t].sum()), 1e-300)
    return {"precision": precision, "recall": recall,
            "f1": 2 * precision * recall / max(precision + recall, 1e-300)}


def _baseline(gt_path: Path, seed: int) -> dict:
    score, elapsed = fpfh_baseline(gt_path, seed=seed)
    s = score["alignments"][ALIGN]["summary"]
    return {"part_acc_strict": s["part_acc_strict"], "solved": bool(s["solved"]), "time": elapsed}


def run_puzzle(gt_path: str, seed: int, baseline: bool, settings: tuple[str, ...] = ()) -> dict:
    from reassemble.pipeline import evaluate_files, read_puzzle, run_to_folder

    config = match_config(None, settings)

    gt_path = Path(gt_path)
    puzzle = read_puzzle(gt_path)
    out = {"name": gt_path.parent.name}
    with tempfile.TemporaryDirectory() as tmp:
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            report = run_to_folder([gt_path.parent / "fragments"], Path(tmp) / "out", config=config, seed=seed,
                                   jobs=1)
        except Exception as exc:  # a failure is a figure too: the puzzle counts as unsolved
            out.update(error=f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}",
                       fragments=len(puzzle.meshes), time=time.perf_counter() - wall,
                       cpu=time.process_time() - cpu, part_acc_strict=0.0, solved=False, f1=0.0,
                       precision=0.0, recall=0.0, placed=0)
            return out
        out["time"], out["cpu"] = time.perf_counter() - wall, time.process_time() - cpu
        score = evaluate_files(Path(tmp) / "out" / "transforms.json", gt_path)
        s = score["alignments"][ALIGN]["summary"]
        out.update(fragments=len(puzzle.meshes), placed=report["summary"]["placed"],
                   part_acc_strict=s["part_acc_strict"], solved=bool(s["solved"]),
                   rot_rmse_deg=s["rot_geodesic_rmse_deg"])
        out.update(_segmentation_f1(gt_path.parent / "fragments", Path(tmp) / "out", puzzle))
    if baseline:
        out["baseline"] = _baseline(gt_path, seed)
    return out


def _group(rows: list[dict]) -> dict:
    """Means over puzzles: F1, strict part accuracy, solved share, time per fragment."""
    if not rows:
        return {"puzzles": 0}
    frags = sum(r["fragments"] for r in rows)
    g = {"puzzles": len(rows), "fragments": frags,
         "f1": float(np.mean([r["f1"] for r in rows])),
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
    cols = ["n", "F1", "strict", "solved", "cpu s/fragment"]
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
                    row += ([g["puzzles"], g["f1"], g["part_acc_strict"], g["solved"], g["cpu_s_per_fragment"]]
                            if g and g.get("puzzles") else [None] * 5)
                b = (figs[halves[0]][noise]["all"] if block == "all" else figs[halves[0]][noise][block].get(k) or {})
                row.append(b.get("baseline", {}).get("part_acc_strict"))
                rows.append(row)
            columns = ["group"] + [f"{h} {c}" for h in halves for c in cols] + [f"{halves[0]} FPFH strict"]
            formats = [""] + ["d", ".3f", ".3f", ".2f", ".1f"] * len(halves) + [".3f"]
            title = f"Field set, {noise}, {'all puzzles' if block == 'all' else block.replace('_', ' ')}"
            out.append(table(title, columns, rows, formats))
    return out


def headline(figs: dict) -> list[tuple[str, str]]:
    g = figs.get("validation", {}).get("clean", {}).get("all", {})
    if not g.get("puzzles"):
        return []
    return [(f"field validation half, clean ({g['puzzles']} puzzles): segmentation F1 / strict part accuracy",
             f"{g['f1']:.2f} / {g['part_acc_strict']:.2f}")]


def main(argv: list[str] | None = None) -> int:
    import sys

    from data_synth.make_sets import add_field_options, build_specs
    from data_synth.sets import FIELD_MESHES, SETS

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
    parser.add_argument("--jobs", type=int, default=1, help="puzzles run at once (each run uses one process)")
    parser.add_argument("--seed", type=int, default=0)
    add_setting_option(parser)
    parser.add_argument("--json", "--out", dest="out", type=Path, default=REPO / "benchmarks" / "results" / "accuracy.field.json",
                        help="the record (default benchmarks/results/accuracy.field.json)")
    parser.add_argument("--resume", action="store_true", help="keep the puzzles already in --out")
    parser.add_argument("--report", action="store_true", help="only print the tables of --out, run nothing")
    args = parser.parse_args(argv)
    if args.report:
        saved = json.loads(args.out.read_text())
        print(f"{args.out}: {machine_line(saved['machine'])}\ncommand: {saved['command']}\ncommit: {saved['commit']}; "
              f"{len(saved['figures']['puzzles'])} puzzles")
        print_tables(saved["figures"]["halves"])
        return 0
    bench = start()
    commit = bench.git["commit"] + ("+changes" if bench.git["dirty"] else "") if bench.git["commit"] else "unknown"
    halves = [h.strip() for h in args.halves.split(",") if h.strip()]
    if any(h not in HALVES for h in halves):
        print(f"field: error: --halves takes {', '.join(HALVES)}", file=sys.stderr)
        return 2

    todo = []  # (half, spec, ground truth path)
    for half in halves:
        root = args.sets / HALVES[half]
        for spec in SETS[HALVES[half]]():
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
    todo = [t for t in todo if t[2].is_file()]

    done: dict[tuple[str, str], dict] = {}
    if args.resume and args.out.is_file():
        saved = json.loads(args.out.read_text())
        done = {(r["half"], r["name"]): r for r in saved["figures"].get("puzzles", [])}
    rows = [done[(h, s.name)] for h, s, _ in todo if (h, s.name) in done]
    todo = [t for t in todo if (t[0], t[1].name) not in done]
    todo.sort(key=lambda t: (halves.index(t[0]), t[1].pieces))  # validation first, small puzzles first
    print(f"{len(todo)} puzzles to run ({len(rows)} kept from {args.out}); commit {commit}")
    print(f"{'half':<10s} {'puzzle':<44s} {'frags':>5s} {'placed':>6s} {'F1':>6s} {'strict':>6s} {'solved':>6s} "
          f"{'wall s':>7s} {'cpu s':>7s}" + ("  fpfh strict" if args.baseline else ""))

    def save() -> dict:
        figs = {h: figures([r for r in rows if r["half"] == h]) for h in halves if any(r["half"] == h for r in rows)}
        bench.write(args.out, figures={"halves": figs, "puzzles": rows, "not_generated": not_generated},
                    tables=tables(figs), headline=headline(figs))
        return figs

    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, max_tasks_per_child=1) as pool:
        futures = [(half, spec, pool.submit(run_puzzle, str(gt), args.seed,
                                            args.baseline and spec.pieces <= args.baseline_max_pieces, tuple(args.setting)))
                   for half, spec, gt in todo]
        for half, spec, fut in futures:
            r = fut.result()
            r.update(half=half, commit=commit, settings=list(args.setting), mesh=spec.mesh, kind=FIELD_MESHES[spec.mesh].kind, style=style_label(spec),
                     pieces=spec.pieces, noise=spec.noise)
            rows.append(r)
            base = f"  {r['baseline']['part_acc_strict']:>11.3f}" if "baseline" in r else ""
            err = f"  ERROR {r['error']}" if "error" in r else ""
            print(f"{half:<10s} {r['name']:<44s} {r['fragments']:>5d} {r['placed']:>6d} {r['f1']:>6.3f} "
                  f"{r['part_acc_strict']:>6.3f} {str(r['solved']):>6s} {r['time']:>7.1f} {r['cpu']:>7.1f}{base}{err}",
                  flush=True)
            save()
    figs = save()
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}; figures in {args.out}")
    print_tables(figs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
