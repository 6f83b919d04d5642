"""No lost files (issue 37): a set of files killed midway is rolled forward or back by the
next write into its folder, its leftovers removed and said; the model commands never replace
a user's files without --force; bad URDFs, a result hand-edited to an implausible estimate,
a result path that is no file and a full disk under export each exit 2 naming the cause."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fault_fs import ENOSPC, os_error
from to_machine_support import MODELS, plausible_values, result_file

from calib.cli import main as calib_main
from calib.fit import model_from_files
from common.write_set import write_files
from twin.formats.dh_table import main as dh_main
from twin.formats.error_model import main as error_model_main
from twin.formats.from_urdf import main as urdf_main

ROOT = Path(__file__).resolve().parent.parent
SET = ("v.json", "v.csv", "v.png")
OLD = {n: f"previous {n}\n".encode() for n in SET}
NEW = {n: f"new {n}\n".encode() for n in SET}

# a child that writes the new set through write_set and is SIGKILLed at the k-th rename of
# one of the set's files (k = 1..3: the swaps; k = 0: while the third new file is written)
KILLED_WRITE = """
import os, signal, sys
from pathlib import Path
from common.write_set import write_files
out, k = Path(sys.argv[1]), int(sys.argv[2])
real, seen = os.replace, []
def replace(src, dst):
    if Path(dst).name in {names!r}:
        seen.append(dst)
        if len(seen) == k:
            os.kill(os.getpid(), signal.SIGKILL)
    real(src, dst)
os.replace = replace
def dies(tmp):
    Path(tmp).write_bytes(b"half")
    os.kill(os.getpid(), signal.SIGKILL)
