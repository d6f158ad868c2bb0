"""Run one command as a child process and print, as one JSON line, its wall time (s), exit
code, the last line it printed and its peak resident memory (MB: the largest of the child and
its waited-for descendants, from the OS via ``getrusage(RUSAGE_CHILDREN)``). Used by
``benchmarks/run.py`` so that every measured run gets a fresh process and its own peak."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time


def main() -> int:
    cmd = sys.argv[1:]
    t0 = time.perf_counter()
    child = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # Linux: kB
    lines = child.stdout.strip().splitlines()
    last = lines[-1] if lines else ""
    print(json.dumps({"wall_s": wall, "rc": child.returncode, "peak_mb": peak_mb, "last": last}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
