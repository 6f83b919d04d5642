"""A scenario's results folder under faults: a full disk, a read-only or immutable folder,
two runs swapping at once, a run killed at any point. Each run either puts its folder in place
whole or leaves the previous one and exits 2 naming the cause; the next run recovers what a
killed run left and says so. Studies are stubs (no computation)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from fault_fs import (
    ENOSPC,
    EPERM,
    EROFS,
    immutable,
    in_small_fs,
    os_error,
    stub_run_argv,
)

from scenarios import results_folder, runner
from scenarios.__main__ import main as cli
from scenarios.recording.recorder import Recorder
from scenarios.results_folder import recover, replaced_whole
from scenarios.runner import run_scenario

NAME = "undeclared_effect"


def _stub(monkeypatch, behaviour) -> None:
    def run(scenario, out_dir, progress, recorder):
        return behaviour(out_dir)

    monkeypatch.setattr(runner, "_study", lambda name: (run, lambda s: f"# {s['run']}\n"))


def _writes(run_id: int, text: str = "data"):
    def behaviour(out_dir: Path) -> dict:
        (out_dir / "data.txt").write_text(f"{text} {run_id}\n")
        return {"scenario": NAME, "run": run_id}

    return behaviour


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _hidden(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir() if p.name.startswith("."))


@pytest.fixture
def earlier(tmp_path, monkeypatch) -> tuple[Path, dict[str, bytes]]:
    """results/<name> of an earlier run, with a sweep/ folder beside its files."""
    _stub(monkeypatch, _writes(1))
    _, out_dir = run_scenario(NAME, tmp_path, quiet=True, record=False)
    (out_dir / "sweep").mkdir()
    (out_dir / "sweep" / "summary.json").write_text("{}\n")
    return out_dir, _snapshot(out_dir)


# ------------------------------------------------------------------ faults, as fakes


@pytest.mark.parametrize(
    ("where", "code", "cause"),
    [
        ("mkdtemp", EROFS, "Read-only file system"),  # point 3: a read-only results root
        ("mkdtemp", EPERM, "Operation not permitted"),  # point 4: an immutable results root
        ("rename_out", EPERM, "Operation not permitted"),  # point 4: results/<name> immutable
        ("study", ENOSPC, "No space left on device"),  # point 5: the disk fills during the run
        ("rename_in", ENOSPC, "No space left on device"),  # the last rename fails
    ],
)
def test_file_errors_exit_2_naming_the_cause_and_leave_the_earlier_run(
    earlier, tmp_path, monkeypatch, capsys, where, code, cause
):
    out_dir, before = earlier
    _stub(monkeypatch, _writes(2))
    if where == "mkdtemp":

        def refused(*args, **kwargs):
            raise os_error(code, tmp_path)

        monkeypatch.setattr(results_folder.tempfile, "mkdtemp", refused)
    elif where == "study":

        def fills(work):
            raise os_error(code)

        _stub(monkeypatch, fills)
    else:
        rename = os.rename

        def failing(src, dst):
            moving_out = Path(src) == out_dir and ".old-" in str(dst)
            moving_in = Path(dst) == out_dir and ".complete-" in str(src)
            if (where == "rename_out" and moving_out) or (where == "rename_in" and moving_in):
                raise os_error(code, src)
            rename(src, dst)

        monkeypatch.setattr(results_folder.os, "rename", failing)
    assert cli(["run", NAME, "--results", str(tmp_path), "--quiet", "--no-record"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and cause in err and "Traceback" not in err
    assert "left as it was" in err
    assert _snapshot(out_dir) == before  # the sweep/ folder too, byte for byte
    assert _hidden(tmp_path) == []


def test_two_runs_swapping_at_once_both_finish_whole(earlier, tmp_path, monkeypatch):
    """Point 2: run B reaches its swap while run A is between its renames. Each swap holds
    the results root's lock, so B waits; both succeed, the folder is B's run whole."""
    out_dir, _ = earlier
    in_window = threading.Event()
    rename = os.rename

    def slow(src, dst):
        rename(src, dst)
        if Path(src) == out_dir and threading.current_thread().name == "A":
            in_window.set()  # A has moved the old folder away and not yet put its own in
            time.sleep(0.3)

    monkeypatch.setattr(results_folder.os, "rename", slow)

    def study(work):
        run_id = 2 if threading.current_thread().name == "A" else 3
        if run_id == 3:
            assert in_window.wait(10)
        return _writes(run_id)(work)

    _stub(monkeypatch, study)
    errors: list[BaseException] = []

    def go() -> None:
        try:
            run_scenario(NAME, tmp_path, quiet=True, record=False)
        except BaseException as exc:  # reported by the assertion below
            errors.append(exc)

    threads = [threading.Thread(target=go, name=n) for n in ("A", "B")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert errors == []
    assert (out_dir / "data.txt").read_text() == "data 3\n"
    assert json.loads((out_dir / "summary.json").read_text())["run"] == 3
    assert (out_dir / "sweep" / "summary.json").is_file()
    assert _hidden(tmp_path) == []


# ------------------------------------------------------------- leftovers of killed runs


def _leftover(root: Path, kind: str, run_id: int, age_s: float) -> Path:
    folder = root / f".{NAME}.{kind}-{run_id:08x}"
    folder.mkdir()
    (folder / "data.txt").write_text(f"data {run_id}\n")
    if kind != "partial":
        (folder / "summary.json").write_text(json.dumps({"run": run_id}))
    stamp = time.time() - age_s
    for p in (folder / "summary.json", folder / "data.txt", folder):
        if p.exists():
            os.utime(p, (stamp, stamp))
    return folder


@pytest.mark.parametrize(
    ("kept", "made", "expect_run", "said"),
    [
        # killed mid-run: an unfinished folder beside the earlier results
        (True, [("partial", 9, 5)], 1, "removed 1 unfinished run"),
        # killed between the two renames: no results/<name>, the old and the new run hidden
        (False, [("old", 1, 60), ("complete", 2, 30)], 2, "was missing"),
        # killed after renaming the finished run, before moving the earlier one away
        (True, [("complete", 2, -30)], 2, "held an older run"),
        # killed after the swap, before deleting the old folder
        (True, [("old", 0, 600)], 1, "removed 1 replaced run"),
    ],
)
def test_next_run_recovers_what_a_killed_run_left(earlier, tmp_path, kept, made, expect_run, said):
    out_dir, _ = earlier
    sweep = (out_dir / "sweep").rename(tmp_path / "sweep_aside")
    if not kept:
        out_dir.rename(tmp_path / f".{NAME}.old-00000001")
        made = [m for m in made if m[0] != "old"]
        os.utime(tmp_path / f".{NAME}.old-00000001" / "summary.json", (1, 1))
    else:
        os.utime(out_dir / "summary.json", (time.time() - 10,) * 2)
    for kind, run_id, age in made:
        folder = _leftover(tmp_path, kind, run_id, age)
        if kind == "complete":  # the sweep/ folder travelled with the finished run
            sweep.rename(folder / "sweep")
    if sweep.exists():
        sweep.rename(out_dir / "sweep")
    notes: list[str] = []
    recover(out_dir, notes.append)
    assert any(said in n for n in notes), notes
    assert json.loads((out_dir / "summary.json").read_text())["run"] == expect_run
    assert (out_dir / "sweep" / "summary.json").is_file()
    assert _hidden(tmp_path) == []


def test_a_live_runs_folder_is_not_taken_for_a_leftover(tmp_path):
    out_dir = tmp_path / NAME
    notes: list[str] = []
    with replaced_whole(out_dir, notes.append) as work:
        recover(out_dir, notes.append)  # another run starting now
        assert work.is_dir() and notes == []
        (work / "summary.json").write_text("{}")
    assert (out_dir / "summary.json").is_file() and _hidden(tmp_path) == []


def _child(tmp_path: Path, pause_s: float, kill_at: str | None = None) -> subprocess.Popen:
    """A scenario run in a child process (stub study); ``kill_at="between renames"`` makes
    it SIGKILL itself right after moving the earlier results away."""
    argv = stub_run_argv(tmp_path, 1000, pause_s)
    if kill_at == "between renames":
        hook = (
            "import os, signal\nfrom scenarios import results_folder\n_r = os.rename\n"
            "def _k(s, d):\n    _r(s, d)\n    if '.old-' in str(d):\n"
            "        os.kill(os.getpid(), signal.SIGKILL)\n"
            "results_folder.os.rename = _k\n"
        )
        argv[2] = hook + argv[2]
    return subprocess.Popen(
        argv,
        cwd=Path(__file__).resolve().parent.parent,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def test_sigkill_mid_run_and_between_renames_then_the_next_run_recovers(
    earlier, tmp_path, monkeypatch, capsys
):
    """Point 6 with real SIGKILLs: a run killed in its study leaves a .partial-* folder; one
    killed between the two renames leaves no results/<name>. The next run cleans the first,
    puts the newest complete run in place for the second, and says so."""
    out_dir, before = earlier
    child = _child(tmp_path, pause_s=30)
    deadline = time.time() + 60
    while not any(".partial-" in n for n in _hidden(tmp_path)) and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)  # the child is in its study's pause
    child.send_signal(signal.SIGKILL)
    child.wait(30)
    assert any(".partial-" in n for n in _hidden(tmp_path))
    assert _snapshot(out_dir) == before
    killed = _child(tmp_path, pause_s=0, kill_at="between renames")
    assert killed.wait(60) == -signal.SIGKILL
    assert "removed 1 unfinished run" in killed.stderr.read()  # the first one's folder
    assert not out_dir.exists()
    hidden = _hidden(tmp_path)
    assert any(".old-" in n for n in hidden) and any(".complete-" in n for n in hidden)
    _stub(monkeypatch, _writes(5))
    assert cli(["run", NAME, "--results", str(tmp_path), "--quiet", "--no-record"]) == 0
    err = capsys.readouterr().err
    assert f"{out_dir} was missing" in err and "put in place the newest complete run" in err
    assert (out_dir / "data.txt").read_text() == "data 5\n"
    assert (out_dir / "sweep" / "summary.json").is_file()
    assert _hidden(tmp_path) == []


# ------------------------------------------------------- real small and read-only disks


def test_full_small_disk_exits_2_and_leaves_nothing(tmp_path):
    """Point 5 on a real 256 kB filesystem: the run's data does not fit."""
    mount = tmp_path / "disk"
    done = in_small_fs(mount, stub_run_argv(mount / "results", 400_000), size="256k")
    assert done.returncode == 2, done.stderr
    assert "No space left on device" in done.stderr and "Traceback" not in done.stderr
    assert "left as it was" in done.stderr