files = {{out / n: (dies if k == 0 and n == "v.png" else f"new {{n}}\\n") for n in {names!r}}}
write_files(files)
"""


def _folder(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


def _killed(out: Path, k: int) -> None:
    for name, data in OLD.items():
        (out / name).write_bytes(data)
    script = KILLED_WRITE.format(names=SET)
    done = subprocess.run([sys.executable, "-c", script, str(out), str(k)], cwd=ROOT, timeout=60)
    assert done.returncode == -signal.SIGKILL
    assert any(p.name.startswith(".") for p in out.iterdir())  # it left working files


@pytest.mark.parametrize("k", [1, 2, 3])
def test_a_set_killed_while_swapped_in_is_rolled_forward(tmp_path, k):
    """Killed before its k-th swap, the folder holds a mixed set (k - 1 new files); the next
    write into the folder completes the killed set first (its journal lists it), then writes
    its own file, and says so."""
    _killed(tmp_path, k)
    mixed = _folder(tmp_path)
    assert [mixed[n] == NEW[n] for n in SET] == [i < k - 1 for i in range(3)]
    notes: list[str] = []
    write_files({tmp_path / "other.txt": "other\n"}, notify=notes.append)
    assert _folder(tmp_path) == {**NEW, "other.txt": b"other\n"}  # nothing hidden is left
    assert len(notes) == 1 and "completed the set" in notes[0]
    assert all(n in notes[0] for n in SET)


def test_a_set_killed_before_any_swap_is_rolled_back(tmp_path):
    _killed(tmp_path, 0)
    notes: list[str] = []
    write_files({tmp_path / "other.txt": "other\n"}, notify=notes.append)
    assert _folder(tmp_path) == {**OLD, "other.txt": b"other\n"}
    assert len(notes) == 1 and "the files there are as they were" in notes[0]


def test_the_next_command_says_what_it_recovered(tmp_path, capsys):
    """The note reaches the user of the next command writing there (stderr, 'note: ')."""
    _killed(tmp_path, 2)
    table = str(MODELS / "arm6r.mdh.csv")
    assert dh_main([table, "--name", "arm", "--out-dir", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert err.startswith("note: completed the set") and "v.png" in err
    assert {n: _folder(tmp_path)[n] for n in SET} == NEW
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


# ---------------------------------------------------------------- the model commands


def _urdf(tmp_path: Path, joint2: str = "", origin: str = "0 0 0.1", n: int = 2) -> Path:
    lines = ['<robot name="rig">', '<link name="l0"/>']
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    for i in range(1, n + 1):
        body = joint2 if (i == 2 and joint2) else f'type="revolute">{limit}'
        lines += [
            f'<link name="l{i}"/>',
            f'<joint name="j{i}" {body}<parent link="l{i - 1}"/><child link="l{i}"/>'
            f'<origin xyz="{origin if i == 1 else "0 0 0.1"}"/><axis xyz="0 0 1"/></joint>',
        ]
    path = tmp_path / "rig.urdf"
    path.write_text("\n".join([*lines, "</robot>"]))
    return path


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n": 1000}, "a chain 1000 joints deep; a machine model here takes at most 100"),
        ({"origin": "nan 0 0"}, "<origin> of joint 'j1': xyz=\"nan 0 0\" is not a list of finite"),
        ({"joint2": 'type="prismatic">'}, "prismatic joint 'j2' has no <limit"),
        (
            {"joint2": 'type="revolute"><limit lower="2" upper="-2" effort="1" velocity="1"/>'},
            'joint \'j2\' has <limit lower="2" upper="-2">: lower is above upper',
        ),
    ],
)
def test_bad_urdfs_exit_2_naming_the_cause(tmp_path, capsys, kwargs, message):
    urdf = _urdf(tmp_path, **kwargs)
    out = tmp_path / "out"
    assert urdf_main([str(urdf), "--target", "target_1=l1", "--out-dir", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_from_urdf_replaces_a_users_files_only_with_force(tmp_path, capsys):
    urdf = _urdf(tmp_path)
    args = [str(urdf), "--target", "target_1=l2", "--out-dir", str(tmp_path)]
    mine = {tmp_path / "rig.xml": b"my model\n", tmp_path / "rig.params.toml": b"my errors\n"}
    for path, data in mine.items():
        path.write_bytes(data)
    assert urdf_main(args) == 2
    err = capsys.readouterr().err
    assert "exist(s)" in err and "--force" in err
    assert all(p.read_bytes() == d for p, d in mine.items())
    assert urdf_main([*args, "--force"]) == 0
    assert "<mujoco" in (tmp_path / "rig.xml").read_text()
    assert (
        "datasets of this machine name the model 'rig' (--name sets it)" in capsys.readouterr().out
    )


@pytest.mark.parametrize("command", ["from-urdf", "from-dh"])
def test_an_out_dir_that_is_a_file_exits_2(tmp_path, capsys, command):
    blocker = tmp_path / "models"
    blocker.write_text("a file\n")
    if command == "from-urdf":
        code = urdf_main(
            [str(_urdf(tmp_path)), "--target", "target_1=l2", "--out-dir", str(blocker)]
        )
    else:
        table = str(MODELS / "arm6r.mdh.csv")
        code = dh_main([table, "--name", "arm", "--out-dir", str(blocker)])
    assert code == 2
    assert f"--out-dir {blocker} is a file, not a folder" in capsys.readouterr().err


def test_error_model_on_a_full_disk_exits_2_naming_the_file(tmp_path, capsys, monkeypatch):
    import common.write_set as write_set_module

    def full(target: Path, token: str) -> Path:
        raise os_error(ENOSPC, target)

    monkeypatch.setattr(write_set_module, "_temporary", full)
    out = tmp_path / "e.toml"
    assert error_model_main([str(MODELS / "arm6r.xml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"cannot write {out}: No space left on device" in err and "Errno" not in err


# ---------------------------------------------------------------- results read back

ARM = [str(MODELS / "arm6r.xml"), str(MODELS / "arm6r.params.toml")]


@pytest.fixture(scope="module")
def edited(tmp_path_factory) -> tuple[Path, str]:
    """A result of the arm with one estimate hand-edited to 1e6 mm."""
    model = model_from_files(*ARM)
    values = plausible_values(model.params, np.random.default_rng(3))
    k = next(i for i, a in enumerate(model.params.is_angle) if not a)
    values[k] = 1e3  # 1e6 mm, in SI
    path = tmp_path_factory.mktemp("edited") / "r.json"
    return result_file(path, model.nominal.name, model.params, values), model.params.names[k]


def _compensate(result: str, tmp_path: Path) -> list[str]:
    poses = tmp_path / "desired.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm\n0,400,0,500\n")
    out = str(tmp_path / "commands.csv")
    base = ["compensate", "--model", ARM[0], "--errors", ARM[1], "--result", result]
    return [*base, "--poses", str(poses), "--out", out]


def test_compensate_and_export_name_an_implausible_estimate(edited, tmp_path, capsys):
    result, name = edited
    export = ["export", "--model", ARM[0], "--errors", ARM[1], "--result", str(result)]
    for argv in (_compensate(str(result), tmp_path), [*export, "--out", str(tmp_path / "m.xml")]):
        assert calib_main(argv) == 2
        err = capsys.readouterr().err
        assert f"implausible estimate(s): {name} = +1e+06 mm" in err, err
        assert "Traceback" not in err
    assert not (tmp_path / "m.xml").exists() and not (tmp_path / "commands.csv").exists()


@pytest.mark.parametrize(
    ("path", "message"),
    [
        ("/dev/null", "is not a regular file (a device, pipe or socket)"),
        (".", "is a folder, not a result file"),
        ("empty.json", "is empty, not a result file"),
    ],
)
def test_a_result_path_that_is_no_result_file_is_named(tmp_path, capsys, path, message):
    (tmp_path / "empty.json").write_text("")
    target = path if path.startswith("/") else str(tmp_path / path)
    assert calib_main(_compensate(target, tmp_path)) == 2
    err = capsys.readouterr().err
    assert message in err and "not found" not in err


def test_export_on_a_full_disk_names_the_file_without_the_errno(tmp_path, capsys, monkeypatch):
    model = model_from_files(*ARM)
    values = plausible_values(model.params, np.random.default_rng(4))
    result = result_file(tmp_path / "r.json", model.nominal.name, model.params, values)
    real = Path.write_text

    def full(self, *args, **kwargs):
        if self.name.startswith(".m.xml."):
            raise OSError(ENOSPC, "No space left on device")  # as write() raises it: no file
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full)
    argv = ["export", "--model", ARM[0], "--errors", ARM[1], "--result", str(result)]
    assert calib_main([*argv, "--out", str(tmp_path / "m.xml")]) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and "[Errno" not in err
    assert f"cannot write {tmp_path}/.m.xml." in err and "nothing written" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]
