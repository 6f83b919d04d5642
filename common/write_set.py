"""Several files written as one set: all of them, or none (the previous files left in place).

``verify --out v.json`` writes v.json, v.csv and v.png; a reader must never find a new
v.json beside an old v.png, nor a set cut short by a full disk. :func:`write_set` first
writes every file to a temporary sibling (where a full disk or a read-only folder fails,
before anything is replaced), then keeps a hard link (or copy) of each file it will replace,
then swaps the new files in one by one; if a swap fails, the files already swapped are put
back from those links (and new ones removed), so the folder holds the previous set.

:func:`staged` serves writers that write files themselves (figures, recordings): they write
into a hidden staging folder, whose files then go in as one set.

:class:`WriteSetError` (an OSError) names the file and the cause and says that the previous
files were left as they were.

A process killed midway (SIGKILL, power loss) leaves hidden working files named
``.<file>.ws-<token>.tmp`` (new) and ``.old`` (previous), held by ``.ws-<token>.lock``; once
every new file is written, a journal ``.ws-<token>.json`` lists the set before the first
swap. The next :func:`write_set` into that folder finds them unheld and rolls the set
forward (journal: every new file put in place) or back (no journal: nothing was replaced;
the working files are deleted), and says what it did (:mod:`common.write_recovery`).
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from common.atomic_files import ordinary_mode
from common.file_locks import drop, is_free, lock_path, take
from common.write_recovery import Notify, journal_text, recover, say, working

Writer = Callable[[Path], None]


class WriteSetError(OSError):
    """A set of files could not be written; none of them was changed."""

    def __str__(self) -> str:
        return str(self.strerror)


def text_writer(text: str) -> Writer:
    """A writer of UTF-8 ``text`` (no newline translation)."""

    def write(path: Path) -> None:
        with open(path, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())

    return write


def _cause(exc: OSError) -> str:
    return exc.strerror or str(exc)


def _temporary(target: Path, token: str) -> Path:
    """Where the new ``target`` is written before it is swapped in."""
    return working(target, token, "tmp")


def _backup(target: Path, keep: Path) -> Path | None:
    """A hidden hard link (else a copy) ``keep`` of ``target`` if it exists, to restore it
    from."""
    if not target.exists():
        return None
    try:
        os.link(target, keep)
    except OSError:  # a filesystem without hard links
        shutil.copy2(target, keep)
    return keep


def write_set(
    files: Mapping[str | os.PathLike[str], Writer],
    make_parents: bool = False,
    notify: Notify = say,
) -> list[Path]:
    """Write each ``path -> writer(tmp_path)`` of ``files`` as one set (see the module);
    returns the paths. Raises :class:`WriteSetError` with every file left as it was.
    ``make_parents`` creates missing folders first (else a missing folder is the error).
    What a killed earlier write left in these folders is first rolled forward or back, and
    said through ``notify``."""
    targets = [Path(p) for p in files]
    writers = list(files.values())
    token = secrets.token_hex(4)
    temps: list[Path] = []
    backups: list[Path | None] = []
    swapped: list[int] = []
    journals: list[Path] = []
    locks: list = []
    current = targets[0] if targets else Path()
    try:
        for folder in dict.fromkeys(t.parent for t in targets):
            current = folder
            if make_parents:
                folder.mkdir(parents=True, exist_ok=True)
            if folder.is_dir():
                recover(folder, notify)
                locks.append(take(folder / f".ws-{token}.lock"))
        for target, writer in zip(targets, writers, strict=True):
            current = target
            temps.append(_temporary(target, token))
            writer(temps[-1])
            os.chmod(temps[-1], ordinary_mode())
        for target in targets:
            current = target
            backups.append(_backup(target, working(target, token, "old")))
        journal = journal_text(targets, temps, backups)
        for folder in dict.fromkeys(t.parent for t in targets):  # the set, before any swap
            current = folder / f".ws-{token}.json"
            journals.append(Path(f"{current}.part"))
            journals[-1].write_text(journal, encoding="utf-8")
            os.replace(journals[-1], current)
            journals[-1] = current
        for i, (target, tmp) in enumerate(zip(targets, temps, strict=True)):
            current = target
            os.replace(tmp, target)
            swapped.append(i)
    except BaseException as exc:
        for i in reversed(swapped):
            with contextlib.suppress(OSError):
                if backups[i] is None:
                    targets[i].unlink()
                else:
                    os.replace(backups[i], targets[i])
        _discard(temps + [b for b in backups if b is not None] + journals)
        _unlock(locks)
        if isinstance(exc, OSError):
            raise WriteSetError(exc.errno, _message(current, targets, exc), str(current)) from None
        raise
    _discard([b for b in backups if b is not None] + journals)
    _unlock(locks)
    return targets


def _unlock(locks: list) -> None:
    for held in locks:
        drop(held)


def _message(current: Path, targets: list[Path], exc: OSError) -> str:
    if len(targets) == 1:
        left = "it is left as it was" if current.exists() else "nothing was written"
    else:
        names = ", ".join(t.name for t in targets)
        left = f"none of {names} was written (the previous files are left as they were)"
    return f"cannot write {current}: {_cause(exc)}; {left}"


def write_files(
    out: Mapping[str | os.PathLike[str], str | bytes | Writer],
    make_parents: bool = False,
    notify: Notify = say,
) -> list[Path]:
    """:func:`write_set` of texts (UTF-8), bytes or writers."""
    return write_set({p: _writer(v) for p, v in out.items()}, make_parents, notify)


def _writer(value: str | bytes | Writer) -> Writer:
    if isinstance(value, str):
        return text_writer(value)
    if isinstance(value, bytes):
        return lambda path: Path(path).write_bytes(value)
    return value


def _discard(paths: list[Path]) -> None:
    for path in paths:
        with contextlib.suppress(OSError):
            path.unlink()


STAGE_PREFIX = ".staged-"


@contextlib.contextmanager
def staged(folder: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield an empty hidden folder inside ``folder`` to write files into; when the block
    ends, its files are written into ``folder`` as one set (:func:`write_set`). On any
    exception nothing in ``folder`` changes (an OSError comes out as :class:`WriteSetError`).
    The staging folder is held locked (``<stage>.lock``) while in use; unheld ones, left by
    killed processes, are removed first."""
    target = Path(folder)
    held = None
    try:
        target.mkdir(parents=True, exist_ok=True)
        for stale in target.glob(f"{STAGE_PREFIX}*"):
            _remove_if_unheld(stale)
        stage = target / f"{STAGE_PREFIX}{secrets.token_hex(4)}"
        held = take(lock_path(stage))  # held before the folder exists: never taken as stale
        stage.mkdir()
    except OSError as exc:
        drop(held)
        raise WriteSetError(exc.errno, _staged_message(target, exc), str(target)) from None
    try:
        try:
            yield stage
        except OSError as exc:
            if isinstance(exc, WriteSetError):
                raise
            raise WriteSetError(exc.errno, _staged_message(target, exc), exc.filename) from None
        write_set({target / p.name: _mover(p) for p in sorted(stage.iterdir()) if p.is_file()})
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        drop(held)


def _staged_message(folder: Path, exc: OSError) -> str:
    return f"cannot write into {folder}: {_cause(exc)}; none of its files was changed"


def _mover(src: Path) -> Writer:
    return lambda tmp: os.replace(src, tmp)


def _remove_if_unheld(path: Path) -> None:
    """A killed process's staging folder (or the lock file it left): removed when no live
    process holds its lock."""
    if path.name.endswith(".lock"):
        if not path.with_suffix("").exists():
            with contextlib.suppress(OSError):
                if is_free(path):
                    path.unlink()
        return
    held = take(lock_path(path))
    if held is None:
        return  # in use by a live process
    shutil.rmtree(path, ignore_errors=True)
    drop(held)