def test_read_only_results_root_exits_2(tmp_path):
    mount = tmp_path / "disk"
    done = in_small_fs(mount, stub_run_argv(mount / "results", 10), read_only=True)
    assert done.returncode == 2, done.stderr
    assert "Read-only file system" in done.stderr and "Traceback" not in done.stderr


def test_immutable_results_folder_exits_2(earlier, tmp_path, monkeypatch, capsys):
    out_dir, before = earlier
    _stub(monkeypatch, _writes(2))
    with immutable(out_dir):
        assert cli(["run", NAME, "--results", str(tmp_path), "--quiet", "--no-record"]) == 2
    err = capsys.readouterr().err
    assert "Operation not permitted" in err and "Traceback" not in err
    assert _snapshot(out_dir) == before and _hidden(tmp_path) == []


def test_recording_on_a_full_disk_raises_instead_of_hanging(tmp_path, monkeypatch):
    """The .rrd is written by Python (rerun encodes it in memory): a full disk is an
    OSError like any other, not a stalled rerun writer thread."""
    import common.atomic_files as atomic_files

    def full(*args, **kwargs):
        raise os_error(ENOSPC)

    monkeypatch.setattr(atomic_files.os, "fsync", full)
    with pytest.raises(OSError, match="No space left"), Recorder(tmp_path / "r.rrd", "t") as rec:
        rec.log_text("notes", "# text")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    with Recorder(tmp_path / "r.rrd", "t") as rec:
        rec.log_text("notes", "# text")
    assert (tmp_path / "r.rrd").stat().st_size > 0


