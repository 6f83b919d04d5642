"""One command, ``pkm-calib``, on a lean core (issue 37): every subcommand is there; the
calibration and model commands import and run with the extras (rerun-sdk, Ray, pinocchio)
absent and with ``fcntl`` absent (Windows); the scenario commands then name the extra; the
package metadata keeps the core lean and every dependency within a version range."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from pkm_calib.command import MODEL_COMMANDS, SCENARIO_COMMANDS, main

ROOT = Path(__file__).resolve().parent.parent
CALIB_COMMANDS = ("identify", "verify", "diagnose", "compensate", "export", "plan")
EXTRAS = ("ray", "rerun", "pinocchio", "pyarrow")  # what only the extras install


def _child(code: str, blocked: tuple[str, ...]) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter where importing any of ``blocked`` fails."""
    block = "".join(f"sys.modules[{name!r}] = None\n" for name in blocked)
    script = f"import sys\n{block}{code}"
    return subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def test_every_subcommand_is_listed(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: pkm-calib")
    for name in (*CALIB_COMMANDS, *MODEL_COMMANDS, *SCENARIO_COMMANDS):
        assert f"    {name} " in out or f"    {name}\n" in out, name


@pytest.mark.parametrize("name", sorted(MODEL_COMMANDS))
def test_model_commands_parse_their_own_arguments(name, capsys):
    with pytest.raises(SystemExit) as done:
        main([name, "--help"])
    assert done.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: pkm-calib {name}")


def test_calibration_commands_run_through_the_one_command(capsys):
    """A calibration subcommand is calib.cli's: its bad input exits 2 naming the file."""
    argv = ["identify", "--model", "no_such.xml", "--errors", "e.toml", "--data", "d.csv"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "no_such.xml" in err and "Traceback" not in err


def test_the_module_entry_point_still_works():
    done = subprocess.run(
        [sys.executable, "-m", "calib", "--help"], cwd=ROOT, capture_output=True, text=True
    )
    assert done.returncode == 0 and "identify" in done.stdout


def test_core_commands_import_without_the_extras():
    """Every calib and twin module imports with ray, rerun, pinocchio and pyarrow absent
    (none is imported at import time), and pkm-calib --help runs."""
    code = """
import importlib, pkgutil
import calib, twin, common
for pkg in (common, twin, calib):
    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
        if m.name.endswith("pinocchio_model"):
            continue  # the cross-check: imported by a test, pinocchio imported on use
        importlib.import_module(m.name)
import twin.kinematics.pinocchio_model  # imports; pinocchio only when called
import calib.cli.commands
from pkm_calib.command import main
try:
    main(["--help"])
except SystemExit as exc:
    assert exc.code == 0, exc.code
extras = ("ray", "rerun", "pinocchio", "pyarrow")
loaded = sorted(n for n, m in sys.modules.items() if n.split(".")[0] in extras and m)
print("LOADED", loaded)
"""
    done = _child(code, EXTRAS)
    assert done.returncode == 0, done.stderr
    assert "LOADED []" in done.stdout


@pytest.mark.parametrize("command", sorted(SCENARIO_COMMANDS))
def test_scenario_commands_name_the_missing_extra(command):
    code = f"from pkm_calib.command import main\nsys.exit(main([{command!r}, 'liu_vs_ols']))"
    done = _child(code, EXTRAS)
    assert done.returncode == 2, done.stderr
    assert "needs the scenarios extra" in done.stderr
    assert "pip install 'pkm-calib[scenarios]'" in done.stderr
    assert "Traceback" not in done.stderr


def test_the_command_line_imports_and_writes_without_fcntl(tmp_path):
    """Windows has no fcntl: the command line imports, and a set of files (with its lock)
    and a staged folder are written all the same."""
    code = f"""
import calib.cli.commands
from pathlib import Path
from common.write_set import staged, write_files
out = Path({str(tmp_path)!r})
write_files({{out / "a.txt": "a\\n", out / "b.txt": "b\\n"}})
with staged(out) as stage:
    (stage / "c.txt").write_text("c\\n")
print(sorted(p.name for p in out.iterdir()))
"""
    done = _child(code, ("fcntl",))
    assert done.returncode == 0, done.stderr
    assert "['a.txt', 'b.txt', 'c.txt']" in done.stdout


def test_the_package_metadata_keeps_the_core_lean():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    project = meta["project"]
    assert project["scripts"] == {"pkm-calib": "pkm_calib.command:main"}
    core = {_name(d) for d in project["dependencies"]}
    extras = project["optional-dependencies"]
    assert not core & {"ray", "rerun-sdk", "pyarrow", "pin"}
    assert {"numpy", "scipy", "mujoco", "matplotlib", "filelock"} <= core
    assert {_name(d) for d in extras["scenarios"]} == {"rerun-sdk", "ray"}
    assert {"pytest", "pytest-xdist", "pin", "ruff"} <= {_name(d) for d in extras["dev"]}
    for dep in [*project["dependencies"], *(d for ds in extras.values() for d in ds)]:
        assert ">=" in dep and "<" in dep.replace("<=", ""), f"{dep}: no version range"
    makefile = (ROOT / "Makefile").read_text()
    assert '-e ".[dev,scenarios]"' in makefile  # make setup installs everything


def _name(requirement: str) -> str:
    for i, ch in enumerate(requirement):
        if ch in "<>=!~[; ":
            return requirement[:i]
    return requirement
