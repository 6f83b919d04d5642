"""How soon the command line answers: ``identify`` on a 20-pose arm (twin data, one
reflector) against the bare import of the command line, each in a fresh process, best of N
(the smallest wall time: what is left when the machine is not busy elsewhere)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from bench.scaling import MACHINES, campaign, run_measured
from scenarios.config import REPO_ROOT

POSES = 20


def command_line_start(repeats: int = 3) -> dict:
    """Best-of-``repeats`` wall time of the bare import and of identify; their ratio."""
    xml, errors = MACHINES["arm"]
    with tempfile.TemporaryDirectory() as tmp:
        data = campaign("arm", POSES, Path(tmp))  # one reflector: a reading per pose
        identify = [
            "identify",
            *("--model", str(REPO_ROOT / xml), "--errors", str(REPO_ROOT / errors)),
            *("--data", str(data)),
        ]
        runs = {"import": [], "identify": []}
        for _ in range(repeats):
            runs["import"].append(run_measured([], "import:calib.cli.commands"))
            runs["identify"].append(run_measured(identify))
    for name, rs in runs.items():
        failed = [r for r in rs if r["exit_code"] != 0]
        if failed:
            raise RuntimeError(f"{name} failed: {failed[0].get('stderr', '')}")
    imp = min(r["wall_s"] for r in runs["import"])
    ident = min(r["wall_s"] for r in runs["identify"])
    return {
        "poses": POSES,
        "import_s": imp,
        "identify_s": ident,
        "identify_over_import": ident / imp,
        "repeats": repeats,
    }
