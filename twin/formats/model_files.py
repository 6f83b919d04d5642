"""Where the model commands (pkm-calib from-urdf, from-dh, error-model) write: never over a
user's file without ``--force``, the model and its error model as one set, and a file error
said with the file and its cause."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from twin.exceptions import ModelError


def out_files(out_dir: str | os.PathLike[str], names: list[str], force: bool) -> list[Path]:
    """``out_dir/<name>`` for each name; refuses (ModelError) an ``out_dir`` that is a file,
    and existing files unless ``force``."""
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise ModelError(f"--out-dir {folder} is a file, not a folder: name a folder")
    paths = [folder / n for n in names]
    for p in paths:
        if p.is_dir():
            raise ModelError(f"{p} is a folder: it cannot be replaced by a file")
    existing = [str(p) for p in paths if p.exists()]
    if existing and not force:
        raise ModelError(
            f"{', '.join(existing)} exist(s) (a model of yours?): nothing written; give "
            "another --out-dir or --name, or --force to replace"
        )
    return paths


def write_model_files(files: dict[Path, str]) -> bool:
    """Write ``files`` as one set; False (the error printed, naming the file) on an OSError."""
    from common.write_set import write_files  # the project's one writer of file sets

    try:
        write_files(files, make_parents=True)
    except OSError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return False
    return True
