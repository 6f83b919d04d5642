"""Every ``--out`` of the calibration's command line is written whole or not at all: on a
full disk (a real small filesystem where one can be made, else a fake raising the same
OSError) the command exits 2 naming the cause and the previous files stay byte for byte;
``verify --out v.json`` writes v.json, v.csv and v.png together or none of them."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from fault_fs import ENOSPC, in_small_fs, os_error

import common.write_set as write_set_module
from calib.cli.commands import main
from calib.data import write_dataset
from common.write_set import WriteSetError, write_files
from scenarios.twin_datasets import measured_dataset
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models/hexapod_rrrprr.xml"
ERRORS = ROOT / "models/hexapod_rrrprr.params.toml"
SET = ("v.json", "v.csv", "v.png")


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Twin readings of the hexapod (Table 2 truth, 5 um noise) and their result file."""
    tmp = tmp_path_factory.mktemp("writes")
    nominal = Mechanism.from_xml(MODEL)
    params = load_parameter_set(ERRORS, nominal.model)
    truth_values = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = Mechanism(params.inject(nominal.model, truth_values), name=nominal.name)
    rng = np.random.default_rng(8)
    poses, commands = random_poses(nominal, 20, rng)
    tracker = Tracker(noise=TrackerNoise("gaussian", 5e-6, 0.0))
    data = write_dataset(
        measured_dataset(truth, commands, poses, "calibration", tracker, rng), tmp / "d.csv"
    )
    result = tmp / "r.json"
    assert main(_identify(data, result)) == 0
    return {"data": data, "result": result, "dir": tmp}


def _common(data: Path) -> list[str]:
    return ["--model", str(MODEL), "--errors", str(ERRORS), "--data", str(data)]


def _identify(data: Path, out: Path) -> list[str]:
    return ["identify", *_common(data), "--sigma-mm", "0.005", "--out", str(out)]


def _verify(files: dict[str, Path], out: Path) -> list[str]:
    return ["verify", *_common(files["data"]), "--result", str(files["result"]), "--out", str(out)]


def _previous(folder: Path) -> dict[str, bytes]:
    folder.mkdir(exist_ok=True)
    old = {name: f"previous {name}\n".encode() for name in SET}
    for name, data in old.items():
        (folder / name).write_bytes(data)
    return old


