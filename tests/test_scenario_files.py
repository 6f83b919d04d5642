"""Scenario files are validated like datasets, and a results folder is replaced whole.

Each bad input is a committed scenario copied into a temporary folder with one thing changed;
its error must name the file, the key as written in the file and, for a typo, the closest
known key. No study runs in the validation tests; the atomicity tests replace the study by a
stub that writes a file (and raises), so they take milliseconds.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

import scenarios.runner as runner
from scenarios.__main__ import main as cli
from scenarios.config import REPO_ROOT, SCENARIO_DIR, SCHEMAS, ScenarioError, load_scenario
from scenarios.runner import STUDIES, run_scenario
from twin.exceptions import WorkspaceError

HEX = "studies/hexapod_paper/hexapod_paper.toml"
UND = "studies/undeclared_effect/undeclared_effect.toml"
LIU = "studies/liu_vs_ols/liu_vs_ols.toml"
LIU_GEO = "studies/liu_vs_ols/liu_vs_ols_geometry.toml"
POL = "studies/polisher_identifiability/polisher_identifiability.toml"
OPT = "studies/optimal_poses/optimal_poses.toml"
TRUTH = SCENARIO_DIR / "truth" / "hexapod_table2.toml"


def _copy(tmp_path: Path, base: str, old="", new="", name: str = "bad.toml") -> Path:
    """``scenarios/<base>`` copied to ``tmp_path/<name>`` with ``old`` replaced by ``new``
    (strings, or tuples of strings replaced pairwise)."""
    text = (SCENARIO_DIR / base).read_text()
    pairs = zip(old, new, strict=True) if isinstance(old, tuple) else [(old, new)]
    for o, n in pairs:
        if o:
            assert o in text, f"{o!r} not in {base}"
            text = text.replace(o, n, 1)
    path = tmp_path / name
    path.write_text(text)
    return path


# (id, base scenario, text to replace, replacement, substrings the message must contain)
BAD = [
    ("unknown top-level key", HEX, "seed = 2019", "seed = 2019\nsede = 3",
     ["unknown key 'sede'", "did you mean 'seed'"]),
    ("unknown nested key", HEX, "repeats = 1", "repeat = 1",
     ["unknown key 'tracker.repeat'", "did you mean 'tracker.repeats'"]),
    ("effect instead of effects", UND, "effects = [", "effect = [",
     ["unknown key 'truth.effect'", "did you mean 'truth.effects'"]),
    ("right key in the wrong table", UND, "seed = 7", "seed = 7\nsigma_mm = 0.005",
     ["unknown key 'sigma_mm'", "did you mean 'tracker.sigma_mm'"]),
    ("negative tracker noise", UND, "sigma_mm = 0.005", "sigma_mm = -0.005",
     ["'tracker.sigma_mm' must be >= 0", "-0.005"]),
    ("negative tracker noise spec", HEX, 'noise = "none"', 'noise = "-5 um"',
     ["'tracker.noise'", "cannot parse noise spec"]),
    ("negative pose noise", HEX, "rotation_deg = 0.004", "rotation_deg = -0.004",
     ["'pose_noise.rotation_deg' must be >= 0"]),
    ("zero calibration poses", UND, "calibration_poses = 80", "calibration_poses = 0",
     ["'plan.calibration_poses' must be >= 1"]),
    ("zero poses in a plan", HEX, "few_poses = 29", "few_poses = 0",
     ["'plans.few_poses' must be >= 1, got 0"]),
    ("nodes_per_axis = 0", HEX, "nodes_per_axis = 3", "nodes_per_axis = 0",
     ["'verification.nodes_per_axis' must be >= 1"]),
    ("margin out of range", HEX, "margin = 0.25", "margin = 0.75",
     ["'verification.margin' must be < 0.5"]),
    ("effect argument typo", UND, "pitch_m = 4e-3", "pitch_mm = 4e-3",
     ["'truth.effects[0].pitch_mm'", "effect 'lead_error_harmonic' has no argument 'pitch_mm'",
      "did you mean 'pitch_m'"]),
    ("effect argument of the wrong type", UND, "delta_K = 8.0",
     'delta_K = "hot"', ["'truth.effects[1].delta_K'", "float"]),
    ("unknown effect name", UND, 'kind = "thermal_warmup"', 'kind = "thermal_warmpu"',
     ["'truth.effects[1].kind'", "unknown effect 'thermal_warmpu'",
      "did you mean 'thermal_warmup'"]),
    ("name ..", HEX, 'name = "hexapod_paper"', 'name = ".."', ["'name'", "'..'"]),
    ("name with /", HEX, 'name = "hexapod_paper"', 'name = "../elsewhere/x"',
     ["'name'", "path separators"]),
    ("name with a backslash", HEX, 'name = "hexapod_paper"', 'name = "a\\\\b"',
     ["'name'", "path separators"]),
    ("empty name", HEX, 'name = "hexapod_paper"', 'name = ""', ["'name' must not be empty"]),
    ("wrong type: string for int", HEX, "seed = 2019", 'seed = "abc"',
     ["'seed' must be int, got 'abc'"]),
    ("wrong type: float for int", HEX, "repeats = 1", "repeats = 1.5",
     ["'tracker.repeats' must be int, got 1.5"]),
    ("wrong type: value for table", POL, ("[checks]\nfd_poses = 3", "study ="),
     ("", "checks = 3\nstudy ="), ["'checks' must be a table", "got 3"]),
    ("wrong type: table for value", UND, "[tracker]\nsigma_mm = 0.005",
     "[tracker.sigma_mm]\nvalue = 0.005", ["'tracker.sigma_mm' must be float"]),
    ("value meant for a table lands in the table above", POL, "[checks]\nfd_poses = 3",
     "checks = 3", ["unknown key 'plan.checks'", "did you mean 'checks'"]),
    ("negative seed", UND, "seed = 7", "seed = -7", ["'seed' must be >= 0"]),
    ("tracker position of two numbers", HEX, "position_mm = [1200.0, 0.0, 300.0]",
     "position_mm = [1200.0, 0.0]", ["'tracker.position_mm' must have 3 entries"]),
    ("pose noise kind typo", HEX, 'kind = "uniform"', 'kind = "unifrom"',
     ["'pose_noise.kind' must be one of", "did you mean 'uniform'"]),
    ("values file and random truth both", HEX, "[tracker]",
     "[truth.random]\ntranslation_mm = 1.0\n\n[tracker]", ["not both", "truth.values_file"]),
    ("missing key", HEX, "many_poses = 256\n", "", ["missing key 'plans.many_poses'"]),
    ("a hundred million poses", HEX, "many_poses = 256", "many_poses = 100000000",
     ["'plans.many_poses' must be <= 100000, got 100000000"]),
    ("missing table", UND, "[plan]\n", "[plam]\n",
     ["unknown key 'plam'", "did you mean 'plan'", "missing table [plan]"]),
    ("unknown study", HEX, 'study = "hexapod_paper"', 'study = "hexapod_papr"',
     ["unknown study 'hexapod_papr'", "did you mean 'hexapod_paper'"]),
    ("estimator option typo", LIU, "k = 1.0 }", "kk = 1.0 }",
     ["'fine.estimators[2].kk'", "estimator 'liu' has no option 'kk'", "did you mean 'k'"]),
    ("unknown estimator", LIU, '"ridge",\n    "pcr",\n]', '"ridge",\n    "pcrr",\n]',
     ["'fine.estimators[6]'", "unknown estimator 'pcrr'", "did you mean 'pcr'"]),
    ("bad estimator option value", LIU, "k = 1.0 }", "k = -1.0 }",
     ["'fine.estimators[2]'", "Liu k must be"]),
    ("one Monte Carlo run", LIU, "runs = 10000", "runs = 1", ["'monte_carlo.runs' must be >= 2"]),
    ("negative random truth", LIU_GEO, "translation_mm = 1.0", "translation_mm = -1.0",
     ["'truth.random.translation_mm' must be >= 0"]),
    ("typo in an array of tables", POL, "nodes_per_side = 5 },", "node_per_side = 5 },",
     ["unknown key 'plan_comparison.plans[1].node_per_side'",
      "did you mean 'plan_comparison.plans[1].nodes_per_side'"]),
    ("max below initial poses", OPT, "max_poses = 40", "max_poses = 5",
     ["'design.max_poses' must be >= 'design.initial_poses'"]),
    ("missing model file", UND, 'model = "models/hexapod_rrrprr.xml"',
     'model = "models/nope.xml"', ["'model'", "models/nope.xml' not found", "looked in"]),
]  # fmt: skip


@pytest.mark.parametrize(
    ("base", "old", "new", "expected"),
    [pytest.param(*case[1:], id=case[0]) for case in BAD],
)
def test_bad_scenario_names_file_and_key(tmp_path, base, old, new, expected):
    path = _copy(tmp_path, base, old, new)
    with pytest.raises(ScenarioError) as info:
        load_scenario(str(path))
    message = str(info.value)
    assert str(path) in message  # the file
    for part in expected:
        assert part in message, f"{part!r} not in {message!r}"
    assert "position_m'" not in message and "sigma_m'" not in message  # no internal SI names


def test_at_least_twenty_bad_inputs():
    assert len(BAD) >= 20


def test_several_problems_are_reported_together(tmp_path):
    text = (SCENARIO_DIR / UND).read_text()
    text = text.replace("sigma_mm = 0.005", "sigma_mm = -1.0").replace("seed = 7", "sede = 7")
    path = tmp_path / "two.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=r"3 problems") as info:
        load_scenario(str(path))
    for part in ("'tracker.sigma_mm' must be >= 0", "unknown key 'sede'", "missing key 'seed'"):
        assert part in str(info.value)


def test_unknown_parameter_in_truth_values_file(tmp_path):
    """A values file beside the copied scenario is used first; its typo names file and name."""
    (tmp_path / "truth").mkdir()
    bad = tmp_path / "truth" / "hexapod_table2.toml"
    bad.write_text(TRUTH.read_text().replace('"leg3.base.dy"', '"leg3.bsae.dy"'))
    path = _copy(tmp_path, HEX)
    with pytest.raises(ScenarioError) as info:
        load_scenario(str(path))
    message = str(info.value)
    for part in (
        str(path),
        str(bad),
        "unknown parameter 'leg3.bsae.dy'",
        "did you mean 'leg3.base.dy'",
    ):
        assert part in message, f"{part!r} not in {message!r}"


def test_copied_scenario_still_finds_its_truth_file(tmp_path):
    path = _copy(tmp_path, HEX, name="my_copy.toml")
    scenario = load_scenario(str(path))
    assert scenario.name == "hexapod_paper"
    assert scenario.resolve(scenario.get("truth.values_file", str)) == TRUTH
    assert scenario.resolve(scenario.get("model", str)) == REPO_ROOT / "models/hexapod_rrrprr.xml"


def test_missing_truth_file_lists_every_place_looked(tmp_path):
    path = _copy(tmp_path, HEX, "truth/hexapod_table2.toml", "truth/nope.toml")
    with pytest.raises(ScenarioError) as info:
        load_scenario(str(path))
    message = str(info.value)
    assert "'truth.values_file'" in message and "'truth/nope.toml' not found" in message
    for base in (tmp_path, SCENARIO_DIR, REPO_ROOT):
        assert str(base / "truth" / "nope.toml") in message


def test_file_name_must_give_a_plain_name_without_a_name_key(tmp_path):
    text = (SCENARIO_DIR / HEX).read_text().replace('name = "hexapod_paper"\n', "")
    path = tmp_path / "a b.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match="from the file name"):
        load_scenario(str(path))
    path = tmp_path / "ab.toml"
    path.write_text(text)
    assert load_scenario(str(path)).name == "ab"


@pytest.mark.parametrize(
    "path", sorted(SCENARIO_DIR.glob("studies/*/*.toml")), ids=lambda p: p.stem
)
def test_committed_scenarios_load_and_validate(path):
    scenario = load_scenario(str(path))
    assert scenario.study in SCHEMAS and scenario.study in STUDIES
    assert scenario.name == path.stem


def test_every_study_has_a_schema():
    assert set(SCHEMAS) == set(STUDIES)


def test_a_study_reading_an_undeclared_key_is_caught():
    scenario = load_scenario("undeclared_effect")
    with pytest.raises(LookupError, match="does not declare"):
        scenario.get("tracker.noise", str, "none")


def test_utf8_byte_order_mark_is_accepted(tmp_path):
    """A scenario saved by an editor that writes a UTF-8 BOM (was 'Invalid statement')."""
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + (SCENARIO_DIR / HEX).read_bytes())
    assert load_scenario(str(path)).data == load_scenario(str(SCENARIO_DIR / HEX)).data


def test_study_modules_write_only_into_their_out_dir():
    for module in STUDIES.values():
        for name in module:
            source = (REPO_ROOT / (name.replace(".", "/") + ".py")).read_text()
            assert "REPO_ROOT" not in source and not re.search(r"[\"']results[/\"']", source), name


def test_cli_prints_error_and_exits_2_without_traceback(tmp_path, capsys):
    path = _copy(tmp_path, UND, "pitch_m = 4e-3", "pitch_mm = 4e-3")
    assert cli(["run", str(path), "--results", str(tmp_path / "results"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "pitch_mm" in err and "Traceback" not in err
    assert not (tmp_path / "results").exists()  # nothing ran, nothing was written


# ------------------------------------------------------------ results replaced whole


def _stub_study(monkeypatch, behaviour):
    """Replace the study by ``behaviour(out_dir)`` and a one-line report: no computation."""

    def run(scenario, out_dir, progress, recorder):
        return behaviour(out_dir)

    monkeypatch.setattr(runner, "_study", lambda name: (run, lambda s: f"# {s['scenario']}\n"))


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _earlier_run(tmp_path: Path, monkeypatch) -> tuple[Path, dict[str, bytes]]:
    def ok(out_dir):
        (out_dir / "datasets").mkdir()
        (out_dir / "datasets" / "calibration.csv").write_text("old data\n")
        (out_dir / "stale.txt").write_text("from the earlier run\n")
        return {"scenario": "undeclared_effect", "run": 1}

    _stub_study(monkeypatch, ok)
    _, out_dir = run_scenario("undeclared_effect", tmp_path, quiet=True, record=False)
    assert out_dir == tmp_path / "undeclared_effect"
    return out_dir, _snapshot(out_dir)


def _leftovers(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir() if p.name.startswith("."))


@pytest.mark.parametrize("error", [RuntimeError("the study failed"), KeyboardInterrupt()])
def test_failed_run_leaves_the_earlier_results_untouched(tmp_path, monkeypatch, error):
    out_dir, before = _earlier_run(tmp_path, monkeypatch)
    assert {"summary.json", "report.md", "stale.txt", "datasets/calibration.csv"} <= set(before)
    seen = {}

    def fails(work):
        seen["work"] = work
        assert work.parent == tmp_path and work.name.startswith(".undeclared_effect.partial-")
        (work / "datasets").mkdir()
        (work / "datasets" / "calibration.csv").write_text("new data\n")
        (work / "summary.json").write_text("{}")
        raise error

    _stub_study(monkeypatch, fails)
    with pytest.raises(type(error)):
        run_scenario("undeclared_effect", tmp_path, quiet=True, record=True)
    assert _snapshot(out_dir) == before  # byte-identical
    assert not seen["work"].exists() and _leftovers(tmp_path) == []


def test_ctrl_c_on_the_command_line(tmp_path, monkeypatch, capsys):
    out_dir, before = _earlier_run(tmp_path, monkeypatch)

    def interrupted(work):
        (work / "summary.json").write_text("{}")
        raise KeyboardInterrupt

    _stub_study(monkeypatch, interrupted)
    monkeypatch.chdir(tmp_path.parent)
    assert cli(["run", "undeclared_effect", "--results", str(tmp_path), "--quiet"]) == 130
    err = capsys.readouterr().err
    assert f"interrupted: {tmp_path.name}/undeclared_effect left as it was" in err
    assert "Traceback" not in err
    assert _snapshot(out_dir) == before and _leftovers(tmp_path) == []


def test_successful_run_replaces_the_folder_whole(tmp_path, monkeypatch):
    out_dir, before = _earlier_run(tmp_path, monkeypatch)
    assert "stale.txt" in before

    def ok(work):
        (work / "new.txt").write_text("from the new run\n")
        return {"scenario": "undeclared_effect", "run": 2}

    _stub_study(monkeypatch, ok)
    summary, again = run_scenario("undeclared_effect", tmp_path, quiet=True, record=True)
    assert again == out_dir and summary["recording"] == "undeclared_effect.rrd"
    after = _snapshot(out_dir)
    assert "stale.txt" not in after and "datasets/calibration.csv" not in after
    assert {"new.txt", "summary.json", "report.md", "undeclared_effect.rrd"} <= set(after)
    assert b'"run": 2' in after["summary.json"]
    assert _leftovers(tmp_path) == []
    assert (out_dir.stat().st_mode & 0o777) == (0o755 & ~_umask())


def test_cli_names_a_machine_error_without_traceback(tmp_path, monkeypatch, capsys):
    out_dir, before = _earlier_run(tmp_path, monkeypatch)

    def unreachable(work):
        raise WorkspaceError("pose 3 lies outside the workspace")

    _stub_study(monkeypatch, unreachable)
    assert cli(["run", "undeclared_effect", "--results", str(tmp_path), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: WorkspaceError: pose 3") and "Traceback" not in err
    assert _snapshot(out_dir) == before and _leftovers(tmp_path) == []


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_no_figures_reaches_the_studies_that_take_it(tmp_path, monkeypatch, capsys):
    """``figures=False`` (``--no-figures``) is passed to a study whose run takes ``figures``,
    and a study without that argument runs as before."""
    seen = []

    def with_switch(scenario, out_dir, progress, recorder, figures=True):
        seen.append(figures)
        return {"scenario": scenario.name}

    def without_switch(scenario, out_dir, progress, recorder):
        seen.append("plain")
        return {"scenario": scenario.name}

    report = lambda s: f"# {s['scenario']}\n"  # noqa: E731
    monkeypatch.setattr(runner, "_study", lambda name: (with_switch, report))
    run_scenario("undeclared_effect", tmp_path, quiet=True, record=False, figures=False)
    run_scenario("undeclared_effect", tmp_path, quiet=True, record=False)
    monkeypatch.chdir(tmp_path.parent)
    assert (
        cli(["run", "undeclared_effect", "--results", str(tmp_path), "--quiet", "--no-figures"])
        == 0
    )
    monkeypatch.setattr(runner, "_study", lambda name: (without_switch, report))
    run_scenario("undeclared_effect", tmp_path, quiet=True, record=False, figures=False)
    assert seen == [False, True, False, "plain"]
