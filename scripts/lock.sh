#!/usr/bin/env bash
# Write requirements.lock from .venv: run it after the full test suite passed in that environment.
set -euo pipefail
cd "$(dirname "$0")/.."
{
  echo "# Tested versions: setup.sh installs with '-c requirements.lock' (pyproject.toml keeps ranges)."
  echo "# Regenerate after a dependency change, once the full suite passes: scripts/lock.sh"
  .venv/bin/python -m pip freeze --exclude-editable --disable-pip-version-check
} > requirements.lock
echo "wrote requirements.lock ($(grep -c '==' requirements.lock) packages)"
