"""docs/results.md and the README's results table are what the benchmarks' JSON records give.

CI checks the same with ``python -m benchmarks.report --check``; having it in the quick
subset catches a benchmark docstring or record edited without regenerating the docs.
"""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_generated_results_are_up_to_date():
    proc = subprocess.run([sys.executable, "-m", "benchmarks.report", "--check"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
