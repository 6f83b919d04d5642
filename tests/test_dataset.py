"""Dataset contract: CSV + JSON sidecar round trip, unit conversion and validation."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np
import pytest

from calib.data import (
    Dataset,
    DatasetError,
    read_dataset,
    sidecar_path,
    write_dataset,
)

ACTS = ("leg1", "joint2")
UNITS = ("mm", "deg")
TARGETS = ("target_1", "target_2", "target_3")


def make_dataset(n_poses: int = 4, n_repeats: int = 2, seed: int = 0) -> Dataset:
    rng = np.random.default_rng(seed)
    p, t, r = n_poses, len(TARGETS), n_repeats
    return Dataset(
        model="hexapod_rrrprr",
        frame="base",
        actuator_names=ACTS,
        actuator_units=UNITS,
        target_names=TARGETS,
        pose_ids=np.array([10, 3, 7, 5][:p]),
        sets=np.array(["calibration", "calibration", "verification", "calibration"][:p]),
        commands=np.column_stack([rng.uniform(0.4, 0.6, p), rng.uniform(-1.0, 1.0, p)]),
        readings=rng.uniform(-0.5, 0.5, (p, t, r, 3)),
        order=np.array([2, 0, 1, 3][:p]),
        time_s=rng.uniform(0.0, 100.0, p),
        commanded_poses=np.column_stack(
            [rng.uniform(-0.1, 0.1, (p, 3)), rng.uniform(-0.3, 0.3, (p, 3))]
        ),
        tracker={"name": "sim", "sigma_mm": 0.01},
        meta={"seed": seed},
        notes="synthetic",
    )


@pytest.fixture
def csv_file(tmp_path: Path) -> Path:
    return write_dataset(make_dataset(), tmp_path / "poses.csv")


def load_rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as fh:
        header, *rows = list(csv.reader(fh))
    return header, rows


def save_rows(path: Path, header: list[str], rows: list[list[str]]) -> None:
    with path.open("w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows([header, *rows])


def edit_cell(path: Path, row: int, column: str, value: str) -> None:
    header, rows = load_rows(path)
    rows[row][header.index(column)] = value
    save_rows(path, header, rows)


def drop_column(path: Path, column: str) -> None:
    header, rows = load_rows(path)
    i = header.index(column)
    save_rows(path, header[:i] + header[i + 1 :], [r[:i] + r[i + 1 :] for r in rows])


def edit_sidecar(path: Path, **changes: object) -> None:
    side = sidecar_path(path)
    data = json.loads(side.read_text())
    data.update(changes)
    side.write_text(json.dumps(data))


def test_round_trip(tmp_path: Path) -> None:
    ds = make_dataset()
    path = write_dataset(ds, tmp_path / "poses.csv")
    assert path == tmp_path / "poses.csv"
    assert sidecar_path(path) == tmp_path / "poses.csv.json"
    back = read_dataset(path, expected_model="hexapod_rrrprr")
    assert back.model == ds.model and back.frame == "base"
    assert back.actuator_names == ACTS and back.actuator_units == UNITS
    assert back.target_names == TARGETS
    assert back.pose_ids.tolist() == [10, 3, 7, 5]
    assert back.sets.tolist() == ds.sets.tolist()
    assert np.array_equal(back.order, ds.order)
    np.testing.assert_allclose(back.commands, ds.commands, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(back.readings, ds.readings, rtol=0, atol=1e-15)
    np.testing.assert_allclose(back.commanded_poses, ds.commanded_poses, rtol=0, atol=1e-15)
    assert np.array_equal(back.time_s, ds.time_s)  # seconds are written unconverted
    assert back.tracker == {"name": "sim", "sigma_mm": 0.01}
    assert back.meta == {"seed": 0} and back.notes == "synthetic"


def test_round_trip_without_optional_columns(tmp_path: Path) -> None:
    ds = Dataset(
        model="m",
        frame="base",
        actuator_names=("a",),
        actuator_units=("mm",),
        target_names=("t",),
        pose_ids=np.array([1, 2]),
        sets=np.array(["calibration", "calibration"]),
        commands=np.array([[0.5], [0.25]]),
        readings=np.array([[[[0.5, 0.25, 1.5]]], [[[0.125, -0.75, 2.0]]]]),
    )
    path = write_dataset(ds, tmp_path / "d.csv")
    header, _ = load_rows(path)
    assert header == ["pose_id", "set", "target", "repeat", "cmd:a", "x_mm", "y_mm", "z_mm"]
    back = read_dataset(path)
    assert back.order is None and back.time_s is None and back.commanded_poses is None
    assert back.tracker is None and back.meta is None
    assert np.array_equal(back.commands, ds.commands)
    assert np.array_equal(back.readings, ds.readings)


def test_rows_sorted_and_written_in_file_units(csv_file: Path) -> None:
    ds = make_dataset()
    header, rows = load_rows(csv_file)
    keys = [(int(r[0]), r[2], int(r[3])) for r in rows]
    assert keys == [(p, t, r) for p in (10, 3, 7, 5) for t in TARGETS for r in (0, 1)]
    first = dict(zip(header, rows[0], strict=True))
    assert float(first["cmd:leg1"]) == pytest.approx(ds.commands[0, 0] * 1000, rel=1e-15)
    assert float(first["cmd:joint2"]) == pytest.approx(np.rad2deg(ds.commands[0, 1]), rel=1e-15)
    assert float(first["x_mm"]) == pytest.approx(ds.readings[0, 0, 0, 0] * 1000, rel=1e-15)
    assert float(first["pose_rz_deg"]) == pytest.approx(
        np.rad2deg(ds.commanded_poses[0, 5]), rel=1e-15
    )


def test_unit_conversion_known_values(tmp_path: Path) -> None:
    path = tmp_path / "hand.csv"
    header = ["pose_id", "set", "target", "repeat", "cmd:leg1", "cmd:joint2"]
    header += ["pose_x_mm", "pose_y_mm", "pose_z_mm", "pose_rx_deg", "pose_ry_deg"]
    header += ["pose_rz_deg", "x_mm", "y_mm", "z_mm"]
    row = ["0", "calibration", "t", "0", "1500", "90", "250", "-500", "0", "180", "45", "-90"]
    save_rows(path, header, [[*row, "1000", "-2500", "125"]])
    sidecar = {
        "format": "pkm-calib-dataset",
        "version": 1,
        "model": "m",
        "frame": "base",
        "length_unit": "mm",
        "angle_unit": "deg",
        "actuators": {"leg1": "mm", "joint2": "deg"},
        "targets": ["t"],
    }
    sidecar_path(path).write_text(json.dumps(sidecar))
    ds = read_dataset(path)
    assert ds.commands[0, 0] == 1.5
    assert ds.commands[0, 1] == pytest.approx(np.pi / 2, rel=1e-15)
    assert ds.readings[0, 0, 0].tolist() == [1.0, -2.5, 0.125]
    assert ds.commanded_poses[0, :3].tolist() == [0.25, -0.5, 0.0]
    np.testing.assert_allclose(ds.commanded_poses[0, 3:], [np.pi, np.pi / 4, -np.pi / 2], 1e-15)
    assert ds.n_poses == 1 and ds.n_targets == 1 and ds.n_repeats == 1
    assert ds.notes == "" and ds.tracker is None


def test_measured_and_repeat_std() -> None:
    ds = make_dataset()
    base = ds.readings[:, :, :1]
    readings = np.concatenate([base, base + np.array([0.002, -0.004, 0.0])], axis=2)
    ds = Dataset(**{**vars(ds), "readings": readings})
    np.testing.assert_allclose(ds.measured, base[:, :, 0] + [0.001, -0.002, 0.0], atol=1e-15)
    expected = np.broadcast_to(np.array([0.002, 0.004, 0.0]) / np.sqrt(2), ds.measured.shape)
    np.testing.assert_allclose(ds.repeat_std, expected, atol=1e-15)


def test_repeat_std_zero_for_single_repeat() -> None:
    ds = make_dataset(n_repeats=1)
    assert ds.n_repeats == 1
    assert np.array_equal(ds.repeat_std, np.zeros((4, 3, 3)))
    assert np.array_equal(ds.measured, ds.readings[:, :, 0])


def test_subset_and_select_set() -> None:
    ds = make_dataset()
    by_mask = ds.subset(np.array([True, False, True, False]))
    assert by_mask.pose_ids.tolist() == [10, 7]
    assert np.array_equal(by_mask.readings, ds.readings[[0, 2]])
    assert np.array_equal(by_mask.commanded_poses, ds.commanded_poses[[0, 2]])
    by_index = ds.subset([3, 1])
    assert by_index.pose_ids.tolist() == [5, 3]
    assert by_index.order.tolist() == [3, 0]
    assert np.array_equal(by_index.commands, ds.commands[[3, 1]])
    ver = ds.select_set("verification")
    assert ver.pose_ids.tolist() == [7] and ver.n_poses == 1
    assert ds.select_set("calibration").pose_ids.tolist() == [10, 3, 5]
    with pytest.raises(DatasetError, match="no poses in set 'layer_1'"):
        ds.select_set("layer_1")
    with pytest.raises(DatasetError, match="mask has shape"):
        ds.subset([True, False])
    with pytest.raises(DatasetError, match="out of range"):
        ds.subset([4])


def test_dataset_is_read_only() -> None:
    ds = make_dataset()
    with pytest.raises(ValueError, match="read-only"):
        ds.readings[0, 0, 0, 0] = 1.0


def test_reordered_and_check_against() -> None:
    ds = make_dataset()
    ds.check_against(("joint2", "leg1"), ("target_3", "target_1", "target_2"))
    re = ds.reordered(("joint2", "leg1"), ("target_3", "target_1", "target_2"))
    assert re.actuator_names == ("joint2", "leg1") and re.actuator_units == ("deg", "mm")
    assert np.array_equal(re.commands, ds.commands[:, [1, 0]])
    assert np.array_equal(re.readings, ds.readings[:, [2, 0, 1]])
    with pytest.raises(DatasetError, match=r"missing actuators \['leg3'\]"):
        ds.check_against(("leg1", "joint2", "leg3"), TARGETS)
    with pytest.raises(DatasetError, match=r"unknown targets \['target_3'\]"):
        ds.reordered(ACTS, ("target_1", "target_2"))


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"commands": np.zeros((4, 3))}, "commands has shape"),
        ({"readings": np.full((4, 3, 2, 3), np.nan)}, "readings contains NaN"),
        ({"pose_ids": np.array([1, 1, 2, 3])}, "pose_ids must be unique"),
        ({"actuator_units": ("mm", "rad")}, "actuator_units"),
        ({"target_names": ("a", "a", "b")}, "target names must be non-empty and unique"),
        ({"sets": np.array(["c", "", "c", "c"])}, "sets must be"),
    ],
)
def test_constructor_validation(change: dict, match: str) -> None:
    with pytest.raises(DatasetError, match=match):
        Dataset(**{**vars(make_dataset()), **change})


# --- file errors -------------------------------------------------------------------------


def test_missing_sidecar(csv_file: Path) -> None:
    sidecar_path(csv_file).unlink()
    with pytest.raises(DatasetError, match=r"poses\.csv\.json: sidecar file not found"):
        read_dataset(csv_file)


def test_missing_csv(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="dataset CSV file not found"):
        read_dataset(tmp_path / "nothing.csv")


def test_malformed_json(csv_file: Path) -> None:
    sidecar_path(csv_file).write_text('{"format": "pkm-calib-dataset",')
    with pytest.raises(DatasetError, match=r"poses\.csv\.json: malformed JSON"):
        read_dataset(csv_file)


def test_wrong_format(csv_file: Path) -> None:
    edit_sidecar(csv_file, format="other")
    with pytest.raises(DatasetError, match="format is 'other', expected 'pkm-calib-dataset'"):
        read_dataset(csv_file)


def test_unsupported_version(csv_file: Path) -> None:
    edit_sidecar(csv_file, version=2)
    with pytest.raises(DatasetError, match="unsupported version 2"):
        read_dataset(csv_file)


@pytest.mark.parametrize("column", ["pose_id", "set", "target", "repeat", "x_mm", "z_mm"])
def test_missing_required_column(csv_file: Path, column: str) -> None:
    drop_column(csv_file, column)
    with pytest.raises(DatasetError, match=rf"missing required column\(s\): \['{column}'\]"):
        read_dataset(csv_file)


def test_actuator_without_cmd_column(csv_file: Path) -> None:
    drop_column(csv_file, "cmd:joint2")
    with pytest.raises(DatasetError, match=r"without a 'cmd:<name>' column: \['joint2'\]"):
        read_dataset(csv_file)


def test_undeclared_cmd_column(csv_file: Path) -> None:
    edit_sidecar(csv_file, actuators={"leg1": "mm"})
    with pytest.raises(DatasetError, match=r"not declared in the sidecar: \['cmd:joint2'\]"):
        read_dataset(csv_file)


def test_partial_commanded_pose_columns(csv_file: Path) -> None:
    drop_column(csv_file, "pose_ry_deg")
    with pytest.raises(
        DatasetError, match=r"missing commanded-pose column\(s\): \['pose_ry_deg'\]"
    ):
        read_dataset(csv_file)


@pytest.mark.parametrize(
    ("column", "value", "match"),
    [
        ("y_mm", "nan", "non-finite value 'nan'"),
        ("cmd:leg1", "inf", "non-finite value 'inf'"),
        ("x_mm", "abc", "expected a number, got 'abc'"),
        ("pose_id", "1.5", "expected an integer, got '1.5'"),
    ],
)
def test_bad_numeric_value(csv_file: Path, column: str, value: str, match: str) -> None:
    edit_cell(csv_file, 4, column, value)
    with pytest.raises(DatasetError, match=rf"poses\.csv line 6 \(data row 5\), column '{column}'"):
        read_dataset(csv_file)
    with pytest.raises(DatasetError, match=match):
        read_dataset(csv_file)


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("length_unit", "m", "length_unit is 'm', expected 'mm'"),
        ("angle_unit", "rad", "angle_unit is 'rad', expected 'deg'"),
        ("actuators", {"leg1": "m", "joint2": "deg"}, "actuator 'leg1' has unit 'm'"),
    ],
)
def test_unit_mismatch(csv_file: Path, key: str, value: object, match: str) -> None:
    edit_sidecar(csv_file, **{key: value})
    with pytest.raises(DatasetError, match=match):
        read_dataset(csv_file)


def test_expected_model_mismatch(csv_file: Path) -> None:
    with pytest.raises(DatasetError, match="model is 'hexapod_rrrprr', expected 'delta'"):
        read_dataset(csv_file, expected_model="delta")


def test_inconsistent_command(csv_file: Path) -> None:
    edit_cell(csv_file, 3, "cmd:joint2", "12.5")
    with pytest.raises(
        DatasetError,
        match=r"inconsistent actuator 'joint2' \(column 'cmd:joint2'\) for pose 10: 12\.5 here",
    ):
        read_dataset(csv_file)


def test_inconsistent_set(csv_file: Path) -> None:
    edit_cell(csv_file, 7, "set", "verification")
    with pytest.raises(
        DatasetError, match=r"inconsistent set \(column 'set'\) for pose 3: 'verification' here"
    ):
        read_dataset(csv_file)


def test_duplicate_row(csv_file: Path) -> None:
    header, rows = load_rows(csv_file)
    save_rows(csv_file, header, [*rows, rows[2]])
    match = r"duplicate row for pose 10, target 'target_2', repeat 0 \(first at line 4\)"
    with pytest.raises(DatasetError, match=match):
        read_dataset(csv_file)


def test_pose_missing_target(csv_file: Path) -> None:
    header, rows = load_rows(csv_file)
    save_rows(csv_file, header, [r for r in rows if not (r[0] == "7" and r[2] == "target_3")])
    with pytest.raises(DatasetError, match="pose 7 has no rows for target 'target_3'"):
        read_dataset(csv_file)


def test_pose_missing_repeat(csv_file: Path) -> None:
    header, rows = load_rows(csv_file)
    keep = [r for r in rows if not (r[0] == "5" and r[2] == "target_1" and r[3] == "1")]
    save_rows(csv_file, header, keep)
    with pytest.raises(
        DatasetError, match=r"pose 5, target 'target_1' is missing repeat\(s\) \[1\]"
    ):
        read_dataset(csv_file)


def test_undeclared_target(csv_file: Path) -> None:
    edit_cell(csv_file, 0, "target", "smr_9")
    with pytest.raises(DatasetError, match="target 'smr_9' is not declared in the sidecar"):
        read_dataset(csv_file)


def test_unknown_column(csv_file: Path) -> None:
    header, rows = load_rows(csv_file)
    save_rows(csv_file, [*header, "temp_c"], [[*r, "20.5"] for r in rows])
    with pytest.raises(DatasetError, match=r"unknown column\(s\): \['temp_c'\]"):
        read_dataset(csv_file)


def test_wrong_field_count(csv_file: Path) -> None:
    header, rows = load_rows(csv_file)
    rows[1] = rows[1][:-1]
    save_rows(csv_file, header, rows)
    with pytest.raises(DatasetError, match=r"line 3 \(data row 2\): 16 fields, the header has 17"):
        read_dataset(csv_file)


def test_empty_file(csv_file: Path) -> None:
    header, _ = load_rows(csv_file)
    save_rows(csv_file, header, [])
    with pytest.raises(DatasetError, match=r"poses\.csv: no data rows"):
        read_dataset(csv_file)
    csv_file.write_text("")
    with pytest.raises(DatasetError, match="empty file"):
        read_dataset(csv_file)


def test_other_frame_is_recorded(tmp_path: Path) -> None:
    ds = Dataset(**{**vars(make_dataset()), "frame": "tracker"})
    back = read_dataset(write_dataset(ds, tmp_path / "poses.csv"))
    assert back.frame == "tracker"


# --- atomic writes -----------------------------------------------------------------------


def test_write_into_missing_directory_raises(tmp_path: Path) -> None:
    with pytest.raises(OSError, match=r"No such file or directory; none of poses\.csv"):
        write_dataset(make_dataset(), tmp_path / "absent" / "poses.csv")
    assert not (tmp_path / "absent").exists()


def test_failed_replace_keeps_previous_files(
    csv_file: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = (csv_file.read_bytes(), sidecar_path(csv_file).read_bytes())

    def boom(src: str, dst: str) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_dataset(make_dataset(seed=1), csv_file)
    assert (csv_file.read_bytes(), sidecar_path(csv_file).read_bytes()) == before
    assert sorted(p.name for p in csv_file.parent.iterdir()) == ["poses.csv", "poses.csv.json"]
    monkeypatch.undo()
    assert read_dataset(csv_file).meta == {"seed": 0}
