"""Command line: parsing only. Heavy libraries are imported inside the commands.

The defaults of the options are those of :class:`config.Config` (and of the functions the
commands call), shown in the help; an option given sets one value of the command's Config.
"""

from __future__ import annotations

import argparse
import inspect
import json
import logging
import sys
from pathlib import Path

from . import __version__
from .errors import ReassembleError, first_line

log = logging.getLogger("reassemble")


def _int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low} (got {value})")
        return value

    return parse


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def _cmd_break(args: argparse.Namespace) -> int:
    from .config import Config
    from .puzzle import break_to_folder
    from .synth import BreakParams

    config = _config(args, base=Config(break_=BreakParams(pieces=args.pieces)))
    out = break_to_folder(args.mesh, args.out, params=config.break_, seed=config.seed, force=args.force,
                          fill_holes=config.fill_holes)
    print(f"wrote {config.break_.pieces} fragments and the ground truth to {out}/")
    return 0


def _config(args: argparse.Namespace, *, base=None):
    """The command's Config: ``--config`` (or ``base``, or the defaults), then the options
    given, then every ``--set``."""
    from .config import Config, read_config, with_setting, with_value

    config = read_config(args.config) if getattr(args, "config", None) else base or Config()
    for dest, value in vars(args).items():
        if dest.startswith(_SET):
            config = with_value(config, dest[len(_SET):], value)
    for setting in getattr(args, "set", None) or []:
        config = with_setting(config, setting)
    config.check()
    return config


