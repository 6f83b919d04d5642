"""The loop closed through files, as a user runs it: diagnose --out, identify --with, verify.

A study that closes its loop in process (the diagnosis's effect fitted and scored with the
library's functions) also hands its readings over as Dataset files and runs the command
line on them in process (``calib.cli.main``), each command's output into a log beside the
files: ``diagnose --out D.json`` names the effect and writes its parameters, ``identify
--with D.json`` fits them with the geometry, ``verify`` scores that result on the test rows.
:func:`loop_through_files` returns what the files say (exit codes, the named effect, the
test RMS of the geometric fit, what the diagnosis reported (identify --with's fit of its file)
and its linearised ranking fit reached, and of the result with the effect) and
:func:`files_loop_sentence` says it from those numbers.
"""

from __future__ import annotations

import contextlib
import io
import json
import time
from pathlib import Path
from typing import Any

from calib.cli import main as calib_main
from scenarios.results_folder import final_paths


def _run(args: list[str], log: io.StringIO, said: dict[str, str]) -> int:
    """Run one command; when it fails, its last line that says why goes into ``said``."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = calib_main(args)
    log.write(f"$ pkm-calib {' '.join(args)}\n{out.getvalue()}exit {code}\n\n")
    if code != 0:
        lines = [x.strip() for x in out.getvalue().splitlines() if x.strip()]
        why = [x for x in lines if x.startswith(("FAILED", "error"))] or lines[-1:]
        said[args[0]] = why[-1] if why else ""
    return code


def _rms(path: Path, *keys: str) -> float | None:
    """The number at ``keys`` of a JSON file the command line wrote (None without it)."""
    if not path.is_file():
        return None
    value: Any = json.loads(path.read_text())
    for k in keys:
        value = value.get(k) if isinstance(value, dict) else None
    return float(value) if isinstance(value, (int, float)) else None


def loop_through_files(
    model: Path,
    errors: Path,
    data: Path,
    out_dir: Path,
    sigma_mm: float,
    test_data: Path | None = None,
) -> dict[str, Any]:
    """diagnose, identify --with and verify on ``data`` (its ``calibration`` rows; the test
    rows: ``test_data``'s, else ``data``'s set ``test``), the files into ``out_dir``;
    ``sigma_mm`` the tracker's accuracy per coordinate, given on the command line."""
    t0 = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    d, r, v = out_dir / "diagnosis.json", out_dir / "result_with_effect.json", out_dir / "verify"
    files = ["--model", str(model), "--errors", str(errors)]
    cal = [*files, "--data", str(data), "--set", "calibration", "--sigma-mm", f"{sigma_mm:g}"]
    held = ["--test", str(test_data)] if test_data is not None else ["--test-set", "test"]
    log = io.StringIO()
    codes: dict[str, int | None] = {"diagnose": None, "identify": None, "verify": None}
    why: dict[str, str] = {}
    codes["diagnose"] = _run(["diagnose", *cal, *held, "--out", str(d)], log, why)
    if codes["diagnose"] == 0:
        codes["identify"] = _run(["identify", *cal, "--with", str(d), "--out", str(r)], log, why)
    if codes["identify"] is not None and r.is_file():
        scored = str(test_data if test_data is not None else data)
        verify = [*files, "--data", scored, "--result", str(r), "--set", "test"]
        codes["verify"] = _run(["verify", *verify, "--out", str(v.with_suffix(".json"))], log, why)
    # the paths as they are after the run's folder is swapped in
    (out_dir / "commands.log").write_text(final_paths(log.getvalue()))
    diag = json.loads(d.read_text()) if d.is_file() else {}
    geometric = _rms(d, "test", "before", "rms_mm")
    reached = _rms(d, "test", "after", "rms_mm")
    linearised = _rms(d, "test", "after_linearised", "rms_mm")
    with_effect = _rms(v.with_suffix(".json"), "after", "rms_mm")
    effect = diag.get("effect") or {}
    return {
        "exit_codes": codes,
        "failed_because": why,  # per failing command, its own line saying why
        "named_effect": diag.get("diagnosed_effect"),
        "added_parameters": [p.get("name") for p in effect.get("added_parameters") or []],
        "sigma_mm_given": sigma_mm,
        # 3D position error per reading on the test rows (mm): the geometric fit's, what the
        # diagnosis reported (identify --with's fit of its file) and what its linearised fit
        # that ranked the candidates reached (diagnosis.json), the result of identify --with
        # (verify.json)
        "test_rms_mm": {
            "geometric_fit": geometric,
            "diagnosis": reached,
            "diagnosis_linearised": linearised,
            "with_effect": with_effect,
        },
        "with_effect_over_diagnosis": None
        if with_effect is None or not reached
        else with_effect / reached,
        "with_effect_over_geometric_fit": None
        if with_effect is None or not geometric
        else with_effect / geometric,
        "files": out_dir.name,
        "runtime_s": time.perf_counter() - t0,
    }


def files_loop_sentence(f: dict[str, Any] | None, in_process_mm: float | None = None) -> str:
    """What the loop through files did, from its numbers; ``in_process_mm``: the test RMS
    the study's own loop reached (3D per reading), when it has one to compare."""
    if not f:
        return ""
    codes = f["exit_codes"]
    said = ", ".join(f"{c} exit {'-' if x is None else x}" for c, x in codes.items())
    if codes["diagnose"] == 0 and f.get("named_effect") == "none":
        geometric = f["test_rms_mm"]["geometric_fit"]
        return (
            f"Through the files ({said}; {f['files']}/commands.log): diagnose named no effect "
            f"(none), so identify --with has nothing to add"
            + (f" and says so (exit {codes['identify']})" if codes["identify"] else "")
            + (
                ""
                if geometric is None
                else f"; the geometric fit's test RMS is {geometric:.4f} mm (3D per reading)"
            )
            + "."
        )
    if codes["diagnose"] != 0 or codes["verify"] is None:
        reasons = "; ".join(f"{c}: {w}" for c, w in (f.get("failed_because") or {}).items())
        return (
            f"Through the files ({said}) the loop did not close"
            + (f" ({reasons})" if reasons else "")
            + f": see {f['files']}/commands.log."
        )
    t = f["test_rms_mm"]
    text = (
        f"Through the files, as a user runs it ({said}; {f['files']}/commands.log): diagnose "
        f"named {f['named_effect']} and wrote {len(f['added_parameters'])} parameters, and "
        "verify of identify --with's result gives a test RMS of "
        f"{t['with_effect']:.4f} mm (3D per reading) against {t['diagnosis']:.4f} mm the "
        f"diagnosis reported ({f['with_effect_over_diagnosis']:.2f}x"
        + (
            ""
            if t.get("diagnosis_linearised") is None
            else f"; {t['diagnosis_linearised']:.4f} mm by its linearised ranking fit"
        )
        + f") and {t['geometric_fit']:.4f} mm the geometric fit's "
        f"({f['with_effect_over_geometric_fit']:.2f}x)"
    )
    if in_process_mm is not None:
        text += f"; the in-process loop's {in_process_mm:.4f} mm beside it"
    return text + "."
