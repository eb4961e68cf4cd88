"""Run the commands on three small puzzles and compare every output file byte for byte.

A refactoring must leave the outputs unchanged at the same seed. Make the reference with the
code before the change, the new outputs with the code after it, then compare::

    PYTHONPATH=/path/to/old/checkout python scripts/compare_outputs.py generate /tmp/ref
    PYTHONPATH=$PWD python scripts/compare_outputs.py generate /tmp/new
    python scripts/compare_outputs.py compare /tmp/ref /tmp/new

``generate`` runs ``python -m reassemble`` (so the code on ``PYTHONPATH`` is the one run):
``break`` three bundled meshes, then ``run``, ``match``, ``describe`` and ``view --no-pictures``
on them; where the CLI has ``--config``, also ``run --config OUT/config.json`` into
``NAME_rerun``, whose ``transforms.json`` must equal the run's. Every command's printed
output is kept too (``NAME.stdout``).

``compare`` checks every file of either folder (but those named by ``--expect-changed``):
byte-identical, or, for the files that carry
timings (``report.json``'s ``timings_s``, ``report.html``, printed seconds), identical once the
timings are masked (said so per file); in ``report.html`` also the random name trimesh gives the
3D view's camera. Exit status 1 when anything differs.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

PUZZLES = [  # name, bundled mesh, pieces, seed, extra break options
    ("spot", "spot_low_resolution", 4, 1, []),
    ("torus", "torus", 3, 2, ["--noise", "0.002"]),
    ("block", "angle_block", 3, 3, []),
]


def _cli(args: list[str], stdout: Path) -> None:
    cmd = [sys.executable, "-m", "reassemble", *args]
    print("$", " ".join(cmd[1:]), flush=True)
    done = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    stdout.write_text(done.stdout + (f"[exit {done.returncode}]\n" if done.returncode else ""))
    if done.returncode:
        sys.exit(f"failed ({done.returncode}): {' '.join(args)}\n{done.stderr}")


def _has_option(command: str, option: str) -> bool:
    done = subprocess.run([sys.executable, "-m", "reassemble", command, "--help"], capture_output=True, text=True)
    return option in done.stdout


def generate(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=False)
    rerun = _has_option("run", "--config")
    for name, mesh, pieces, seed, extra in PUZZLES:
        puzzle = out / f"{name}_puzzle"
        _cli(["break", mesh, "--pieces", str(pieces), "--seed", str(seed), "--out", str(puzzle), *extra],
             out / f"{name}_break.stdout")
        frags = str(puzzle / "fragments")
        common = ["--seed", "0", "--jobs", "1", "--quiet"]
        _cli(["run", frags, "--out", str(out / f"{name}_run"), *common, *(["--debug-files"] if name == "spot" else [])],
             out / f"{name}_run.stdout")
        _cli(["match", frags, "--out", str(out / f"{name}_match"), *common], out / f"{name}_match.stdout")
        first = sorted((puzzle / "fragments").iterdir())[0]
        _cli(["describe", str(first), "--radii", "0.03,0.06", "--relative", "--principal",
              "--out", str(out / f"{name}_describe.npz")], out / f"{name}_describe.stdout")
        _cli(["view", str(out / f"{name}_run"), "--no-pictures", "--quiet"], out / f"{name}_view.stdout")
        if rerun:
            _cli(["run", frags, "--out", str(out / f"{name}_rerun"), "--config", str(out / f"{name}_run" / "config.json"),
                  "--jobs", "1", "--quiet"], out / f"{name}_rerun.stdout")


def _masked(path: Path, data: bytes, root: Path) -> bytes | None:
    """``data`` with its timings (and, in printed output, the folder ``root``) replaced, or None
    when the file carries none."""
    if path.name == "report.json":
        report = json.loads(data)
        report["summary"]["timings_s"] = {k: "-" for k in report["summary"]["timings_s"]}
        return json.dumps(report, sort_keys=True).encode()
    if path.name == "report.html" or path.suffix == ".stdout":
        text = data.decode().replace(str(root), "ROOT")
        # the page's 3D view: a GLB whose camera trimesh names at random (camera_23A024)
        text = re.sub(r"base64_data=&quot;([A-Za-z0-9+/=]*)&quot;", lambda m: "base64_data=" + hashlib.sha256(
            re.sub(rb"camera_[0-9A-F]{6}", b"camera_", base64.b64decode(m.group(1)))).hexdigest(), text)
        text = re.sub(r'"timings_s": *\{[^}]*\}', '"timings_s": {}', text)
        text = re.sub(r"\d+(\.\d+)? s\b", "N s", text)
        text = re.sub(r"(?s)(<t[dh][^>]*>)[^<]*timing[^<]*(</t[dh]>)", r"\1T\2", text)
        return text.encode()
    return None


def compare(ref: Path, new: Path, *, expect_changed: tuple[str, ...] = ()) -> int:
    files = sorted({p.relative_to(ref) for p in ref.rglob("*") if p.is_file()}
                   | {p.relative_to(new) for p in new.rglob("*") if p.is_file()})
    bad = 0
    for rel in files:
        a, b = ref / rel, new / rel
        if rel.parts[0].endswith("_rerun") or rel.name.endswith("_rerun.stdout"):
            continue  # checked against the run below, not the reference (which may predate --config)
        if not a.is_file() or not b.is_file():
            print(f"MISSING  {rel} (only in {'the new' if b.is_file() else 'the reference'} outputs)")
            bad += 1
            continue
        da, db = a.read_bytes(), b.read_bytes()
        if da == db:
            print(f"same     {rel}  sha256 {hashlib.sha256(da).hexdigest()[:16]}")
            continue
        ma, mb = _masked(rel, da, ref), _masked(rel, db, new)
        if ma is not None and ma == mb:
            print(f"same     {rel}  (timings, folder and camera names masked)")
            continue
        if rel.name in expect_changed:
            print(f"changed  {rel}  (expected: --expect-changed {rel.name})")
            continue
        print(f"DIFFERS  {rel}")
        bad += 1
    for run in sorted(p for p in new.iterdir() if p.name.endswith("_rerun")):
        original = new / run.name.replace("_rerun", "_run") / "transforms.json"
        same = (run / "transforms.json").read_bytes() == original.read_bytes()
        print(f"{'same   ' if same else 'DIFFERS'}  {run.name}/transforms.json vs {original.parent.name}/transforms.json "
              "(run --config OUT/config.json)")
        bad += not same
    print(f"{len(files)} files compared: {'all identical' if not bad else f'{bad} differ'}")
    return 1 if bad else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("generate").add_argument("out", type=Path)
    p = sub.add_parser("compare")
    p.add_argument("ref", type=Path)
    p.add_argument("new", type=Path)
    p.add_argument("--expect-changed", action="append", default=[], metavar="FILE_NAME",
                   help="files of this name may differ (a format changed on purpose), e.g. config.json")
    args = parser.parse_args()
    if args.command == "generate":
        generate(args.out)
        return 0
    return compare(args.ref, args.new, expect_changed=tuple(args.expect_changed))


if __name__ == "__main__":
    sys.exit(main())
