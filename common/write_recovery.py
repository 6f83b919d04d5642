"""What a killed :func:`common.write_set.write_set` left, rolled forward or back.

A write set's working files are ``.<file>.ws-<token>.tmp`` (a new file, complete once the
journal exists) and ``.<file>.ws-<token>.old`` (a link to the file it replaces), its lock
``.ws-<token>.lock`` and, from the moment every new file is written until the set is in
place, its journal ``.ws-<token>.json`` (in every folder of the set: target, new file and
previous file of each member). When the lock is free (its process is gone):

* a journal: the set was being swapped in; every new file still waiting is put in place
  (forward: the whole new set, as its command meant), then the previous files are deleted;
* no journal: nothing was replaced yet; the working files are deleted (back: the previous
  set stands).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path

from common.file_locks import drop, take

Notify = Callable[[str], None]
# a new or previous file of a set, and the temporary its writer (savefig, say) made of it
_WORKING = re.compile(r"^\..*\.ws-(?P<token>[0-9a-f]{8})\.(tmp|old)(\..*)?$")
_OWN = re.compile(r"^\.ws-(?P<token>[0-9a-f]{8})\.(json|json\.part|lock)$")


def say(text: str) -> None:
    print(f"note: {text}", file=sys.stderr, flush=True)


def working(target: Path, token: str, kind: str) -> Path:
    """The hidden working file (``tmp``: new, ``old``: previous) of ``target``."""
    return target.with_name(f".{target.name}.ws-{token}.{kind}")


def journal_text(targets: list[Path], temps: list[Path], backups: list[Path | None]) -> str:
    rows = [
        {"target": str(t.absolute()), "new": str(n.absolute()), "old": b and str(b.absolute())}
        for t, n, b in zip(targets, temps, backups, strict=True)
    ]
    return json.dumps({"set": rows}, indent=1) + "\n"


def _tokens(folder: Path) -> dict[str, list[Path]]:
    found: dict[str, list[Path]] = {}
    with contextlib.suppress(OSError):
        for p in folder.iterdir():
            m = _WORKING.match(p.name) or _OWN.match(p.name)
            if m:
                found.setdefault(m["token"], []).append(p)
    return found


def recover(folder: Path, notify: Notify = say) -> list[str]:
    """Roll forward or back every write set a killed process left in ``folder`` (see the
    module); returns (and passes to ``notify``) one sentence per set."""
    notes = []
    for token, paths in sorted(_tokens(folder).items()):
        held = take(folder / f".ws-{token}.lock")
        if held is None:
            continue  # a live process is writing this set
        try:
            journal = folder / f".ws-{token}.json"
            if journal.is_file():
                notes.append(_forward(journal, folder, token))
            else:
                names = sorted(p.name for p in paths if not p.name.endswith(".lock"))
                _unlink(paths)
                if names:
                    notes.append(
                        f"removed {len(names)} unfinished file(s) of a write killed before it "
                        f"replaced anything in {folder} ({', '.join(names)}); the files there "
                        "are as they were"
                    )
        finally:
            drop(held)
    for note in notes:
        notify(note)
    return notes


def _forward(journal: Path, folder: Path, token: str) -> str:
    rows = json.loads(journal.read_text(encoding="utf-8"))["set"]
    done = []
    for row in rows:
        new, target = Path(row["new"]), Path(row["target"])
        if new.exists():
            os.replace(new, target)
        done.append(target.name)
    folders = {Path(r["target"]).parent for r in rows} | {folder}
    _unlink([Path(r["old"]) for r in rows if r["old"]])
    for f in folders:  # the journal and lock of the set in each of its folders
        _unlink([f / f".ws-{token}.json", f / f".ws-{token}.json.part"])
        if f != folder:
            _unlink([f / f".ws-{token}.lock"])
    return (
        f"completed the set of files a killed write was replacing in {folder}: "
        f"{', '.join(done)} now all hold the new versions (their previous versions removed)"
    )


def _unlink(paths: list[Path]) -> None:
    for p in paths:
        with contextlib.suppress(OSError):
            p.unlink()
