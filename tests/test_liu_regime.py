"""The regime map (scenario liu_regime) on a tiny grid: its summary contract, its test
placements, its aggregation, its figures and recording. The full grid (4 noise levels x 3
placements x 100 draws, about 2 minutes) is not run here."""

from __future__ import annotations

import json

import numpy as np
import pytest
from recording_faces import assert_every_face_has_data

from scenarios.config import ScenarioError, load_scenario
from scenarios.runner import run_scenario
from scenarios.studies.liu_regime.study import aggregate_cells, placement_poses, tilted
from scenarios.studies.liu_vs_ols.pipeline import CONTROL, make_bench
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import inverse
from twin.rotations import matrix_from_rpy

ESTIMATORS = ("liu_paper_deg", "liu", "ridge", "pcr")
SMALL = {  # the shipped file's settings and a tiny grid's
    "sigmas_mm = [0.005, 0.01, 0.02, 0.05]": "sigmas_mm = [0.005, 0.05]",
    "draws = 100": "draws = 2",
    'engine = "ray"': 'engine = "local"',
}


def tiny(tmp_path, extra: dict[str, str] | None = None) -> str:
    text = load_scenario("liu_regime").path.read_text()
    for old, new in {**SMALL, **(extra or {})}.items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "liu_regime.toml"
    path.write_text(text)
    return str(path)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("regime")
    s, out = run_scenario(tiny(tmp), tmp / "results", quiet=True)
    return s, out


def test_the_shipped_grid_is_the_issues():
    s = load_scenario("liu_regime")
    assert s.data["regime"]["sigmas_mm"] == [0.005, 0.01, 0.02, 0.05]
    assert s.data["regime"]["placements"] == ["interpolated", "extrapolated", "tilted"]
    assert s.data["regime"]["draws"] >= 20
    labels = [e if isinstance(e, str) else e["label"] for e in s.data["fine"]["estimators"]]
    assert labels == ["ols", *ESTIMATORS]


def test_summary_keys_of_every_cell(run):
    _, out = run
    written = json.loads((out / "summary.json").read_text())
    assert set(written["cells"]) == {
        f"{p}/{sg}" for p in ("interpolated", "extrapolated", "tilted") for sg in ("0.005", "0.05")
    }
    for cell in written["cells"].values():
        assert cell["n_draws"] == 2
        assert set(cell["estimators"]) == set(ESTIMATORS)
        for e in cell["estimators"].values():
            m = e["minus_ols_um"]
            assert m["p05"] <= m["median"] <= m["p95"]
            assert 0.0 <= e["better_fraction"] <= 1.0
        assert cell["ols_test_pos_mean_um"]["median"] > 1.0  # the effects' tens of um
    assert written["scoring"]["order_control_um"] < 0.05
    # a larger tracker noise, the same truths and placements: OLS's error grows
    cells = written["cells"]
    for p in ("interpolated", "extrapolated", "tilted"):
        lo, hi = cells[f"{p}/0.005"], cells[f"{p}/0.05"]
        assert hi["ols_test_pos_mean_um"]["median"] > lo["ols_test_pos_mean_um"]["median"]


def test_figures_report_and_recording(run):
    s, out = run
    assert set(s["figures"]) == {f"regime_{e}" for e in ESTIMATORS}
    for file in s["figures"].values():
        assert (out / file).stat().st_size > 5000
    text = (out / "report.md").read_text()
    assert "In the paper's cell (interpolated/0.005) the paper's estimator" in text
    assert "![regime_liu_paper_deg](regime_liu_paper_deg.png)" in text
    rerun_chunk = pytest.importorskip("rerun.chunk")
    store = rerun_chunk.RrdReader(str(out / "liu_regime.rrd")).store()
    entities = set(store.schema().entity_paths())
    assert {f"/figures/regime_{e}" for e in ESTIMATORS} <= entities
    assert "/report" in entities
    views = {v["name"] for v in assert_every_face_has_data(out / "liu_regime.rrd")}
    named = {f"regime {e}".replace("_", " ") for e in ESTIMATORS}
    assert named | {"report: key numbers"} <= views


def test_placements_are_where_the_issue_puts_them():
    s = load_scenario("liu_regime")
    test = placement_poses(s, 7)
    mid, ext, tilt = (test[p]["poses"] for p in ("interpolated", "extrapolated", "tilted"))
    assert np.allclose(mid[:, 2], 0.0) and np.allclose(mid[:, 3:], 0.0) and len(mid) == 49
    # 60 mm below the lower calibration layer (-60 mm), nodes too near a stroke end left out
    assert np.allclose(ext[:, 2], -0.120) and 40 <= len(ext) < 49
    np.testing.assert_allclose(tilt[:, :3], mid[:, :3])  # the same points, the head tilted
    z_tool = matrix_from_rpy(tilt[:, 3:])[:, :, 2]
    angle = np.degrees(np.arccos(np.clip(z_tool[:, 2], -1, 1)))
    assert np.all(angle >= 5.0 - 1e-9) and np.all(angle <= 10.0 + 1e-9)
    assert angle.max() - angle.min() > 3.0  # spread over the range, not one angle
    # the tilted poses are reachable on the nominal machine: its forward kinematics of their
    # commands gives them back
    nominal = make_bench(s).machine.nominal
    for pose in tilt[:5]:
        sol = inverse(nominal, pose)
        back = forward_batch(nominal, sol.actuators[None, :])
        np.testing.assert_allclose(back.tool_position[0], pose[:3], atol=1e-9)


def test_tilts_are_about_horizontal_axes():
    poses = np.zeros((200, 6))
    out = tilted(poses, [5.0, 10.0], seed=3)
    r = matrix_from_rpy(out[:, 3:])
    # a rotation about a horizontal axis keeps that axis: r's axis has no vertical part
    w = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], 1)
    assert np.all(np.abs(w[:, 2]) < 1e-12 * np.abs(w).max())
    np.testing.assert_array_equal(out, tilted(poses, [5.0, 10.0], seed=3))  # seeded


def test_aggregate_cells_differences_and_fractions():
    def row(mean):
        return {"pos_mean_mm": mean, "pos_max_mm": 2 * mean}

    results = []
    for i in range(10):
        ols = 0.040 + 1e-4 * i
        layers = {"ols": row(ols), CONTROL: row(ols), "liu": row(ols + (i - 6.5) * 1e-4)}
        results.append({"sigma_mm": 0.01, "layers": {"tilted": layers}})
    cells = aggregate_cells(results, ["tilted"], [0.01], ["liu"])
    c = cells["tilted/0.01"]
    assert c["n_draws"] == 10 and c["order_control_um"] == 0.0
    liu = c["estimators"]["liu"]
    assert liu["better_fraction"] == pytest.approx(7 / 10)  # i = 0..6 below OLS
    assert liu["minus_ols_um"]["median"] == pytest.approx(-0.2, abs=1e-9)  # (4.5 - 6.5) 0.1 um
    assert liu["minus_ols_max_um"]["median"] == pytest.approx(-0.4, abs=1e-9)
    assert liu["better_fraction_max"] == pytest.approx(7 / 10)  # the max is twice the mean
    # OLS's max 2 x (40 + 0.1 i) um: median over i = 0..9 is 2 x 40.45
    assert c["ols_test_pos_max_um"]["median"] == pytest.approx(80.9, abs=1e-9)


def test_bad_placements_are_refused(tmp_path):
    path = tiny(tmp_path, {'"tilted"]': '"tilted", "sideways"]'})
    with pytest.raises(ScenarioError, match="sideways"):
        load_scenario(path)
