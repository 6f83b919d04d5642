"""Run a module as ``__main__`` (``python -m bench.child_peak FILE MODULE ARGS...``) or import one
(MODULE given as ``import:NAME``), then write its own peak resident memory in kB to FILE.

The peak the operating system reports to a parent (``wait4``'s ``ru_maxrss``) starts from the
parent's: Linux carries the resident high-water mark across ``exec``, so a command started by
a 400 MB benchmark process reads at least 400 MB. Here the peak is this process's own
(``VmHWM`` of /proc/self/status, counted from its ``exec``) or that of its largest worker
process (``RUSAGE_CHILDREN``), whichever is larger; without /proc, ``ru_maxrss`` of itself."""

from __future__ import annotations

import resource
import runpy
import sys
from pathlib import Path


def _own_peak_kb() -> int:
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    line = next((x for x in text.splitlines() if x.startswith("VmHWM:")), None)
    return int(line.split()[1]) if line else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def main() -> None:
    out, target, args = sys.argv[1], sys.argv[2], sys.argv[3:]
    code = 0
    try:
        if target.startswith("import:"):
            __import__(target[len("import:") :])
        else:
            sys.argv = [target, *args]
            runpy.run_module(target, run_name="__main__", alter_sys=True)
    except SystemExit as exc:  # as the interpreter ends on it: a message is printed, exit 1
        if isinstance(exc.code, int) or exc.code is None:
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    finally:
        kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        Path(out).write_text(str(max(_own_peak_kb(), kids)))
    sys.exit(code)


if __name__ == "__main__":
    main()
