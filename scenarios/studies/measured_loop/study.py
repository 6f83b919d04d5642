"""The loop on a machine with real characteristics, through the commands a user types.

A cobot-like 6R arm (models/arm6r_3targets: three reflectors, no masses in its MJCF) whose
joints wind up under a payload (the twin's joint compliance), measured by a tracker standing
4.5 m away in its own frame, with the accuracy an honest export declares (0.02 mm): the
geometric fit leaves 10-20 times the tracker noise, as real machines do. The study writes
one dataset file (a calibration and a test set) and runs, in process:

    pkm-calib identify --set calibration --out R.json
    pkm-calib verify   --result R.json --set test --out V.json
    pkm-calib diagnose --test-set test --out D.json
    pkm-calib identify --with D.json --out RW.json      (if the effect is static)
    pkm-calib verify   --result RW.json --set test --out VW.json

Every number comes from the files those commands write; their logs lie beside the report.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.data import write_dataset
from scenarios.config import Scenario
from scenarios.machine_setup import build_effects
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.serial_arm.program import compensate_program
from scenarios.studies.serial_arm.study import _cli, _tracker, drawn_arm
from scenarios.twin_datasets import tracker_frame_dataset


def _verified(common: list[str], result: Path, out: Path, log: Path) -> tuple[int, dict]:
    code = _cli(
        ["verify", *common, "--result", str(result), "--set", "test", "--out", str(out)], log
    )
    return code, json.loads(out.read_text()) if out.is_file() else {}


def _to_the_machine(scenario, common, result, arm, effects, out_dir) -> dict[str, Any]:
    """The result with its effect taken to the machine: a program compensated through it and
    re-measured on the twin, and the exported model (with what it cannot hold beside it)
    scored as it is on the test set."""
    n = scenario.get("compensation.program_targets", int, None)
    out: dict[str, Any] = {}
    if n:
        model_path, errors_path, data = (Path(common[i]) for i in (1, 3, 5))
        out["program"] = compensate_program(
            "with_effect", model_path, errors_path, data, result, arm.truth,
            _tracker(scenario), effects, out_dir, _cli, n,
            scenario.get("compensation.joint_fraction", float),
            np.random.default_rng([scenario.get("seed", int), 31]),
        )  # fmt: skip
    exported = out_dir / "calibrated.xml"
    code_exp = _cli(
        ["export", *common[:4], "--result", str(result), "--out", str(exported)],
        out_dir / "export.log",
    )
    as_is_json = out_dir / "calibrated_verify.json"
    code_ver = _cli(
        ["verify", "--model", str(exported), *common[4:], "--set", "test", "--out",
         str(as_is_json)],
        out_dir / "calibrated_verify.log",
    )  # fmt: skip
    scored = json.loads(as_is_json.read_text()) if as_is_json.is_file() else {}
    out["export"] = {
        "exit_codes": {"export": code_exp, "verify_as_is": code_ver},
        "model_lacks": scored.get("model_lacks"),
        "verify_as_is_test": {k: scored.get("as_is", {}).get(k) for k in ("n", "rms_mm", "max_mm")},
    }
    return out


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    arm = drawn_arm(scenario, "model", "error_model", rng)
    model_path, errors_path, truth, commands = arm.model, arm.errors, arm.truth, arm.commands
    n_cal, n_test, sigma_mm = arm.n_cal, arm.n_test, arm.sigma_mm
    effects = build_effects(scenario)
    progress.step(f"measure {n_cal} + {n_test} poses with {[e.name for e in effects]}")
    data = write_dataset(
        tracker_frame_dataset(
            truth,
            _tracker(scenario),
            commands,
            n_cal,
            sigma_mm,
            rng,
            effects,
            notes="twin: a cobot-like arm, compliant joints under a payload, tracker in its "
            "own frame",
        ),
        out_dir / "readings.csv",
    )
    common = ["--model", str(model_path), "--errors", str(errors_path), "--data", str(data)]
    files = {k: out_dir / f"{k}.json" for k in ("result", "verify", "diagnosis")}
    progress.step("identify --set calibration; verify --set test")
    code_id = _cli(
        ["identify", *common, "--set", "calibration", "--out", str(files["result"])],
        out_dir / "identify.log",
    )
    code_ver, ver = _verified(common, files["result"], files["verify"], out_dir / "verify.log")
    progress.step("diagnose --test-set test")
    code_diag = _cli(
        ["diagnose", *common, "--test-set", "test", "--out", str(files["diagnosis"])],
        out_dir / "diagnose.log",
    )
    result = json.loads(files["result"].read_text())
    diag = json.loads(files["diagnosis"].read_text())
    summary: dict[str, Any] = {
        "study": "measured_loop",
        "n_poses": {"calibration": n_cal, "test": n_test},
        "effects": [e.name for e in effects],
        "exit_codes": {"identify": code_id, "verify": code_ver, "diagnose": code_diag},
        "sigma_mm": sigma_mm,
        "verdict": result["verdict"],
        "calibration": result["residual"],
        "regularisation": result["regularisation"],
        "test": {"before": ver["before"], "after": ver["after"]},
        "diagnosis": {
            "named": diag["diagnosed_effect"],
            "reason": diag["reason"],
            "chi2_p_value": diag["chi2_p_value"],
            "test": diag.get("test"),
            "static": diag["effect"]["static"],
            "not_static": diag["effect"]["not_static"],
            "not_static_reasons": diag["effect"]["not_static_reasons"],
        },
    }
    if diag["effect"]["added_parameters"]:
        progress.step(f"identify --with diagnosis.json ({diag['diagnosed_effect']}); verify")
        with_result = out_dir / "result_with_effect.json"
        code_with = _cli(
            [
                "identify",
                *common,
                "--set",
                "calibration",
                "--with",
                str(files["diagnosis"]),
                "--out",
                str(with_result),
            ],
            out_dir / "identify_with.log",
        )
        code_vw, ver_w = _verified(
            common, with_result, out_dir / "verify_with_effect.json", out_dir / "verify_with.log"
        )
        summary["exit_codes"].update(identify_with=code_with, verify_with=code_vw)
        refit = json.loads(with_result.read_text()) if with_result.is_file() else {}
        added = [a["name"] for a in diag["effect"]["added_parameters"]]
        summary["with_effect"] = {
            "test": {"before": ver_w.get("before"), "after": ver_w.get("after")},
            "verdict": refit.get("verdict"),
            "parameters": {
                n: refit["parameters"][n] for n in added if n in refit.get("parameters", {})
            },
        }
        if with_result.is_file():
            summary.update(_to_the_machine(scenario, common, with_result, arm, effects, out_dir))
    summary["runtime_s"] = time.perf_counter() - t0
    recorder.log_report("measured_loop", summary)
    # the diagnosis's own figure, as a user gets it beside diagnosis.json, and the test set
    # at each step of the loop in one figure (verify's two figures, each with a histogram
    # beside, stay beside their files)
    if (out_dir / "diagnosis.png").is_file():
        recorder.log_figure(
            "diagnosis",
            out_dir / "diagnosis.png",
            "diagnose: the residual against what explains it",
        )
    png = _test_errors_figure(summary, out_dir)
    if png is not None:
        summary["figures"] = {"test_errors": png.name}
        recorder.log_figure("test_errors", png, "verify: the test set at each step")
    return summary


def _test_errors_figure(summary: dict[str, Any], out_dir: Path) -> Path | None:
    """test_errors.png from verify's CSV files, the RMS of the legend from summary's."""
    from scenarios.studies.measured_loop.figures import per_pose_mm, test_errors_png

    plain, with_effect = out_dir / "verify.csv", out_dir / "verify_with_effect.csv"
    if not plain.is_file():
        return None
    stages = {
        "nominal": (per_pose_mm(plain, "before_mm"), summary["test"]["before"]["rms_mm"]),
        "geometry": (
            per_pose_mm(plain, "after_mm"),
            summary["test"]["after"]["rms_mm"],
        ),
    }
    after = (summary.get("with_effect") or {}).get("test", {}).get("after")
    if with_effect.is_file() and after:
        label = f"geometry + {summary['diagnosis']['named']}"
        stages[label] = (per_pose_mm(with_effect, "after_mm"), after["rms_mm"])
    accuracy = float(summary["sigma_mm"]) * float(np.sqrt(3.0))
    return test_errors_png(out_dir / "test_errors.png", stages, accuracy)
