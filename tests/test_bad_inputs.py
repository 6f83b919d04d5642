"""Bad input gives a clear error naming its cause, never a traceback of an internal type.

One table of bad inputs (datasets, sidecars, error models, poses and commands out of range)
-> the exception type and substrings its message must contain: the file, the line or entry,
the field or column, the closest valid name, the value in the file's units (mm, deg).
Every input is built in ``tmp_path`` from a valid dataset (``write_dataset``) or a valid
error model in the format of models/hexapod_rrrprr.params.toml.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from calib.data import Dataset, DatasetError, read_dataset, sidecar_path, write_dataset
from twin.exceptions import ParameterError, WorkspaceError
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.workspace import check_command_strokes, commands_for_poses

ROOT = Path(__file__).resolve().parent.parent
ACTS = tuple(f"leg{i}" for i in range(1, 7))
TARGETS = ("target_1", "target_2", "target_3")
POSE_IDS = (42, 7, 13)
N_COLUMNS = 4 + len(ACTS) + 3  # pose_id, set, target, repeat, cmd:leg1..6, x, y, z


def hexapod_dataset(commands: np.ndarray | None = None) -> Dataset:
    """Three poses of the hexapod (pose ids 42, 7, 13), three targets, one repeat."""
    rng = np.random.default_rng(10)
    n = len(POSE_IDS)
    return Dataset(
        model="hexapod_rrrprr",
        frame="base",
        actuator_names=ACTS,
        actuator_units=("mm",) * len(ACTS),
        target_names=TARGETS,
        pose_ids=np.array(POSE_IDS),
        sets=np.array(["calibration"] * n),
        commands=np.full((n, len(ACTS)), 0.23) if commands is None else commands,
        readings=rng.uniform(-0.1, 0.3, (n, len(TARGETS), 1, 3)),
        notes="valid dataset",
    )


MODEL_TOML = """model = "hexapod_rrrprr"

[[parameter]]
name = "leg1.length"
kind = "body_pos"
element = "leg1_rod"
axis = [0, 0, 1]

