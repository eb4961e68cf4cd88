"""Print which locked packages a Python environment has at other versions.

    python scripts/compare_versions.py PYTHON requirements.lock
"""

import json
import subprocess
import sys


def main() -> int:
    python, lock = sys.argv[1], sys.argv[2]
    locked = {}
    for line in open(lock, encoding="utf-8"):
        line = line.split("#")[0].strip()
        if "==" in line:
            name, version = line.split("==", 1)
            locked[name.strip().lower().replace("_", "-")] = version.strip()
    listing = subprocess.run([python, "-m", "pip", "list", "--format", "json", "--disable-pip-version-check"],
                             capture_output=True, text=True, check=True).stdout
    have = {p["name"].lower().replace("_", "-"): p["version"] for p in json.loads(listing)}
    changed = [(n, v, have[n]) for n, v in sorted(locked.items()) if n in have and have[n] != v]
    for name, old, new in changed:
        print(f"ci:   {name}: locked {old}, newest {new}")
    if not changed:
        print("ci:   every locked package is at its newest version")
    return 0


if __name__ == "__main__":
    sys.exit(main())
