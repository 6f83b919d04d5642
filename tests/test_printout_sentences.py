"""What diagnose and identify print comes from the numbers beside it: fed other numbers, the
sentence moves with them."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from calib.diagnosis.fit import undetermined
from calib.diagnosis.problem import Problem


class _Columns:
    """A candidate whose design is given columns (N, R, k) at any shape."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = x

    def design(self, ctx, shape) -> np.ndarray:
        return self.x


def test_an_effect_parameter_the_geometry_absorbs_is_undetermined():
    """A column that is a combination of the geometry's, or of another effect parameter's,
    has no value; a column outside their span has one, however small its effect."""
    rng = np.random.default_rng(0)
    n, rows, p = 40, 6, 4
    geo = rng.normal(size=(n, rows, p))
    own = rng.normal(size=(n, rows))
    x = np.stack(
        [
            geo[:, :, 0] - 2.5 * geo[:, :, 3],  # the geometry's
            own,
            -3.0 * own,  # the previous one's: both undetermined
            1e-6 * rng.normal(size=(n, rows)),  # small but its own
            np.zeros((n, rows)),  # not seen: no column, counted elsewhere
        ],
        axis=2,
    )
    prob = Problem(rng.normal(size=(n, rows)), geo)
    ctx, ev = SimpleNamespace(n_poses=n), SimpleNamespace(shapes=(float("nan"),))
    got = undetermined(prob, ctx, [_Columns(x)], ev)
    assert got.tolist() == [True, True, True, False, False]
    # the same columns without the geometric combination: each determined
    x2 = x.copy()
    x2[:, :, 0] = rng.normal(size=(n, rows))
    x2[:, :, 2] = rng.normal(size=(n, rows))
    got = undetermined(prob, ctx, [_Columns(x2)], ev)
    assert got.tolist() == [False] * 5


def test_weakly_identified_means_wide_and_not_determined_by_its_value():
    """Above half the physical range and within DETERMINED_Z standard errors of zero: weak;
    a 6-sigma estimate is determined whatever the range; below half the range never weak."""
    from calib.fit.prior import DETERMINED_Z, physical_ranges, weakly_identified
    from twin.formats.parameter_file import load_parameter_set
    from twin.mechanism import Mechanism

    root = Path(__file__).resolve().parent.parent / "models"
    params = load_parameter_set(
        root / "arm6r.params.toml", Mechanism.from_xml(root / "arm6r.xml").model
    )
    half = 0.5 * physical_ranges(params)
    std = 2.0 * half  # every one wide
    std[1] = 0.5 * half[1]  # ... but this one
    z = np.full(len(params), 1.0)
    z[0], z[2], z[3] = 6.0, DETERMINED_Z, 0.999 * DETERMINED_Z
    weak = {w["name"] for w in weakly_identified(params.names, std, params, None, z * std)}
    names = params.names
    assert names[0] not in weak and names[2] not in weak  # 6 and exactly Z sigma: determined
    assert names[1] not in weak  # narrow
    assert names[3] in weak and names[4] in weak
    # without values: the range alone, as before
    plain = {w["name"] for w in weakly_identified(params.names, std, params)}
    assert plain == set(names) - {names[1]}


class _Held:
    """An evaluation's held-out RMS per fold scheme (mm per coordinate)."""

    def __init__(self, blocked: float, random: float) -> None:
        self.by = {"blocked": blocked, "random": random}

    def heldout_rms_mm(self, scheme: str | None = None) -> float:
        if scheme is None:
            return float(np.sqrt(np.mean([v**2 for v in self.by.values()])))
        return self.by[scheme]


def test_the_physical_candidates_sentence_moves_with_the_table():
    from calib.diagnosis.verdict import lowering, physical_sentence

    base = _Held(0.070, 0.066)
    singles = {
        "gain_error": _Held(0.068, 0.064),  # lower in both schemes
        "backlash": _Held(0.0703, 0.0662),  # higher in both
        "zero_drift": _Held(0.143, 0.065),  # lower in one only: not lower
        "encoder_eccentricity": _Held(0.062, 0.059),
    }
    assert [n for n, _ in lowering(base, singles)] == ["encoder_eccentricity", "gain_error"]
    text = physical_sentence(base, singles, 0.05)
    assert text.startswith("2 physical candidate(s) lower the held-out error")
    pooled = lambda a, b: f"{np.sqrt((a**2 + b**2) / 2):.4g} mm"  # noqa: E731
    assert f"encoder_eccentricity {pooled(0.062, 0.059)}" in text
    assert f"gain_error {pooled(0.068, 0.064)}" in text
    assert f"geometry alone {pooled(0.070, 0.066)}" in text
    assert "5 %" in text and "no physical candidate" not in text
    worse = {k: _Held(0.08, 0.07) for k in singles}
    assert physical_sentence(base, worse, 0.05) == "no physical candidate lowers the held-out error"


def _no_declared_noise(case) -> None:
    """Strip the sidecar's tracker.sigma_mm: nothing declares the noise, no repeats give it."""
    import json

    from calib.data import sidecar_path

    side = sidecar_path(case.data)
    meta = json.loads(side.read_text())
    meta["tracker"].pop("sigma_mm", None)
    side.write_text(json.dumps(meta))


def test_diagnose_and_identify_share_one_noise_rule_and_the_none_row_is_test_before(
    tmp_path, capsys
):
    import re

    import real_like_cases as cases

    from calib.cli.commands import main

    case = cases.arm_case(tmp_path, seed=8, n_cal=60, n_test=20, name="undeclared")
    _no_declared_noise(case)
    files = ["--model", str(case.model), "--errors", str(case.errors), "--data", str(case.data)]
    main(["identify", *files, "--set", "calibration"])
    said = capsys.readouterr()
    assert "0.05 mm per coordinate (assumed)" in said.out + said.err
    code = main(["diagnose", *files, "--set", "calibration", "--test-set", "test"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "assumed 0.05 mm, as identify assumes" in text
    none_row = re.search(r"^  none .* test RMS ([0-9.]+) mm", text, re.M)
    before = re.search(r"^test before: .* RMS ([0-9.]+) mm", text, re.M)
    assert none_row and before
    assert abs(float(none_row.group(1)) - float(before.group(1))) <= 5e-5  # 5 vs 4 decimals


def test_diagnose_checks_its_inputs_before_the_fit(tmp_path, capsys, monkeypatch):
    import real_like_cases as cases

    import calib.cli.diagnose as cmd
    from calib.cli.commands import main

    case = cases.arm_case(tmp_path, seed=8, n_cal=20, n_test=5, name="checked")

    def no_fit(args):
        raise AssertionError("the fit ran before the inputs were checked")

    monkeypatch.setattr(cmd, "run_fit", no_fit)
    files = ["--model", str(case.model), "--errors", str(case.errors), "--data", str(case.data)]
    assert main(["diagnose", *files, "--test-set", "nosuchset"]) == 2
    assert "nosuchset" in capsys.readouterr().err
    assert main(["diagnose", *files, "--test", str(tmp_path / "missing.csv")]) == 2
    assert "missing.csv" in capsys.readouterr().err
