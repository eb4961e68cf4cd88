"""What every benchmark prints first: the machine and the command, so figures can be rerun."""

from __future__ import annotations

import os
import platform
import sys


def machine_line() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError):
        mem = float("nan")
    return (f"machine: {cpu}, {os.cpu_count()} cores, {mem:.0f} GiB; "
            f"Python {platform.python_version()} on {platform.system()} {platform.machine()}")


def header() -> None:
    print(machine_line())
    print("command: " + " ".join([os.path.relpath(sys.argv[0])] + sys.argv[1:]))
