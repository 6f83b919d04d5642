"""Faults of the filesystem for tests: a small or read-only filesystem where one can be made,
else fakes that raise the same OSError; a child process killed at a chosen point.

``in_small_fs`` runs a command with a tmpfs of a given size (or read-only) mounted on a
folder, inside a user and mount namespace of its own (``unshare -rm``): no root needed where
the kernel allows unprivileged namespaces; tests skip where it does not. ``immutable``
makes a path immutable (``chattr +i``, root on ext4/xfs) or skips.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# A study that writes ``BYTES`` bytes (and an optional pause), and a scenario run on the
# command line with it; the child's argv: results root, bytes, pause in seconds.
STUB_RUN = """
import sys, time
from pathlib import Path
from scenarios import runner
from scenarios.__main__ import main

def run(scenario, out_dir, progress, recorder):
    (out_dir / "data.bin").write_bytes(b"x" * int(sys.argv[2]))
    time.sleep(float(sys.argv[3]))
    return {"scenario": scenario.name, "bytes": int(sys.argv[2])}

runner._study = lambda name: (run, lambda s: "# report\\n")
sys.exit(main(["run", "undeclared_effect", "--results", sys.argv[1], "--quiet", "--no-record"]))
"""


def _unshare() -> str | None:
    return shutil.which("unshare")


_NS_OK: bool | None = None


def namespaces_work() -> bool:
    """Whether ``unshare -rm`` can mount a tmpfs here."""
    global _NS_OK
    if _NS_OK is None:
        tool = _unshare()
        _NS_OK = bool(tool) and (
            subprocess.run(
                [tool, "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                capture_output=True,
                timeout=30,
            ).returncode
            == 0
        )
    return _NS_OK


def in_small_fs(
    mount: Path, argv: list[str], size: str = "1m", read_only: bool = False, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """Run ``argv`` with a fresh tmpfs of ``size`` on ``mount`` (read-only: an empty one)."""
    if not namespaces_work():
        pytest.skip("cannot mount a small filesystem here (no unprivileged namespaces)")
    mount.mkdir(parents=True, exist_ok=True)
    options = f"size={size}" + (",ro" if read_only else "")
    script = f"mount -t tmpfs -o {options} tmpfs {shlex.quote(str(mount))} && exec " + " ".join(
        shlex.quote(a) for a in argv
    )
    return subprocess.run(
        [_unshare() or "unshare", "-rm", "sh", "-c", script],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


def stub_run_argv(results: Path, n_bytes: int, pause_s: float = 0.0) -> list[str]:
    return [sys.executable, "-c", STUB_RUN, str(results), str(n_bytes), str(pause_s)]


@contextlib.contextmanager
def immutable(path: Path) -> Iterator[None]:
    """``chattr +i path`` for the block (skips where that is not allowed)."""
    tool = shutil.which("chattr")
    if tool is None or os.geteuid() != 0:
        pytest.skip("chattr +i needs the chattr tool and root")
    if subprocess.run([tool, "+i", str(path)], capture_output=True).returncode != 0:
        pytest.skip("this filesystem does not take chattr +i")
    try:
        yield
    finally:
        subprocess.run([tool, "-i", str(path)], capture_output=True)


def os_error(code: int, filename: str | os.PathLike[str] | None = None) -> OSError:
    """The OSError the system raises for ``code`` (ENOSPC, EROFS, EPERM, ...)."""
    return OSError(code, os.strerror(code), None if filename is None else str(filename))


ENOSPC, EROFS, EPERM = errno.ENOSPC, errno.EROFS, errno.EPERM
