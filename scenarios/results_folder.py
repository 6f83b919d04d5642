"""A scenario's results folder, replaced whole or not at all, and what a killed run leaves.

A run writes into ``<root>/.<name>.partial-XXXX``, which its process holds locked (the lock
file ``.<name>.partial-XXXX.lock``; common.file_locks, on any OS) while it lives. When the run
has finished, one swap at a time (the lock ``<root>/.<name>.lock``, so that two runs of the
same scenario never interleave their renames), the folder is renamed ``.<name>.complete-XXXX``,
the previous ``<name>`` is renamed ``.<name>.old-XXXX``, the complete one becomes ``<name>``
and the old one is deleted. A failure at any step (a full disk, a read-only or immutable
folder) puts back what was moved and removes the new folder: ``<name>`` is as it was, and
:class:`ResultsWriteError` says why.

A process killed at any point (SIGKILL, power loss) may leave an unlocked ``.partial-*``
folder (an unfinished run), a ``.complete-*`` folder (a finished run not yet in place) or an
``.old-*`` folder (a replaced run not yet deleted), or no ``<name>`` at all (killed between
the two renames). The next run of that name, before it starts, puts the newest complete run
in place, deletes the rest, and says what it did (:func:`recover`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

from common.atomic_files import write_text_atomic
from common.file_locks import drop, is_free, lock_path, take

DIR_MODE = 0o755
KEPT = ("sweep",)  # subfolders of results/<name> that a plain run carries over
LOCK_TIMEOUT_S = 60.0  # a swap takes milliseconds; a lock held longer is a stuck process
PARTIAL, COMPLETE, OLD = "partial", "complete", "old"

Notify = Callable[[str], None]
# a path component ``.<name>.partial-XXXXXXXX`` (mkdtemp's suffix: 8 of [a-z0-9_]), at the
# start of the text or after a separator, a space, a quote or an equals sign
_PARTIAL_COMPONENT = re.compile(
    rf"(?<![^/\\\s'\"=])\.([^/\\\s'\"]+)\.{PARTIAL}-[a-z0-9_]{{8}}(?=[/\\\s'\":]|$)",
    re.MULTILINE,
)


class ResultsWriteError(OSError):
    """The results folder could not be written or replaced; it was left as it was."""


def _stderr(text: str) -> None:
    print(f"note: {text}", file=sys.stderr, flush=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def sibling(out_dir: Path, kind: str) -> Path:
    """A new hidden sibling name ``.<name>.<kind>-XXXXXXXX`` of ``out_dir``."""
    return out_dir.parent / f".{out_dir.name}.{kind}-{secrets.token_hex(4)}"


def final_paths(text: str) -> str:
    """``text`` with every run folder ``.<name>.partial-XXXXXXXX`` named by its final name
    ``<name>``: what a log or a summary written during the run says of paths in its own
    folder, as they are after the swap (the partial folder no longer exists then)."""
    return _PARTIAL_COMPONENT.sub(r"\1", text)


def final_paths_in(value: Any) -> Any:
    """:func:`final_paths` on every string of a JSON-like value (dicts, lists, strings)."""
    if isinstance(value, str):
        return final_paths(value)
    if isinstance(value, dict):
        return {k: final_paths_in(v) for k, v in value.items()}
    if isinstance(value, list):
        return [final_paths_in(v) for v in value]
    if isinstance(value, tuple):
        return tuple(final_paths_in(v) for v in value)
    return value


TEXT_SUFFIXES = (".json", ".log", ".md", ".txt")  # files a run writes that may name paths


def name_final_paths(folder: Path) -> list[Path]:
    """:func:`final_paths` on every text file under the run's ``folder`` (what the command
    line wrote there names its inputs and outputs by the partial folder), each rewritten
    atomically; returns the files changed."""
    changed = []
    for path in sorted(folder.rglob("*")):
        if path.suffix not in TEXT_SUFFIXES or not path.is_file():
            continue
        text = path.read_text(encoding="utf-8")
        if f".{PARTIAL}-" in text and (new := final_paths(text)) != text:
            write_text_atomic(path, new)
            changed.append(path)
    return changed


def leftovers(out_dir: Path, kind: str) -> list[Path]:
    return sorted(out_dir.parent.glob(f".{out_dir.name}.{kind}-*"))


def describe_os_error(exc: OSError) -> str:
    """``No space left on device: '/path'``: the cause of an OSError without its errno."""
    what = exc.strerror or str(exc)
    return f"{what}: '{exc.filename}'" if exc.filename else what


@contextlib.contextmanager
def _locked(root: Path, name: str) -> Iterator[None]:
    """One swap at a time of the runs named ``name`` under ``root``: the lock file
    ``<root>/.<name>.lock``, waited for up to LOCK_TIMEOUT_S (then ResultsWriteError), and
    removed when released (a swap takes milliseconds)."""
    lock = root / f".{name}.lock"
    held = take(lock, timeout=LOCK_TIMEOUT_S)
    if held is None:
        raise ResultsWriteError(
            errno.EBUSY,
            f"another process has held the lock {lock} for {LOCK_TIMEOUT_S:g} s",
            str(lock),
        )
    try:
        yield
    finally:
        drop(held)


def _finished_at(folder: Path) -> float:
    """When the run in ``folder`` finished: its summary.json's time, else the folder's."""
    summary = folder / "summary.json"
    with contextlib.suppress(OSError):
        return summary.stat().st_mtime
    with contextlib.suppress(OSError):
        return folder.stat().st_mtime
    return 0.0


def _remove(path: Path, removed: list[str], failed: list[str]) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
        removed.append(path.name)
    except OSError as exc:
        failed.append(f"{path.name} ({describe_os_error(exc)})")


def _carry_kept(into: Path, sources: list[Path]) -> None:
    for keep in KEPT:
        if (into / keep).exists():
            continue
        for src in sources:
            if (src / keep).is_dir():
                os.rename(src / keep, into / keep)
                break


def recover(out_dir: Path, notify: Notify = _stderr) -> list[str]:
    """Clean up after killed runs of ``out_dir``'s name (call with the root locked): delete
    unfinished (unlocked) ``.partial-*`` folders; of ``out_dir``, ``.complete-*`` and
    ``.old-*``, keep the newest complete run as ``out_dir`` and delete the others. Returns
    (and passes to ``notify``) one sentence per thing done."""
    notes: list[str] = []
    removed: list[str] = []
    failed: list[str] = []
    for partial in leftovers(out_dir, PARTIAL):
        if partial.name.endswith(".lock"):  # a lock whose folder is gone
            if not partial.with_suffix("").exists() and is_free(partial):
                partial.unlink(missing_ok=True)
            continue
        held = take(lock_path(partial))
        if held is not None:  # no live process holds it: a run killed before it finished
            _remove(partial, removed, failed)
            drop(held)
    if removed:
        notes.append(f"removed {len(removed)} unfinished run(s) of killed processes: {removed}")
    removed = []
    finished = leftovers(out_dir, COMPLETE) + leftovers(out_dir, OLD)
    if finished:
        present = out_dir.exists() or out_dir.is_symlink()
        candidates = ([out_dir] if present else []) + finished
        newest = max(candidates, key=_finished_at)
        when = datetime.fromtimestamp(_finished_at(newest)).isoformat(sep=" ", timespec="seconds")
        if newest != out_dir:
            _carry_kept(newest, [c for c in candidates if c != newest])
            if present:
                aside = sibling(out_dir, OLD)
                os.rename(out_dir, aside)
                finished.append(aside)
            os.rename(newest, out_dir)
            finished.remove(newest)
            state = "held an older run" if present else "was missing"
            notes.append(
                f"{out_dir} {state} (a run was killed while replacing it): put in place the "
                f"newest complete run, {newest.name}, finished {when}"
            )
        for leftover in finished:
            _remove(leftover, removed, failed)
        if removed:
            notes.append(f"removed {len(removed)} replaced run(s) left by killed processes")
    if failed:
        notes.append(f"could not remove {failed}")
    for note in notes:
        notify(note)
    return notes


def _os_error(out_dir: Path, exc: OSError) -> ResultsWriteError:
    return ResultsWriteError(
        exc.errno,
        f"{out_dir} not written: {describe_os_error(exc)}; the results folder is left as it was",
        exc.filename,
    )


@contextlib.contextmanager
def replaced_whole(out_dir: Path, notify: Notify = _stderr) -> Iterator[Path]:
    """Yield an empty temporary sibling of ``out_dir`` to write into; when the block ends
    without an exception, it becomes ``out_dir`` (a ``sweep/`` folder of earlier sweeps is
    carried over). On any exception, KeyboardInterrupt included, the temporary folder is
    removed and ``out_dir`` is left untouched; an OSError (a full disk, a read-only or
    immutable folder) comes out as :class:`ResultsWriteError` naming its cause. Leftovers of
    killed runs of the same name are recovered first (:func:`recover`)."""
    root = out_dir.parent
    try:
        root.mkdir(parents=True, exist_ok=True)
        with _locked(root, out_dir.name):
            recover(out_dir, notify)
            # made and locked while the name is locked: no other run's recover sees it unheld
            tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.{PARTIAL}-", dir=root))
            hold = take(lock_path(tmp))
    except ResultsWriteError:
        raise
    except OSError as exc:
        raise _os_error(out_dir, exc) from None
    try:
        os.chmod(tmp, DIR_MODE & ~_umask())  # mkdtemp makes 0700; results are ordinary
        yield tmp
        with _locked(root, out_dir.name):
            _swap_in(tmp, out_dir)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OSError) and not isinstance(exc, ResultsWriteError):
            raise _os_error(out_dir, exc) from None
        raise
    finally:
        drop(hold)


def _swap_in(tmp: Path, out_dir: Path) -> None:
    """Put the finished folder ``tmp`` in place of ``out_dir`` (root locked); on failure
    ``out_dir`` is put back as it was, the new folder removed and the error raised."""
    complete = sibling(out_dir, COMPLETE)
    os.rename(tmp, complete)
    moved: list[str] = []
    old = None
    try:
        for keep in KEPT:  # a sweep's runs are not this run's output: they stay
            if (out_dir / keep).is_dir() and not (complete / keep).exists():
                os.rename(out_dir / keep, complete / keep)
                moved.append(keep)
        if out_dir.exists() or out_dir.is_symlink():
            old = sibling(out_dir, OLD)
            os.rename(out_dir, old)
        try:
            os.rename(complete, out_dir)
        except BaseException:
            if old is not None:
                os.rename(old, out_dir)
                old = None
            raise
    except BaseException:
        for keep in moved:
            with contextlib.suppress(OSError):
                os.rename(complete / keep, out_dir / keep)
        shutil.rmtree(complete, ignore_errors=True)  # a failed swap is not a run to recover
        raise
    if old is not None:
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old, ignore_errors=True)  # what stays is recovered by the next run
        else:
            old.unlink(missing_ok=True)
