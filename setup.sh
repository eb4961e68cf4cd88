#!/usr/bin/env bash
# Set up reassemble in ./.venv and run the demo.  Usage: ./setup.sh [--no-demo]
set -euo pipefail
cd "$(dirname "$0")"

PYTHON=${PYTHON:-python3}
if ! command -v "$PYTHON" >/dev/null 2>&1; then
  echo "setup: $PYTHON not found; install Python 3.10 or newer (Debian/Ubuntu: apt-get install python3 python3-venv)" >&2
  exit 1
fi

# open3d links against libusb-1.0 at import time; Debian/Ubuntu do not always ship it.
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  echo "setup: installing the system library libusb-1.0-0 (open3d needs it)"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libusb-1.0-0 >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PYTHON" -m venv .venv
fi
# requirements.lock pins the versions the tests ran with (pyproject.toml keeps ranges for library users)
echo "setup: installing reassemble and its dependencies (tested versions: requirements.lock) into .venv (log: .venv/setup.log)"
# build-backend chatter goes to the log; it is shown only if the install fails
if ! { .venv/bin/python -m pip install --disable-pip-version-check --upgrade pip &&
       .venv/bin/python -m pip install --disable-pip-version-check -c requirements.lock -e ".[test]"; } > .venv/setup.log 2>&1; then
  tail -n 30 .venv/setup.log >&2
  echo "setup: pip install failed (full log: .venv/setup.log)" >&2
  exit 1
fi

if [ "${1:-}" != "--no-demo" ]; then
  # The one-minute proof: break the bundled cow into 8 fragments in random poses, put them
  # back together with `reassemble run`, and score the result against the ground truth.
  echo "setup: demo: breaking the bundled cow into 8 fragments and reassembling them in out/demo/"
  .venv/bin/reassemble demo --out out/demo --force --quiet
fi
echo "setup: done. Run the tests with: .venv/bin/python -m pytest -q"