def _radii(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of numbers: {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError("no radii given")
    return values


def _bytes(text: str) -> float:
    units = {"k": 1e3, "m": 1e6, "g": 1e9, "t": 1e12}
    t = text.strip().lower().rstrip("b")
    try:
        if t and t[-1] in units:
            return float(t[:-1]) * units[t[-1]]
        return float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a size (e.g. 4G, 500M): {text!r}") from None


def _gap(text: str) -> float | None:
    if text.strip().lower() == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 <= value < 0.5:  # nan fails it too
        raise argparse.ArgumentTypeError(f"not 'auto' or a fraction in [0, 0.5): {text!r}")
    return value


FILL_HOLES = 0.25  # --fill-holes without a value: holes up to a quarter of the mesh's size


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value <= 1.0:  # nan fails it too
        raise argparse.ArgumentTypeError(f"not a fraction in (0, 1]: {text!r}")
    return value


_SET = "set:"  # argparse dest prefix of an option that sets one value of the Config: "set:segment.crease_angle"


def _g(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _size_text(value: float) -> str:
    for unit, factor in (("T", 1e12), ("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if value >= factor and value % factor == 0:
            return f"{value / factor:g}{unit}"
    return f"{value:g}"


def _auto(value) -> str:
    return "auto" if value is None else _g(value)


def _option(p, flag: str, path: str, *, help: str, defaults=None, show=_g, **kwargs) -> None:
    """An option that sets the value at ``path`` of the command's Config (``segment.crease_angle``);
    its default, shown in the help, is the Config's (or that of the dataclass ``defaults``)."""
    from .config import default

    value = default(path) if defaults is None else getattr(defaults, path.rpartition(".")[2])
    if "action" not in kwargs:
        kwargs.setdefault("metavar", flag.lstrip("-").upper().replace("-", "_"))
    p.add_argument(flag, dest=_SET + path, default=argparse.SUPPRESS,
                   help=f"{help} (default {show(value)})" if show else help, **kwargs)


def _add_config(p) -> None:
    p.add_argument("--config", type=Path, metavar="CONFIG_JSON",
                   help="start from the options of this config.json (a run's, to repeat it); the options "
                   "given here and --set change it")
    p.add_argument("--set", action="append", metavar="SECTION.NAME=VALUE",
                   help="change one option of the configuration, e.g. segment.crease_angle=25 (repeatable; "
                   "every option is in a run's config.json)")


def _add_fill_holes(p, *, dest: str = _SET + "fill_holes") -> None:
    p.add_argument("--fill-holes", type=_fraction, nargs="?", const=FILL_HOLES, dest=dest, metavar="MAX",
                   default=argparse.SUPPRESS if dest.startswith(_SET) else None,
                   help="close the holes of open scans with flat patches, those up to MAX of the mesh's "
                   f"bounding-box diagonal (default {FILL_HOLES} when given; without it an open mesh is read as it is, "
                   "its holes bridged by the winding number)")


def _thin_walls(text: str) -> bool | None:
    value = {"auto": None, "yes": True, "no": False}.get(text.strip().lower(), "?")
    if value == "?":
        raise argparse.ArgumentTypeError(f"not 'auto', 'yes' or 'no': {text!r}")
    return value


def _cmd_describe(args: argparse.Namespace) -> int:
    from .descriptors import DescriptorParams
    from .pipeline import describe_to_file

    given = {dest[len(_SET):].partition(".")[2]: value for dest, value in vars(args).items() if dest.startswith(_SET)}
    summary = describe_to_file(
        args.mesh, args.out, radii=args.radii, relative=args.relative, params=DescriptorParams(**given),
        force=args.force, fill_holes=args.fill_holes,
    )
    radii = ", ".join(f"{r:.4g}" for r in summary["radii"])
    print(f"{summary['vertices']} vertices, radii {radii}: {summary['timings']['total']:.2f} s -> {args.out}")
    return 0


def _format_report(report: dict) -> str:
    rows = [
        ("part accuracy (Breaking Bad)", "part_acc", "{:.3f}"),
        ("part accuracy (strict, 1% diag)", "part_acc_strict", "{:.3f}"),
        ("rotation RMSE, Euler (deg)", "rot_rmse_euler_deg", "{:.2f}"),
        ("rotation, geodesic RMSE (deg)", "rot_geodesic_rmse_deg", "{:.2f}"),
        ("translation RMSE (unit box)", "trans_rmse", "{:.4f}"),
        ("shape chamfer (unit box, sq.)", "shape_cd", "{:.2e}"),
        ("solved (all strict-correct)", "solved", "{}"),
    ]
    modes = [m for m in ("as_given", "anchor_largest", "best_anchor") if m in report["alignments"]]
    width = 34
    lines = [
        f"{report['n_placed']}/{report['n_fragments']} fragments placed"
        + (f"; missing from prediction: {', '.join(report['missing'])}" if report["missing"] else ""),
        f"{'':{width}}" + "".join(f"{m:>16}" for m in modes),
    ]
    for label, key, fmt in rows:
        cells = "".join(f"{fmt.format(report['alignments'][m]['summary'][key]):>16}" for m in modes)
        lines.append(f"{label:{width}}{cells}")
    anchors = [report["alignments"][m].get("anchor") for m in modes[1:]]
    lines.append(f"{'anchor fragment':{width}}" + "".join(f"{a or '-':>16}" for a in [None] + anchors))
    return "\n".join(lines)


def _cmd_eval(args: argparse.Namespace) -> int:
    from .files import write_json
    from .puzzle import evaluate_files

    report = evaluate_files(args.predicted, args.ground_truth, n_points=args.points, seed=args.seed)
    if args.out:
        write_json(args.out, report)
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(_format_report(report))
    return 0


def _cmd_match(args: argparse.Namespace) -> int:
    from .pipeline import match_to_folder

    summary = match_to_folder(args.inputs, args.out, config=_config(args), force=args.force, debug=args.debug_files,
                              jobs=_jobs(args), scheduler=args.scheduler, progress=not args.quiet)
    print(f"{summary['fragments']} fragments, {summary['pairs']} pairs, {summary['touching']} touching:")
    for p in summary["pair_list"]:
        best = p["candidates"][0] if p["candidates"] else None
        score = f"score {best['score']:.3f}, contact {best['contact_area']:.4g}" if best else "no candidate"
        print(f"  {p['source']} - {p['target']}: {'touch' if p['touching'] else 'apart'} ({score})")
    print(f"wrote {args.out}/pairs.json")
    return 0


def _jobs(args) -> int:
    import os

    if args.jobs:
        return args.jobs
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _print_run(report: dict, out: Path) -> None:
    s = report["summary"]
    print(f"{s['placed']} of {s['fragments']} fragments placed, {s['contacts']} contacts"
          + (f", {s['sub_assemblies'] - 1} further sub-assemblies" if s["sub_assemblies"] > 1 else "")
          + f" ({sum(s['timings_s'].values()):.0f} s)")
    for name, f in report["fragments"].items():
        state = "placed" if f["placed"] else f"NOT placed (group {f['group']})"
        print(f"  {name}: {state}, confidence {f['confidence']:.2f}, touches {', '.join(f['neighbours']) or '-'}")
    print(f"wrote {out}/transforms.json, assembled.glb, assembled.ply, report.json")


def _cmd_run(args: argparse.Namespace) -> int:
    from .pipeline import run_to_folder

    report = run_to_folder(args.inputs, args.out, config=_config(args), force=args.force, debug=args.debug_files,
                           jobs=_jobs(args), scheduler=args.scheduler, progress=not args.quiet)
    _print_run(report, args.out)
    if args.render or args.viewer:
        _view(args.out, render=args.render, viewer=args.viewer, progress=not args.quiet)
    return 0


def _view(folder: Path, *, progress: bool, **options) -> None:
    from .view import view_folder

    summary = view_folder(folder, progress=progress, **options)
    if summary["pictures"]:
        print(f"wrote {summary['pictures']} pictures to {folder}/pictures/")
    print(f"wrote {summary['report']} (open it in a browser; it needs no network)")


def _cmd_view(args: argparse.Namespace) -> int:
    _view(args.folder, truth=args.truth, radius=args.radius, render=not args.no_pictures, viewer=args.viewer,
          width=args.size[0], height=args.size[1], progress=not args.quiet)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from .demo import demo_to_folder

    report, score = demo_to_folder(args.out, mesh=args.mesh, pieces=args.pieces, seed=args.seed, force=args.force,
                                   jobs=_jobs(args), progress=not args.quiet)
    _print_run(report, args.out / "result")
    print(f"against the ground truth ({args.out}/result/score.json):")
    print(_format_report(score))
    print("(reassemble's world frame is the largest placed fragment's file frame, not the puzzle's: "
          "the anchored columns are the ones that count)")
    if not args.no_render:
        _view(args.out / "result", progress=not args.quiet)
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not WIDTHxHEIGHT: {text!r}") from None
    if not (64 <= w <= 4096 and 64 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"each side between 64 and 4096 pixels (got {text})")
    return w, h


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="reassemble",
        description="Put broken 3D objects back together.",
    )
    parser.add_argument("--version", action="version", version=f"reassemble {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add in (_add_break, _add_describe, _add_eval, _add_match, _add_run, _add_bench):
        add(sub)
    return parser


def _add_break(sub) -> None:
    p = sub.add_parser(
        "break",
        help="break a mesh into a synthetic puzzle with ground truth",
        description="Cut a mesh into fragments along rough, multi-scale surfaces "
        "(manifold3d booleans), pose them at random and write the ground truth. "
        "Lengths are fractions of the object's bounding-box diagonal.",
    )
    p.add_argument("mesh", help="mesh file (any triangle set with an inside), or the name of a bundled mesh (e.g. spot, torus)")
    p.add_argument("--pieces", type=_int_at_least(2), required=True, help="number of fragments (>= 2)")
    _option(p, "--seed", "seed", type=_int_at_least(0), help="random seed")
    p.add_argument("--out", type=Path, required=True, help="output folder (must not exist)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    _option(p, "--style", "break.style", choices=("fractal", "smooth", "cells", "mixed"),
            help="cut surfaces: fractal (rough at every scale), smooth (long undulations), cells "
            "(Voronoi-like, near-planar faces), mixed (each cut its own)")
    _option(p, "--keep-cell-faces", "break.keep_cell_faces", action="store_true", show=None,
            help="write each fragment as a union of cells keeping the faces between them, twice each, "
            "labelled 2 = interior (Breaking Bad's early layout)")
    for flag, help in (
        ("--roughness", "RMS height of the cut surfaces / radius of the piece cut, 0 = planes (default 0.08 fractal, 0.05 smooth, 0.02 cells; mixed draws its own)"),
        ("--cut-edge", "edge length of cut surfaces / object diagonal"),
        ("--noise", "Gaussian vertex noise sigma / object diagonal"),
        ("--chips", "mean number of chips knocked off each fragment's break edge"),
        ("--chip-size", "typical chip radius / object diagonal"),
        ("--decimate", "simplify fragments to this tolerance / object diagonal (0: off)"),
        ("--gap", "material lost at the break: mating surfaces end this far apart / diagonal"),
        ("--scale", "scale the mesh first, e.g. 1000 for metres to millimetres"),
    ):
        _option(p, flag, "break." + flag[2:].replace("-", "_"), type=_number, help=help)
    _add_fill_holes(p)
    p.add_argument("--set", action="append", metavar="break.NAME=VALUE",
                   help="change one option of the break (synth.BreakParams), e.g. break.hurst=0.5 (repeatable)")
    p.set_defaults(func=_cmd_break)


def _add_describe(sub) -> None:
    from .descriptors import DescriptorParams

    p = sub.add_parser(
        "describe",
        help="multi-scale integral invariants (V_r, D2_r and curvatures) of a mesh",
        description="Integral invariants at every (welded) vertex: V_r (volume of ball and solid), "
        "P_r (its second moment), D2_r (squared distance integral) and the curvatures they give: "
        "H (mean), H_rob (offset-robust mean), K2 = (kappa1 - kappa2)^2; SA_r (sphere area, dV_r/dr), "
        "D_r (signed distance integral), SD2_r (squared distance over the sphere) and the normal "
        "of the area vector grad V_r. Written to an .npz with arrays vertices (n x 3), faces, "
        "radii (m), n x m arrays V, P, D2, H, H_rob, K2, SA, D, SD2 and n x m x 3 normal_area.",
    )
    p.add_argument("mesh", help="mesh file, or the name of a bundled mesh")
    p.add_argument("--radii", type=_radii, required=True, help="comma-separated kernel radii, mesh units")
    p.add_argument("--relative", action="store_true", help="radii are fractions of the bounding-box diagonal")
    p.add_argument("--out", type=Path, required=True, help="output .npz file")
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    descriptor = DescriptorParams()
    _option(p, "--resolution", "describe.resolution", type=_number, defaults=descriptor,
            help="voxels per radius of the occupancy grids, at least")
    _option(p, "--d2-resolution", "describe.d2_resolution", type=_number, defaults=descriptor,
            help="voxels per radius of the squared-distance grids")
    _option(p, "--no-d2", "describe.with_d2", action="store_false", show=None,
            help="skip D2_r and K2, and D_r and SD2_r (the slow part: NaN in the file)")
    _option(p, "--no-sphere-area", "describe.sphere_area", action="store_false", show=None,
            help="skip SA_r (one more FFT per radius; NaN in the file)")
    _option(p, "--principal", "describe.principal", action="store_true", show=None,
            help="also principal curvatures k1, k2, K2_cov, directions dir1 and normals "
            "from the covariance of ball and solid (robust to noise, unlike K2 from D2)")
    _option(p, "--max-memory", "describe.max_memory", type=_bytes, defaults=descriptor, show=_size_text,
            help="working memory allowed for one grid, e.g. 4G; a larger grid is computed in tiles (slower)")
    _add_fill_holes(p, dest="fill_holes")
    p.set_defaults(func=_cmd_describe)


def _add_eval(sub) -> None:
    from .puzzle import evaluate_files

    p = sub.add_parser(
        "eval",
        help="score a transforms.json against a puzzle's ground truth",
        description="Score predicted fragment poses: Breaking Bad metrics (part accuracy, "
        "Euler RMSE, translation RMSE, shape chamfer), strict part accuracy and geodesic "
        "rotation error, with the prediction as given and anchored on one fragment.",
    )
    p.add_argument("predicted", type=Path,
                   help="transforms.json (convention T_world_fragment), or the folder `run` wrote it to")
    p.add_argument("ground_truth", type=Path,
                   help="ground_truth.json of the puzzle (fragments/ beside it), or the puzzle's folder")
    p.add_argument("--json", action="store_true", help="print the full report as JSON")
    p.add_argument("--out", type=Path, help="also write the full report to this JSON file")
    scoring = inspect.signature(evaluate_files).parameters
    p.add_argument("--points", type=_int_at_least(10), default=scoring["n_points"].default,
                   help="points sampled per fragment (default %(default)s)")
    p.add_argument("--seed", type=_int_at_least(0), default=scoring["seed"].default,
                   help="seed of the point samples (default %(default)s)")
    p.set_defaults(func=_cmd_eval)


def _add_common(p) -> None:
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.add_argument("--jobs", type=_int_at_least(0), default=0,
                   help="processes for descriptors and pairwise registration (default 0: one per available core)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def _add_inputs(p) -> None:
    """Fragments in, a folder out: the arguments of match and run."""
    p.add_argument("inputs", nargs="+", help="fragment mesh files (.ply .obj .stl .off .glb .gltf), or folders of them")
    p.add_argument("--out", type=Path, required=True, help="output folder (must not exist)")
    p.add_argument("--debug-files", action="store_true",
                   help="also write fracture labels as vertex colours (labels/*.ply) and matched keypoints per "
                   "pair (matches/)")
    _option(p, "--seed", "seed", type=_int_at_least(0), help="random seed")
    _option(p, "--max-memory", "describe.max_memory", type=_bytes, show=_size_text,
            help="working memory one fragment's descriptor grid may take, e.g. 4G; larger grids are computed "
            "in tiles, and a fragment for which even one tile needs more is left out with a note")
    _option(p, "--gap", "gap", type=_gap, show=_auto,
            help="how far apart mating fracture surfaces are (material lost at the break), a fraction of the "
            "median fragment's bounding-box diagonal; 'auto': measured from the pairs")
    _option(p, "--thin-walls", "thin_walls", type=_thin_walls, show=_auto,
            help="match as thin-walled sherds, along their break strips: 'auto' (when most fragments are "
            "walls under 8 %% of their diagonal thick; then as solids too, keeping the assembly with more "
            "contact), 'yes' or 'no'")
    _add_fill_holes(p)
    _add_config(p)
    _option(p, "--split-bodies", "split_bodies", action="store_true", show=None,
            help="a file holding several separate bodies gives one fragment per body (stem.1, stem.2, "
            "...); by default a file is one rigid piece")
    _add_common(p)
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="describe fragments and register pairs on the Dask cluster of this scheduler, e.g. "
                   "tcp://host:8786, instead of local processes (workers need reassemble installed; the result is "
                   "the same)")


def _add_run(sub) -> None:
    from .demo import demo_to_folder
    from .view import view_folder

    p = sub.add_parser(
        "run",
        help="assemble a folder of fragments into the object",
        description="Find the fracture surfaces, register fragment pairs and assemble all fragments "
        "into one consistent, collision-free object. Writes transforms.json (T_world_fragment, placed, "
        "confidence per file stem), assembled.glb (one node per fragment), assembled.ply (placed "
        "fragments), report.json, pairs.json and config.json. The folder appears only when complete.",
    )
    _add_inputs(p)
    p.add_argument("--render", action="store_true",
                   help="also write pictures and report.html (as 'reassemble view OUT' does)")
    p.add_argument("--viewer", action="store_true", help="open an interactive 3D window at the end (needs a display)")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "view",
        help="pictures and a shareable HTML report of a run",
        description="Render headless pictures of a run folder (made by 'reassemble run'): every fragment "
        "coloured by fracture / original surface and by mean curvature, every accepted match pulled apart "
        "with lines between touching points and in contact, the assembly from six sides and exploded. "
        "Writes FOLDER/pictures/ and FOLDER/report.html: one self-contained page (interactive 3D view, "
        "pictures, tables) that opens from disk with no network. With no OpenGL the pictures are skipped "
        "with a warning and the page is still written.",
    )
    p.add_argument("folder", type=Path, help="a run's output folder (with transforms.json)")
    p.add_argument("--truth", type=Path, help="a puzzle's ground_truth.json: add the metrics to the report")
    p.add_argument("--radius", type=_number,
                   help="descriptor radius of the curvature pictures, a fraction of the reference size "
                   "(one of the run's radii; default the middle one)")
    view = inspect.signature(view_folder).parameters
    size = (view["width"].default, view["height"].default)
    p.add_argument("--size", type=_size, default=size, help=f"size of one view, WIDTHxHEIGHT (default {size[0]}x{size[1]})")
    p.add_argument("--no-pictures", action="store_true", help="write report.html without rendering pictures")
    p.add_argument("--viewer", action="store_true", help="open an interactive 3D window (needs a display)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_view)

    p = sub.add_parser(
        "demo",
        help="break a bundled mesh, reassemble it and score the result",
        description="The one-minute proof: breaks a bundled mesh into fragments in random poses "
        "(OUT/puzzle), reassembles them with 'run' (OUT/result), scores the result against the "
        "ground truth (OUT/result/score.json) and writes the pictures and OUT/result/report.html.",
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    demo = inspect.signature(demo_to_folder).parameters
    p.add_argument("--mesh", default=demo["mesh"].default,
                   help="bundled mesh name or a mesh file (default %(default)s)")
    p.add_argument("--pieces", type=_int_at_least(2), default=demo["pieces"].default,
                   help="number of fragments (default %(default)s)")
    p.add_argument("--seed", type=_int_at_least(0), default=demo["seed"].default, help="random seed (default %(default)s)")
    p.add_argument("--no-render", action="store_true", help="skip the pictures and report.html")
    _add_common(p)
    p.set_defaults(func=_cmd_demo)


def _add_match(sub) -> None:
    p = sub.add_parser(
        "match",
        help="find fracture surfaces and register fragment pairs",
        description="Segment every fragment into fracture and original surface and register every "
        "pair along the fracture surfaces. Writes pairs.json (ranked candidate transforms "
        "T_target_source with contact and penetration), fragments.json and config.json.",
    )
    _add_inputs(p)
    p.set_defaults(func=_cmd_match)


def _pieces_range(text: str) -> tuple[int, int]:
    try:
        lo, _, hi = text.partition("-")
        low, high = int(lo), int(hi or lo)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a piece count or range like 2-20: {text!r}") from None
    if not 2 <= low <= high:
        raise argparse.ArgumentTypeError(f"need 2 <= LOW <= HIGH (got {text})")
    return low, high


def _cmd_bench(args: argparse.Namespace) -> int:
    from .bench import bench

    summary = bench(args.dataset, args.out, config=_config(args), pieces=args.pieces, limit=args.limit,
                    timeout=args.timeout or None, jobs=_jobs(args), scheduler=args.scheduler,
                    memory_limit=args.memory_limit or "auto", n_points=args.points, progress=not args.quiet)
    g = summary["overall"]
    fmt = lambda x, f: "-" if x is None else format(x, f)  # noqa: E731
    print(f"{g['sets']} sets ({summary['ran']} run now, {summary['skipped']} from earlier), {g['failed']} failed: "
          f"part accuracy {fmt(g['part_acc'], '.3f')} (strict {fmt(g['part_acc_strict'], '.3f')}), "
          f"rotation RMSE {fmt(g['rot_rmse_euler_deg'], '.2f')} deg, translation RMSE {fmt(g['trans_rmse'], '.4f')}, "
          f"chamfer {fmt(g['shape_cd'], '.2e')}")
    print(f"wrote {args.out}/results.jsonl, summary.json, summary.md, pa_by_pieces.png, rotation_errors.png")
    return 0


def _add_bench(sub) -> None:
    from .bench import bench

    defaults = inspect.signature(bench).parameters
    p = sub.add_parser(
        "bench",
        help="solve and score every fracture set of a dataset (Breaking Bad layout or puzzles), on Dask",
        description="Every folder of DATASET holding two or more mesh files is a fracture set in assembled pose "
        "(Breaking Bad's category/object/fractured_k/piece_*.obj), or a puzzle made by 'reassemble break' (its "
        "ground_truth.json is the truth). Each set gets seeded random poses and shuffled names, is solved with "
        "run's pipeline in one process and scored as the literature does (Breaking Bad part accuracy, Euler "
        "rotation RMSE, translation RMSE, chamfer; largest piece anchored) and strictly (docs/method/metrics.md). "
        "Each set is a task on Dask distributed: a local cluster, or an existing one (--scheduler). Writes "
        "OUT/results.jsonl (one line per set, appended as they finish), summary.json, summary.md, "
        "pa_by_pieces.png and rotation_errors.png. Rerunning with the same options skips the sets already done.",
    )
    p.add_argument("dataset", type=Path, metavar="DATASET", help="folder tree of fracture sets")
    p.add_argument("--out", type=Path, required=True, help="output folder (an existing one is resumed)")
    p.add_argument("--limit", type=_int_at_least(1), help="a seeded random sample of this many sets")
    p.add_argument("--pieces", type=_pieces_range, default=defaults["pieces"].default, metavar="LOW-HIGH",
                   help="sets with this many pieces, LOW-HIGH or N (default 2-20)")
    _option(p, "--seed", "seed", type=_int_at_least(0), help="random seed (poses, sample, solver)")
    p.add_argument("--timeout", type=_number, default=defaults["timeout"].default,
                   help="seconds per set; a set over it is recorded as 'timeout' (default %(default)g; 0: none)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=_int_at_least(0), default=0,
                       help="worker processes of the local Dask cluster (default 0: one per available core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use the Dask cluster of this scheduler, e.g. tcp://host:8786 (scheduler and workers need "
                       "reassemble installed; start them with DASK_DISTRIBUTED__WORKER__DAEMON=False so they can enforce "
                       "--timeout)")
    p.add_argument("--memory-limit", type=_bytes, default=None,
                   help="memory per local worker, e.g. 4G (default: the RAM shared among the workers); a set "
                   "over it is stopped and recorded")
    p.add_argument("--points", type=_int_at_least(10), default=defaults["n_points"].default,
                   help="points sampled per piece for scoring (default %(default)s)")
    _add_config(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_bench)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    from .allocator import retain_freed_memory

    retain_freed_memory()
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return args.func(args)
    except ReassembleError as exc:
        print(f"reassemble: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("reassemble: interrupted; nothing half-written was left behind", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: one line for users, the traceback with --debug
        if args.debug:
            raise
        msg = first_line(exc)
        print(
            f"reassemble: internal error: {type(exc).__name__}: {msg} (rerun with --debug for details)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