[[parameter]]
name = "leg1.base.dx"
kind = "body_pos"
element = "leg1_base"
axis = [1, 0, 0]
"""


@dataclass
class Env:
    """What a case may use: a temporary directory and the (lazily built) machines."""

    tmp_path: Path
    request: pytest.FixtureRequest

    def machine(self, name: str) -> Mechanism:
        return self.request.getfixturevalue(name)

    def dataset(self) -> Path:
        return write_dataset(hexapod_dataset(), self.tmp_path / "poses.csv")

    def model(self, text: str = MODEL_TOML, data: bytes | None = None) -> Path:
        path = self.tmp_path / "bad.toml"
        path.write_bytes(text.encode() if data is None else data)
        return path


# --- building bad inputs -------------------------------------------------------------------


def csv_lines(path: Path) -> list[str]:
    return path.read_text(encoding="utf-8").splitlines(keepends=True)


def edit_csv(env: Env, edit: Callable[[list[str]], list[str]]) -> Callable[[], object]:
    path = env.dataset()
    path.write_text("".join(edit(csv_lines(path))), encoding="utf-8")
    return lambda: read_dataset(path)


def set_cell(line: int, column: str, value: str) -> Callable[[list[str]], list[str]]:
    """Set one cell; ``line`` is the 1-based line of the file (line 1 is the header)."""

    def edit(lines: list[str]) -> list[str]:
        header = lines[0].rstrip("\n").split(",")
        cells = lines[line - 1].rstrip("\n").split(",")
        cells[header.index(column)] = value
        lines[line - 1] = ",".join(cells) + "\n"
        return lines

    return edit


def encode_csv(env: Env, encode: Callable[[str], bytes]) -> Callable[[], object]:
    path = env.dataset()
    path.write_bytes(encode(path.read_text(encoding="utf-8")))
    return lambda: read_dataset(path)


def random_text_csv(env: Env) -> Callable[[], object]:
    """3000 random printable bytes (and line ends) in place of the CSV, beside its sidecar."""
    path = env.dataset()
    rng = np.random.default_rng(2)
    alphabet = np.frombuffer(bytes(range(32, 127)) + b"\n" * 3, dtype=np.uint8)
    path.write_bytes(rng.choice(alphabet, 3000).tobytes())
    return lambda: read_dataset(path)


def latin1_csv(env: Env) -> Callable[[], object]:
    path = env.dataset()
    lines = csv_lines(path)
    lines[2] = lines[2].replace("calibration", "calibración")  # line 3 of the file
    path.write_bytes("".join(lines).encode("latin-1"))
    return lambda: read_dataset(path)


def edit_sidecar_bytes(env: Env, make: Callable[[str], bytes]) -> Callable[[], object]:
    path = env.dataset()
    side = sidecar_path(path)
    side.write_bytes(make(side.read_text(encoding="utf-8")))
    return lambda: read_dataset(path)


def sidecar_keys(env: Env, **changes: object) -> Callable[[], object]:
    def make(text: str) -> bytes:
        data = json.loads(text)
        for key, value in changes.items():
            if value is None:
                data.pop(key)
            else:
                data[key] = value
        return json.dumps(data, indent=2).encode()

    return edit_sidecar_bytes(env, make)


def renamed_sidecar_key(env: Env, old: str, new: str) -> Callable[[], object]:
    def make(text: str) -> bytes:
        data = json.loads(text)
        data[new] = data.pop(old)
        return json.dumps(data, indent=2).encode()

    return edit_sidecar_bytes(env, make)


def latin1_sidecar(text: str) -> bytes:
    data = json.loads(text)
    data["notes"] = "mesuré au café"
    return json.dumps(data, indent=2, ensure_ascii=False).encode("latin-1")


def broken_json(text: str) -> bytes:
    lines = text.splitlines(keepends=True)
    lines[2] = lines[2].rstrip("\n") + ",\n"  # a second comma at the end of line 3
    return "".join(lines).encode()


def model_file(env: Env, old: str, new: str, count: int = 1) -> Callable[[], object]:
    assert old in MODEL_TOML
    path = env.model(MODEL_TOML.replace(old, new, count))
    return lambda: load_parameter_set(path, env.machine("hexapod").model)


def model_bytes(env: Env, data: bytes) -> Callable[[], object]:
    path = env.model(data=data)
    return lambda: load_parameter_set(path, env.machine("hexapod").model)


def stroke_from_dataset(env: Env) -> Callable[[], object]:
    """A dataset whose pose_id 7 (row 1) commands leg3 past its stroke (300 > 265 mm)."""
    commands = np.full((3, 6), 0.23)
    commands[1, 2] = 0.300
    ds = read_dataset(
        write_dataset(hexapod_dataset(commands), env.tmp_path / "poses.csv"),
        expected_model="hexapod_rrrprr",
    )
    return lambda: check_command_strokes(env.machine("hexapod"), ds.commands, ds.pose_labels)


def poses_with_labels(env: Env, pose: list[float]) -> Callable[[], object]:
    poses = np.array([[0, 0, 0.22, 0, 0, 0], [0, 0, 0.23, 0, 0, 0], pose])
    labels = [str(i) for i in POSE_IDS]
    return lambda: commands_for_poses(env.machine("hexapod"), poses, labels=labels)


def polisher_wrist(env: Env) -> Callable[[], object]:
    commands = np.array([[0.9, 0.9, 0.9, 0.0, 0.0, 0.0], [0.9, 0.9, 0.9, 2.0, 0.0, 0.0]])
    return lambda: check_command_strokes(env.machine("polisher"), commands, labels=["p1", "p2"])


def unlabelled_commands(env: Env) -> Callable[[], object]:
    commands = np.full((3, 6), 0.23)
    commands[2, 5] = 0.19
    return lambda: check_command_strokes(env.machine("hexapod"), commands)


# --- the table -----------------------------------------------------------------------------

Case = tuple[Callable[[Env], Callable[[], object]], type[Exception], tuple[str, ...]]
CASES: dict[str, Case] = {
    # encodings
    "csv in Latin-1": (
        latin1_csv,
        DatasetError,
        ("poses.csv", "line 3, column 13", "byte 0xf3", "Latin-1", "'ó'", "UTF-8 is expected"),
    ),
    "csv in UTF-16 with BOM": (
        lambda env: encode_csv(env, lambda t: t.encode("utf-16")),
        DatasetError,
        ("poses.csv", "UTF-16 (little-endian)", "byte-order mark", "UTF-8 is expected"),
    ),
    "csv in UTF-16-LE without BOM": (
        lambda env: encode_csv(env, lambda t: t.encode("utf-16-le")),
        DatasetError,
        ("poses.csv", "looks like UTF-16 (little-endian)", "NUL bytes", "UTF-8 is expected"),
    ),
    "csv in UTF-16-BE without BOM": (
        lambda env: encode_csv(env, lambda t: t.encode("utf-16-be")),
        DatasetError,
        ("poses.csv", "looks like UTF-16 (big-endian)", "UTF-8 is expected"),
    ),
    "csv in UTF-32 with BOM": (
        lambda env: encode_csv(env, lambda t: t.encode("utf-32")),
        DatasetError,
        ("poses.csv", "UTF-32 (little-endian)", "byte-order mark"),
    ),
    "csv with a NUL byte": (
        lambda env: encode_csv(env, lambda t: t.replace("target_2", "target\x002", 1).encode()),
        DatasetError,
        ("poses.csv", "NUL byte at line 3", "not a text file"),
    ),
    "sidecar in Latin-1": (
        lambda env: edit_sidecar_bytes(env, latin1_sidecar),
        DatasetError,
        ("poses.csv.json", "sidecar", "byte 0xe9", "Latin-1", "UTF-8 is expected"),
    ),
    "sidecar in UTF-16": (
        lambda env: edit_sidecar_bytes(env, lambda t: t.encode("utf-16")),
        DatasetError,
        ("poses.csv.json", "UTF-16", "UTF-8 is expected"),
    ),
    # delimiters
    "csv with ';' delimiter": (
        lambda env: edit_csv(env, lambda ls: [ln.replace(",", ";") for ln in ls]),
        DatasetError,
        ("poses.csv line 1", "the file uses ';' as delimiter; the format is comma-separated"),
    ),
    "csv with tab delimiter": (
        lambda env: edit_csv(env, lambda ls: [ln.replace(",", "\t") for ln in ls]),
        DatasetError,
        ("poses.csv line 1", "uses tab", "as delimiter", "comma-separated"),
    ),
    "';' header after blank lines": (
        lambda env: edit_csv(env, lambda ls: ["\n", "\n", *(ln.replace(",", ";") for ln in ls)]),
        DatasetError,
        ("poses.csv line 3", "uses ';' as delimiter"),
    ),
    "data row with ';' delimiter": (
        lambda env: edit_csv(env, lambda ls: [*ls[:3], ls[3].replace(",", ";"), *ls[4:]]),
        DatasetError,
        ("poses.csv line 4", "1 fields", "uses ';' as delimiter"),
    ),
    # structure
    "empty csv": (
        lambda env: edit_csv(env, lambda ls: []),
        DatasetError,
        ("poses.csv", "empty file"),
    ),
    "blank csv": (
        lambda env: edit_csv(env, lambda ls: ["  \n", "\n"]),
        DatasetError,
        ("poses.csv", "empty file"),
    ),
    "header only": (
        lambda env: edit_csv(env, lambda ls: ls[:1]),
        DatasetError,
        ("poses.csv", "no data rows"),
    ),
    "row with too few columns": (
        lambda env: edit_csv(env, lambda ls: [*ls[:3], ls[3].rsplit(",", 1)[0] + "\n", *ls[4:]]),
        DatasetError,
        ("poses.csv line 4", f"{N_COLUMNS - 1} fields, the header has {N_COLUMNS}"),
    ),
    "duplicate column names": (
        lambda env: edit_csv(env, lambda ls: [ls[0].replace("x_mm", "y_mm"), *ls[1:]]),
        DatasetError,
        ("poses.csv", "duplicate column(s)", "'y_mm'"),
    ),
    # cells
    "non-numeric reading": (
        lambda env: edit_csv(env, set_cell(4, "x_mm", "abc")),
        DatasetError,
        ("poses.csv line 4", "column 'x_mm'", "expected a number", "'abc'"),
    ),
    "decimal comma": (
        lambda env: edit_csv(env, set_cell(5, "z_mm", '"1,5"')),
        DatasetError,
        ("poses.csv line 5", "column 'z_mm'", "'1,5'"),
    ),
    "digit separator": (
        lambda env: edit_csv(env, set_cell(2, "y_mm", "1_000")),
        DatasetError,
        ("poses.csv line 2", "column 'y_mm'", "'1_000'"),
    ),
    "non-integer pose id": (
        lambda env: edit_csv(env, set_cell(6, "pose_id", "P7")),
        DatasetError,
        ("poses.csv line 6", "column 'pose_id'", "expected an integer", "'P7'"),
    ),
    "pose id beyond int64": (
        lambda env: edit_csv(env, set_cell(2, "pose_id", "99999999999999999999")),
        DatasetError,
        ("poses.csv line 2", "column 'pose_id'", "outside the range of a 64-bit integer"),
    ),
    "negative pose id beyond int64": (
        lambda env: edit_csv(env, set_cell(3, "pose_id", "-9223372036854775809")),
        DatasetError,
        ("poses.csv line 3", "column 'pose_id'", "-9223372036854775809 is outside the range"),
    ),
    "reading of 1e300 mm": (
        lambda env: edit_csv(env, set_cell(4, "x_mm", "1e300")),
        DatasetError,
        ("poses.csv line 4", "column 'x_mm'", "1e+300 mm is beyond 1e+06 mm (1 km)"),
    ),
    "random bytes": (
        random_text_csv,
        DatasetError,
        ("poses.csv", "not a dataset CSV", "names none of the columns", "pose_id, set"),
    ),
    "NaN command": (
        lambda env: edit_csv(env, set_cell(3, "cmd:leg2", "nan")),
        DatasetError,
        ("poses.csv line 3", "column 'cmd:leg2'", "non-finite"),
    ),
    # sidecar
    "sidecar not JSON": (
        lambda env: edit_sidecar_bytes(env, broken_json),
        DatasetError,
        ("poses.csv.json", "malformed JSON at line 3, column 16"),
    ),
    "sidecar empty": (
        lambda env: edit_sidecar_bytes(env, lambda t: b"\n"),
        DatasetError,
        ("poses.csv.json", "empty sidecar"),
    ),
    "sidecar missing": (
        lambda env: (lambda p: (sidecar_path(p).unlink(), lambda: read_dataset(p))[1])(
            env.dataset()
        ),
        DatasetError,
        ("poses.csv.json", "sidecar file not found"),
    ),
    "sidecar key misspelt": (
        lambda env: renamed_sidecar_key(env, "actuators", "actuator"),
        DatasetError,
        ("poses.csv.json", "unknown keys ['actuator']", "did you mean 'actuators'"),
    ),
    "sidecar unit in metres": (
        lambda env: sidecar_keys(env, length_unit="m"),
        DatasetError,
        ("poses.csv.json", "length_unit is 'm', expected 'mm'"),
    ),
    "sidecar model does not match": (
        lambda env: (lambda p: lambda: read_dataset(p, expected_model="polisher"))(env.dataset()),
        DatasetError,
        ("poses.csv.json", "model is 'hexapod_rrrprr', expected 'polisher'"),
    ),
    # error models
    "parameter = [1, 2]": (
        lambda env: model_bytes(env, b'model = "hexapod_rrrprr"\nparameter = [1, 2]\n'),
        ParameterError,
        ("bad.toml", "parameter #1 must be a table", "[[parameter]]", "got 1 (int)"),
    ),
    "parameter = string": (
        lambda env: model_bytes(env, b'parameter = "leg1.length"\n'),
        ParameterError,
        ("bad.toml", "'parameter' must be an array of tables", "(str)"),
    ),
    "name is a number": (
        lambda env: model_file(env, 'name = "leg1.base.dx"', "name = 5"),
        ParameterError,
        ("bad.toml", "parameter #2", "field 'name'", "non-empty string", "got 5 (int)"),
    ),
    "kind is an array": (
        lambda env: model_file(env, 'kind = "body_pos"', 'kind = ["body_pos"]'),
        ParameterError,
        ("bad.toml", "parameter #1 'leg1.length'", "field 'kind'", "(list)"),
    ),
    "axis is a string": (
        lambda env: model_file(env, "axis = [1, 0, 0]", 'axis = "100"'),
        ParameterError,
        ("bad.toml", "parameter #2 'leg1.base.dx'", "field 'axis'", "array of 3 numbers"),
    ),
    "axis holds a boolean": (
        lambda env: model_file(env, "axis = [0, 0, 1]", "axis = [0, 0, true]"),
        ParameterError,
        ("bad.toml", "parameter #1 'leg1.length'", "field 'axis' component 3", "(bool)"),
    ),
    "axis with 2 components": (
        lambda env: model_file(env, "axis = [1, 0, 0]", "axis = [1, 0]"),
        ParameterError,
        ("bad.toml", "parameter #2 'leg1.base.dx' axis must have 3 components"),
    ),
    "unknown field axsi": (
        lambda env: model_file(env, "axis = [1, 0, 0]", "axsi = [1, 0, 0]"),
        ParameterError,
        ("bad.toml", "parameter #2", "unknown field 'axsi'", "did you mean 'axis'"),
    ),
    "unknown field elment": (
        lambda env: model_file(env, 'element = "leg1_rod"', 'elment = "leg1_rod"'),
        ParameterError,
        ("bad.toml", "parameter #1 'leg1.length'", "'elment'", "did you mean 'element'"),
    ),
    "kind misspelt": (
        lambda env: model_file(env, 'kind = "body_pos"', 'kind = "body_postion"'),
        ParameterError,
        ("bad.toml", "parameter #1 'leg1.length'", "field 'kind'", "did you mean 'body_pos'"),
    ),
    "unknown top-level key": (
        lambda env: model_file(env, "[[parameter]]", "[[paramter]]", count=2),
        ParameterError,
        ("bad.toml", "unknown top-level key 'paramter'", "did you mean 'parameter'"),
    ),
    "error model of another machine": (
        lambda env: model_file(env, 'model = "hexapod_rrrprr"', 'model = "polisher"'),
        ParameterError,
        ("bad.toml is an error model for 'polisher'", "the MJCF is 'hexapod_rrrprr'"),
    ),
    "element not in the model": (
        lambda env: model_file(env, 'element = "leg1_base"', 'element = "leg9_base"'),
        ParameterError,
        ("bad.toml", "'leg1.base.dx'", "no body named 'leg9_base'"),
    ),
    "error model in Latin-1": (
        lambda env: model_bytes(env, ("# modèle\n" + MODEL_TOML).encode("latin-1")),
        ParameterError,
        ("bad.toml", "line 1, column 6", "Latin-1", "UTF-8 is expected"),
    ),
    "error model in UTF-16": (
        lambda env: model_bytes(env, MODEL_TOML.encode("utf-16")),
        ParameterError,
        ("bad.toml", "UTF-16", "UTF-8 is expected"),
    ),
    # strokes and workspace: named by pose_id, values in mm and deg
    "stroke of a dataset pose": (
        stroke_from_dataset,
        WorkspaceError,
        ("pose_id 7:", "actuator 'leg3' command 300 mm", "outside its stroke [195, 265] mm"),
    ),
    "pose outside the workspace": (
        lambda env: poses_with_labels(env, [0, 0, 0.30, 0, 0, 0]),
        WorkspaceError,
        ("pose_id 13:", "pose z = 300 mm is outside the workspace [200, 240] mm"),
    ),
    "pose outside the strokes": (
        lambda env: poses_with_labels(env, [0, 0, 0.24, 0.26, 0.26, 0]),
        WorkspaceError,
        ("pose_id 13:", "not reachable", " mm is outside its stroke [195, 265] mm"),
    ),
    "revolute command in degrees": (
        polisher_wrist,
        WorkspaceError,
        ("pose_id p2:", "actuator 'theta4' command 114.592 deg", "range [-90, 90] deg"),
    ),
    "unlabelled commands keep the row index": (
        unlabelled_commands,
        WorkspaceError,
        ("pose 2:", "actuator 'leg6' command 190 mm", "[195, 265] mm"),
    ),
}


@pytest.fixture(scope="module")
def polisher() -> Mechanism:
    return Mechanism.from_xml(ROOT / "models" / "polisher.xml")


@pytest.mark.parametrize(("build", "error", "expected"), CASES.values(), ids=CASES.keys())
def test_bad_input_names_its_cause(
    tmp_path: Path,
    request: pytest.FixtureRequest,
    build: Callable[[Env], Callable[[], object]],
    error: type[Exception],
    expected: tuple[str, ...],
) -> None:
    action = build(Env(tmp_path, request))
    with pytest.raises(error) as info:
        action()
    assert type(info.value) is error
    message = str(info.value)
    for part in expected:
        assert part in message, f"{part!r} not in {message!r}"
    for internal in ("UnicodeDecodeError", "TypeError", "codec", "0.195", "0.265"):
        assert internal not in message
    assert info.value.__cause__ is None  # no internal exception chained to the user's error


def test_at_least_twenty_cases() -> None:
    assert len(CASES) >= 20


# --- what must keep working ----------------------------------------------------------------


def test_utf8_bom_is_accepted(tmp_path: Path) -> None:
    ds = hexapod_dataset()
    path = write_dataset(ds, tmp_path / "poses.csv")
    for p in (path, sidecar_path(path)):
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())
    back = read_dataset(path, expected_model="hexapod_rrrprr")
    assert back.pose_labels == ("42", "7", "13")
    assert np.allclose(back.readings, ds.readings, rtol=0, atol=1e-15)
    assert back.notes == "valid dataset"


def test_utf8_bom_in_error_model_is_accepted(tmp_path: Path, hexapod: Mechanism) -> None:
    path = tmp_path / "m.toml"
    path.write_bytes(b"\xef\xbb\xbf" + MODEL_TOML.encode())
    assert load_parameter_set(path, hexapod.model).names == ("leg1.length", "leg1.base.dx")


def test_commands_in_stroke_pass_with_labels(hexapod: Mechanism) -> None:
    ds = hexapod_dataset()
    check_command_strokes(hexapod, ds.commands, ds.pose_labels)  # no error
    poses = np.array([[0, 0, 0.22, 0, 0, 0], [0, 0, 0.23, 0, 0, 0]])
    assert commands_for_poses(hexapod, poses, labels=["a", "b"]).shape == (2, 6)
    with pytest.raises(ValueError, match="1 pose labels for 2 poses"):
        commands_for_poses(hexapod, poses, labels=["a"])


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_dataset_files_are_ordinary_files(tmp_path: Path, umask: int) -> None:
    old = os.umask(umask)
    try:
        path = tmp_path / "poses.csv"
        path.write_text("old")
        os.chmod(path, 0o600)  # an existing file does not keep mkstemp's private mode
        write_dataset(hexapod_dataset(), path)
        modes = [p.stat().st_mode & 0o777 for p in (path, sidecar_path(path))]
    finally:
        os.umask(old)
    assert modes == [0o644 & ~umask] * 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poses.csv", "poses.csv.json"]
