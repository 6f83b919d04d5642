"""calib plan on a real arm's pool: the UR5's 1000 measured calibration poses (a public
laser-tracker dataset, /work/shared/data/real_ur5), 60 chosen, judged on its own 20 held-out
poses (the source's random file): better than the median of random 60-pose subsets and within
1.15x of using all 1000 (the issue's bars)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from calib.cli.commands import main
from calib.data import read_dataset
from calib.fit import calibrate, model_from_files

REAL = Path("/work/shared/data/real_ur5")
pytestmark = pytest.mark.skipif(
    not (REAL / "real_ur5.csv").is_file(), reason="the real UR5 data are not on this machine"
)


def _held_out_rms(model, cal, test, ids) -> float:
    """identify (the command's defaults) on the rows ``ids``; 3D RMS error on the test rows."""
    run = calibrate(model, cal.subset(np.isin(cal.pose_ids, ids)))
    # the run's own model: identify may have kept the fuller variant (the base placement)
    pred = run.model.predict(run.result.values, np.array(test.commands)).targets
    return float(np.sqrt(np.mean(np.sum((test.measured - pred) ** 2, axis=-1))) * 1e3)


def test_planned_60_of_the_ur5_pool_beat_random_and_nearly_match_all(tmp_path, capsys):
    out = tmp_path / "program.csv"
    args = ["plan", "--model", str(REAL / "real_ur5.xml"), "--errors"]
    args += [str(REAL / "real_ur5.params.toml"), "--candidates", str(REAL / "real_ur5.csv")]
    args += ["--set", "calibration", "--n", "60", "--n-test", "0", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "1000 of 1000 candidate poses feasible" in printed
    rows = list(csv.DictReader(out.open()))
    ids = [int(r["pose_id"]) for r in rows]
    assert len(ids) == len(set(ids)) == 60
    assert {r["set"] for r in rows} == {"calibration"}
    model = model_from_files(str(REAL / "real_ur5.xml"), str(REAL / "real_ur5.params.toml"))
    data = read_dataset(REAL / "real_ur5.csv")
    cal, test = data.select_set("calibration"), data.select_set("test")
    assert set(ids) <= set(cal.pose_ids.tolist())
    # the program's commands are the pool's (mm/deg written to 10 significant digits)
    by_id = dict(zip(cal.pose_ids.tolist(), np.degrees(np.array(cal.commands)), strict=True))
    for r in rows:
        got = [float(r[f"cmd:J{k}"]) for k in range(1, 7)]
        assert np.allclose(got, by_id[int(r["pose_id"])], rtol=0, atol=1e-6)
    planned = _held_out_rms(model, cal, test, ids)
    everything = _held_out_rms(model, cal, test, cal.pose_ids)
    rng = np.random.default_rng(0)
    random = [
        _held_out_rms(model, cal, test, rng.choice(cal.pose_ids, 60, replace=False))
        for _ in range(20)
    ]
    # measured: planned 0.1048, all 1000 0.1056, random median 0.1636 mm
    print(f"planned {planned:.4f} all {everything:.4f} random median {np.median(random):.4f}")
    assert planned < np.median(random)
    assert planned <= 1.15 * everything