def _contents(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


@pytest.mark.parametrize("failing", SET)
def test_verify_out_on_a_full_disk_writes_none_of_the_set(
    files, tmp_path, monkeypatch, capsys, failing
):
    """Point 5 (fake): the disk fills while one file of the three is written."""
    old = _previous(tmp_path)
    real = write_set_module._temporary

    def temporary(target: Path, token: str) -> Path:
        if target.name == failing:
            raise os_error(ENOSPC, target)
        return real(target, token)

    monkeypatch.setattr(write_set_module, "_temporary", temporary)
    assert main(_verify(files, tmp_path / "v.json")) == 2
    err = capsys.readouterr().err
    assert f"cannot write {tmp_path / failing}: No space left on device" in err
    assert "none of v.json, v.csv, v.png was written" in err and "Traceback" not in err
    assert _contents(tmp_path) == old


def test_verify_out_writes_the_whole_set_over_the_previous_one(files, tmp_path, capsys):
    _previous(tmp_path)
    assert main(_verify(files, tmp_path / "v.json")) == 0
    got = _contents(tmp_path)
    assert sorted(got) == sorted(SET)
    assert got["v.png"].startswith(b"\x89PNG") and b'"after"' in got["v.json"]


def test_verify_out_on_a_real_full_disk(files, tmp_path):
    """Point 5 on a real 48 kB filesystem already holding a previous set: the new JSON and
    CSV fit, the PNG does not; the previous three files are left as they were."""
    mount = tmp_path / "disk"
    stage = tmp_path / "stage"
    old = _previous(stage)
    copy = " && ".join(f"cp {stage / n} {mount / n}" for n in SET)
    argv = [sys.executable, "-m", "calib", *_verify(files, mount / "v.json")]
    script = f"{copy} && {' '.join(argv)}; code=$?; cat {mount}/v.* > {tmp_path}/after; exit $code"
    done = in_small_fs(mount, ["sh", "-c", script], size="48k")
    assert done.returncode == 2, done.stderr
    assert "No space left on device" in done.stderr and "Traceback" not in done.stderr
    assert (tmp_path / "after").read_bytes() == b"".join(old[n] for n in sorted(SET))


def test_identify_out_on_a_full_disk_exits_2_and_keeps_the_previous_file(
    files, tmp_path, monkeypatch, capsys
):
    out = tmp_path / "r.json"
    out.write_text("previous result\n")

    def full(fd):
        raise os_error(ENOSPC)

    monkeypatch.setattr(write_set_module.os, "fsync", full)
    assert main(_identify(files["data"], out)) == 2
    err = capsys.readouterr().err
    assert f"cannot write {out}: No space left on device; it is left as it was" in err
    assert out.read_text() == "previous result\n" and os.listdir(tmp_path) == ["r.json"]


def test_a_failed_swap_puts_the_replaced_files_back(tmp_path, monkeypatch):
    """The second of three renames fails (after the first file was replaced): the first is
    restored from its link and the new third file, which had no predecessor, never appears."""
    (tmp_path / "a.txt").write_text("old a\n")
    (tmp_path / "b.txt").write_text("old b\n")
    replace = os.replace

    def failing(src, dst):
        if Path(dst).name == "b.txt":
            raise os_error(ENOSPC, dst)
        replace(src, dst)

    monkeypatch.setattr(write_set_module.os, "replace", failing)
    with pytest.raises(WriteSetError, match=r"none of a\.txt, b\.txt, c\.txt was written"):
        write_files({tmp_path / n: f"new {n}\n" for n in ("a.txt", "b.txt", "c.txt")})
    monkeypatch.undo()
    assert _contents(tmp_path) == {"a.txt": b"old a\n", "b.txt": b"old b\n"}


@pytest.mark.parametrize(
    ("command", "out", "message"),
    [
        ("verify", "v.csv", "a file written beside it would take its own name"),
        ("identify", "d.csv", "would overwrite an input file"),
        ("verify", "d.csv.json", "would overwrite an input file"),
        ("identify", ".", "is a folder"),
    ],
)
def test_out_that_would_overwrite_an_input_is_refused_first(files, capsys, command, out, message):
    before = files["data"].read_bytes()
    target = files["dir"] / out
    argv = _verify(files, target) if command == "verify" else _identify(files["data"], target)
    assert main(argv) == 2
    assert message in capsys.readouterr().err
    assert files["data"].read_bytes() == before


def test_staged_files_go_in_as_a_set_or_not_at_all(tmp_path):
    """What a sweep's aggregate (figures, recording, summary, report) is written through."""
    from common.write_set import STAGE_PREFIX, staged

    (tmp_path / "summary.json").write_text("previous\n")
    with (
        pytest.raises(WriteSetError, match="none of its files was changed"),
        staged(tmp_path) as stage,
    ):
        (stage / "summary.json").write_text("new\n")
        (stage / "figure.png").write_bytes(b"png")
        raise os_error(ENOSPC, stage / "report.md")  # the disk fills at the third file
    assert _contents(tmp_path) == {"summary.json": b"previous\n"}
    killed = tmp_path / f"{STAGE_PREFIX}left"  # a killed process's staging folder
    killed.mkdir()
    (killed / "x").write_text("x")
    with staged(tmp_path) as stage:
        (stage / "summary.json").write_text("new\n")
        (stage / "report.md").write_text("report\n")
    assert _contents(tmp_path) == {"summary.json": b"new\n", "report.md": b"report\n"}


def test_sweep_on_a_full_disk_exits_2(tmp_path, monkeypatch, capsys):
    import scenarios.sweep.runner as sweep_module
    from scenarios.__main__ import main as scenarios_main

    def full(*args, **kwargs):
        raise WriteSetError(ENOSPC, "cannot write into x: No space left on device; none", "x")

    monkeypatch.setattr(sweep_module, "sweep", full)
    argv = ["sweep", "undeclared_effect", "--seeds", "1", "--engine", "local", "--quiet"]
    assert scenarios_main([*argv, "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: cannot write into x: No space left on device")


def test_dh_table_on_a_full_disk_writes_neither_file(tmp_path, monkeypatch, capsys):
    """``python -m twin.formats.dh_table --out-dir``: the MJCF and its error model, both or
    neither."""
    from twin.formats.dh_table import main as dh_main

    real = write_set_module._temporary

    def temporary(target: Path, token: str) -> Path:
        if target.name.endswith(".params.toml"):
            raise os_error(ENOSPC, target)
        return real(target, token)

    monkeypatch.setattr(write_set_module, "_temporary", temporary)
    table = ROOT / "models/arm6r.mdh.csv"
    assert dh_main([str(table), "--name", "arm", "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "No space left on device; none of arm.xml, arm.params.toml was written" in err
    assert list(tmp_path.iterdir()) == []


def test_verify_as_is_on_a_full_disk_writes_neither_file(files, tmp_path, monkeypatch, capsys):
    """``verify`` without ``--result`` (a model as it is) writes v.json and v.csv together."""
    old = {n: f"previous {n}\n".encode() for n in ("v.json", "v.csv")}
    for name, data in old.items():
        (tmp_path / name).write_bytes(data)
    real = write_set_module._temporary

    def temporary(target: Path, token: str) -> Path:
        if target.name == "v.csv":
            raise os_error(ENOSPC, target)
        return real(target, token)

    monkeypatch.setattr(write_set_module, "_temporary", temporary)
    argv = ["verify", "--model", str(MODEL), "--data", str(files["data"])]
    assert main([*argv, "--out", str(tmp_path / "v.json")]) == 2
    assert "none of v.json, v.csv was written" in capsys.readouterr().err
    assert _contents(tmp_path) == old
