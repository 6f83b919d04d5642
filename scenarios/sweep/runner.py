"""Sweeps: a scenario's study once per seed (and per value of any swept setting) as tasks.

``python -m scenarios sweep NAME|FILE --seeds N [--over truth|noise|both] [--set k=v,...]``

* Runs are planned and validated first (:func:`scenarios.sweep.settings.plan_runs`), then
  given to the engine (:mod:`scenarios.sweep.engine`): Ray by default (a local instance sized
  to this machine's cores, or the cluster ``RAY_ADDRESS`` names), or ``local`` (in this
  process, the same numbers).
* Each run writes ``results/<name>/sweep/<run-id>/`` whole (summary.json, report.md, figures,
  run.json); a run already there with the same spec is skipped, so an interrupted sweep
  resumes; a failed run leaves error.json, is counted, and does not stop the others.
* At the end: ``results/<name>/sweep/summary.json`` (engine, n_runs, n_failed, the swept
  settings, statistics of every number), report.md with the distributions as figures, and
  ``<name>_sweep.rrd`` with the runs as a timeline.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from common.atomic_files import write_json_atomic, write_text_atomic
from common.write_set import staged
from scenarios.config import REPO_ROOT, ScenarioError, load_scenario
from scenarios.sweep.aggregate import aggregate
from scenarios.sweep.engine import engine_env, make_engine
from scenarios.sweep.one_run import finished, run_task
from scenarios.sweep.report import distribution_pngs, record_timeline, report_markdown
from scenarios.sweep.settings import RunSpec, parse_sets, plan_runs

SWEEP_DIR = "sweep"


class ProgressBar:
    """``[name] |#####-----| 3/8 runs, 1 failed, 12 s`` on stderr (redrawn on a terminal)."""

    def __init__(self, name: str, total: int, quiet: bool = False, stream: TextIO | None = None):
        self.name, self.total, self.quiet = name, total, quiet
        self.stream = stream or sys.stderr
        self.done = self.failed = 0
        self.t0 = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def update(self, done: int, failed: int, note: str = "") -> None:
        self.done, self.failed = done, failed
        if self.quiet:
            return
        width = 30
        filled = round(width * done / max(self.total, 1))
        bar = "#" * filled + "-" * (width - filled)
        text = (
            f"[{self.name} sweep] |{bar}| {done}/{self.total} runs"
            + (f", {failed} failed" if failed else "")
            + f", {time.perf_counter() - self.t0:.0f} s"
            + (f"  {note}" if note else "")
        )
        end = "" if self.tty and done < self.total else "\n"
        print(("\r" if self.tty else "") + text, end=end, file=self.stream, flush=True)

    def message(self, text: str) -> None:
        if not self.quiet:
            prefix = "\n" if self.tty and 0 < self.done < self.total else ""
            print(f"{prefix}[{self.name} sweep] {text}", file=self.stream, flush=True)


def _spec_record(scenario_path: str, spec: RunSpec, over: str) -> dict[str, Any]:
    return {"scenario": scenario_path, "over": over, **spec.plain()}


def sweep(
    name_or_path: str,
    seeds: int,
    over: str = "both",
    sets: list[str] | None = None,
    engine: str = "ray",
    results_root: Path | None = None,
    quiet: bool = False,
    num_cpus: int | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> tuple[dict[str, Any], Path]:
    """Run the sweep; returns the aggregate summary and ``<results_root>/<name>/sweep``."""
    scenario = load_scenario(name_or_path)
    settings = parse_sets(sets or [])
    specs = plan_runs(scenario, seeds, over, settings)
    ids = [s.run_id for s in specs]
    if len(set(ids)) != len(ids):
        raise ScenarioError("two runs of this sweep would share a folder; check --set values")
    out = Path(results_root or REPO_ROOT / "results") / scenario.name / SWEEP_DIR
    out.mkdir(parents=True, exist_ok=True)
    path = str(scenario.path)
    records = {s.run_id: _spec_record(path, s, over) for s in specs}
    swept = {
        "seeds": seeds,
        "over": over,
        "base_seed": scenario.data.get("seed"),
        "settings": {k: v for k, v in settings.items() if len(v) > 1},
        "fixed": {k: v[0] for k, v in settings.items() if len(v) == 1},
    }

    bar = ProgressBar(scenario.name, len(specs), quiet)
    results: dict[str, dict[str, Any]] = {}
    for s in specs:
        done = finished(out / s.run_id, records[s.run_id])
        if done is not None:
            results[s.run_id] = {
                "run_id": s.run_id,
                "status": "ok",
                "summary": done,
                "resumed": True,
            }
    todo = [s for s in specs if s.run_id not in results]
    if results:
        bar.message(f"resuming: {len(results)} of {len(specs)} runs already done")
    n_failed = 0
    bar.update(len(results), n_failed)
    where: dict[str, Any] | None = None
    if todo:
        eng = make_engine(engine, num_cpus)
        where = getattr(eng, "cluster", None)  # Ray: the address joined (None: a local one)
        args = [
            (path, s.overrides, s.run_id, str(out), s.truth_seed, records[s.run_id]) for s in todo
        ]
        try:
            with engine_env(eng.name):
                for outcome in eng.map(run_task, args):
                    spec = todo[outcome.index]
                    result = outcome.value
                    if outcome.error is not None:  # the engine lost the task
                        result = {"run_id": spec.run_id, "status": "failed", "error": outcome.error}
                        write_json_atomic(out / spec.run_id / "error.json", result)
                    elif (
                        result["status"] == "ok"
                        and finished(out / spec.run_id, records[spec.run_id]) is None
                    ):  # ran on a node that does not share this disk
                        write_json_atomic(out / spec.run_id / "summary.json", result["summary"])
                        write_json_atomic(out / spec.run_id / "run.json", records[spec.run_id])
                    results[spec.run_id] = result
                    n_failed += result["status"] != "ok"
                    if on_result is not None:
                        on_result(result)
                    bar.update(len(results), n_failed, spec.run_id)
        except KeyboardInterrupt:
            bar.message(
                f"interrupted: {len(results)} of {len(specs)} runs done in {out}; "
                "run the same command again to resume"
            )
            raise
        finally:
            eng.close()

    ordered = [{**results[s.run_id], "spec": records[s.run_id]} for s in specs]
    summary = aggregate(scenario.name, engine, swept, ordered)
    if where is not None:
        summary["ray"] = where  # {"address": RAY_ADDRESS or None, "cpus": the cluster's}
    with staged(out) as stage:  # the aggregate's files go in together, or none of them
        figures = distribution_pngs(stage, scenario.name, ordered)
        summary["figures"] = figures
        summary["recording"] = f"{scenario.name}_sweep.rrd"
        report = report_markdown(summary, figures)
        record_timeline(stage / summary["recording"], scenario.name, ordered, report)
        write_json_atomic(stage / "summary.json", summary)
        write_text_atomic(stage / "report.md", report)
    bar.message(f"wrote {out / 'summary.json'} and report.md")
    return summary, out
