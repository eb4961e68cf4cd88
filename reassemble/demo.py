"""The ``demo`` command: break a bundled mesh, reassemble it and score the result."""

from __future__ import annotations

from pathlib import Path

from .files import check_output_folder, write_json
from .pipeline import run_to_folder
from .puzzle import break_to_folder, evaluate_files
from .synth import BreakParams


def demo_to_folder(
    out: str | Path, *, mesh: str = "spot", pieces: int = 8, seed: int = 1, force: bool = False, jobs: int = 1,
    progress: bool = False,
) -> tuple[dict, dict]:
    """Break ``mesh`` into ``out/puzzle``, reassemble it into ``out/result`` and score it.

    Returns the run's report and the score (also written to ``out/result/score.json``).
    """
    out = Path(out)
    check_output_folder(out, force=force)
    puzzle = break_to_folder(mesh, out / "puzzle", params=BreakParams(pieces=pieces), seed=seed, force=True)
    report = run_to_folder([puzzle / "fragments"], out / "result", seed=seed, force=True, jobs=jobs, progress=progress)
    score = evaluate_files(out / "result" / "transforms.json", puzzle / "ground_truth.json")
    write_json(out / "result" / "score.json", score)
    return report, score
