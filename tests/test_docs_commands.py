"""Every command block of README.md and docs/*.md runs as written.

A fenced block's info string says what it is: ```sh (a user runs it as it stands, from the
repository's root, on models/ and the real data in ../shared/data), ```sh template (it holds
placeholders such as M.xml or readings.csv, or runs make, which would recurse into the test
run), ```python (runs as it stands with the venv's Python), ```text right after a runnable
block (what it prints: each line's pieces between "..." must appear in its output). The
runnable blocks of one file run in order in one clone-like folder (models/ copied, .venv/bin/
pointing at this Python and this checkout, ../shared beside it), so a block may use the files
an earlier one wrote, as a reader following the page would.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL_WORDS = {"sh", "bash", "shell", "console", "zsh"}
KNOWN = {"sh", "sh template", "python", "python template", "text", "toml", "json", "csv"}
FENCE = re.compile(r"^(?P<indent> *)```(?P<info>[^`]*)$")
# where a clone finds the shipped real data: beside it (CI), else this machine's copy
SHARED = [ROOT.parent / "shared", Path("/work/shared")]
# the README's promise: a short page, the manual lives in docs/guide.md
README_MAX_WORDS = 600


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    info: str
    body: str

    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file, indented ones (in lists) included."""
    found, lines, i = [], path.read_text(encoding="utf-8").split("\n"), 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        indent, start, body = len(m["indent"]), i, []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            body.append(lines[i][indent:] if lines[i][:indent].isspace() else lines[i])
            i += 1
        found.append(Block(path, start + 1, m["info"].strip(), "\n".join(body) + "\n"))
        i += 1
    return found


ALL = [b for path in DOCS for b in blocks(path)]


def runnable(block: Block) -> bool:
    return block.info in ("sh", "python")


def shared_data() -> Path | None:
    for place in SHARED:
        if (place / "data" / "real_ur5" / "real_ur5.csv").is_file():
            return place
    return None


def test_every_block_says_what_it_is() -> None:
    assert ALL, "no code blocks found"
    for b in ALL:
        assert b.info in KNOWN, f"{b.where()}: info string {b.info!r} (one of {sorted(KNOWN)})"
        if b.info == "sh":
            # make targets set up the venv and run the suite: never inside the docs test
            assert not re.search(r"(^|\s)make\s", b.body), f"{b.where()}: make in a runnable block"
            for cmd in re.findall(r"^\s*(\S+)", b.body, flags=re.M):
                assert cmd != "pkm-calib", f"{b.where()}: say the venv (.venv/bin/pkm-calib)"


def test_commands_name_real_subcommands() -> None:
    """Templates cannot run, but the subcommands they name must exist."""
    from calib.cli import build_parser
    from pkm_calib.command import MODEL_COMMANDS, SCENARIO_COMMANDS

    calib_subs = set(build_parser()._subparsers._group_actions[0].choices)
    known = calib_subs | set(MODEL_COMMANDS) | set(SCENARIO_COMMANDS)
    for b in ALL:
        if b.info.startswith("sh"):
            for sub in re.findall(r"pkm-calib (\w[\w-]*)", b.body):
                assert sub in known, f"{b.where()}: no subcommand {sub!r}"


def test_readme_is_short_and_links_resolve() -> None:
    words = len((ROOT / "README.md").read_text(encoding="utf-8").split())
    assert words <= README_MAX_WORDS, f"README.md has {words} words (the guide is docs/guide.md)"
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
            if "://" not in target:
                assert (path.parent / target).exists(), f"{path.name}: broken link {target}"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for doc in ("docs/guide.md", "docs/architecture.md", "docs/recordings.md"):
        assert f"]({doc})" in readme, f"README.md does not link {doc}"


def clone_like(tmp: Path, shared: Path) -> Path:
    """A folder laid out as a user's clone: models/, .venv/bin/{pkm-calib,python} running
    this Python on this checkout, ../shared beside it."""
    clone = tmp / "clone"
    shutil.copytree(ROOT / "models", clone / "models")
    (tmp / "shared").symlink_to(shared, target_is_directory=True)
    venv_bin = clone / ".venv" / "bin"
    venv_bin.mkdir(parents=True)
    scripts = {
        "python": f'exec "{sys.executable}" "$@"\n',
        "pkm-calib": f'exec "{sys.executable}" -m pkm_calib.command "$@"\n',
    }
    for name, line in scripts.items():
        script = venv_bin / name
        script.write_text("#!/bin/sh\n" + line, encoding="utf-8")
        script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return clone


def check_output(block: Block, printed: Block | None, out: str) -> None:
    if printed is None or printed.info != "text":
        return
    flat = " ".join(out.split())
    for line in printed.body.splitlines():
        for piece in (p.strip() for p in line.split("...")):
            if piece:
                assert " ".join(piece.split()) in flat, (
                    f"{printed.where()}: {piece!r} not printed by {block.where()}:\n{out}"
                )


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_runnable_blocks_run(path: Path, tmp_path: Path) -> None:
    page = blocks(path)
    todo = [i for i, b in enumerate(page) if runnable(b)]
    if not todo:
        return
    shared = shared_data()
    if shared is None:
        pytest.skip("the shipped real data (../shared/data) are not beside this checkout")
    clone = clone_like(tmp_path, shared)
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["MPLBACKEND"] = "Agg"
    for i in todo:
        b = page[i]
        if b.info == "sh":
            argv = ["bash", "-euo", "pipefail", "-c", b.body]
        else:
            argv = [str(clone / ".venv" / "bin" / "python"), "-c", b.body]
        run = subprocess.run(
            argv, cwd=clone, env=env, capture_output=True, text=True, timeout=300, check=False
        )
        assert run.returncode == 0, (
            f"{b.where()} exited {run.returncode}:\n{run.stdout}\n{run.stderr}"
        )
        check_output(b, page[i + 1] if i + 1 < len(page) else None, run.stdout)