def test_recording_on_a_real_full_disk_exits_instead_of_hanging(tmp_path):
    """The case that hung for over 600 s: rerun's writer after "No space left on device"."""
    mount = tmp_path / "disk"
    script = (
        "import sys\nfrom scenarios.recording.recorder import Recorder\n"
        "try:\n    with Recorder(__import__('pathlib').Path(sys.argv[1]), 't') as rec:\n"
        "        for i in range(200):\n            rec.log_text(f'notes/{i}', 'x' * 4000)\n"
        "except OSError as exc:\n    print(exc.strerror, file=sys.stderr)\n    sys.exit(2)\n"
    )
    done = in_small_fs(
        mount, [sys.executable, "-c", script, str(mount / "r.rrd")], "128k", timeout=60
    )
    assert done.returncode == 2, done.stderr
    assert "No space left on device" in done.stderr


def test_final_paths_name_the_run_folder_by_its_final_name():
    """A ``.<name>.partial-XXXXXXXX`` component (mkdtemp's 8 characters) becomes ``<name>``
    wherever a path starts; anything else is left as it was."""
    from scenarios.results_folder import final_paths, final_paths_in

    logged = (
        "$ pkm-calib identify --data /r/.serial_arm.partial-5854nu2p/d/a.csv "
        "--out=/r/.x.y.partial-ab_d1234/r.json"
    )
    assert (
        final_paths(logged)
        == "$ pkm-calib identify --data /r/serial_arm/d/a.csv --out=/r/x.y/r.json"
    )
    said = "error: '.liu.partial-ue0jnw48/loop/diagnosis.json': bad\n.a.partial-abcdefgh"
    assert final_paths(said) == "error: 'liu/loop/diagnosis.json': bad\na"
    for kept in ("/r/.a.partial-abc/x", "/r/b.a.partial-abcdefgh/x", "/r/.a.complete-abcdefgh"):
        assert final_paths(kept) == kept
    nested = {"k": ["/r/.a.partial-abcdefgh/f", 1.5, ("/r/.a.partial-abcdefgh",)], "n": None}
    assert final_paths_in(nested) == {"k": ["/r/a/f", 1.5, ("/r/a",)], "n": None}


def test_name_final_paths_rewrites_the_text_files_only(tmp_path):
    from scenarios.results_folder import name_final_paths

    run = tmp_path / ".arm.partial-abcd1234"
    (run / "sub").mkdir(parents=True)
    said = f'{{"data": "{run}/d.csv"}}'
    (run / "r.json").write_text(said)
    (run / "sub" / "c.log").write_text(f"$ pkm-calib verify --out {run}/v.json\n")
    (run / "ok.md").write_text("nothing to change")
    (run / "x.rrd").write_bytes(said.encode())  # a recording is no text: left as it was
    changed = name_final_paths(run)
    assert [p.name for p in changed] == ["r.json", "c.log"]
    assert (run / "r.json").read_text() == f'{{"data": "{tmp_path}/arm/d.csv"}}'
    assert (
        run / "sub" / "c.log"
    ).read_text() == f"$ pkm-calib verify --out {tmp_path}/arm/v.json\n"
    assert (run / "x.rrd").read_bytes() == said.encode()
