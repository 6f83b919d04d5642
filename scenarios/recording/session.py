"""A recording's life: the rerun stream made (or nothing, cheaply, without path and viewer),
one timeline at most (rerun's wall-clock timelines off), its time set per call, and on close the
series styles, a machine never posed at its home pose, the blueprint and the atomic write."""

from __future__ import annotations

import contextlib
import functools
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.atomic_files import write_bytes_atomic
from scenarios.recording.blueprints import Logged, build_blueprint
from twin.mechanism import Mechanism

FLUSH_TIMEOUT_S = 120.0  # encoding a recording of a few MB takes well under a second
PALETTE = [(220, 60, 50), (40, 110, 220), (40, 160, 80), (150, 80, 200), (230, 150, 30)]


def entity_part(name: str) -> str:
    """A display name as one plain entity-path part: ``test layer, ols`` -> ``test_layer_ols``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "_"


def _active(method: Callable[..., None]) -> Callable[..., None]:
    """A no-op on a disabled or closed recorder; rerun usage mistakes raise under strict mode."""

    @functools.wraps(method)
    def wrapper(self: RecorderBase, *args: Any, **kwargs: Any) -> None:
        if self._rec is None:
            return
        with self._checked():
            method(self, *args, **kwargs)

    return wrapper


class RecorderBase:
    """A rerun stream, its blueprint and its file; the views are logged by the mixins."""

    def __init__(self, path: Path | None, app_id: str, spawn_viewer: bool = False) -> None:
        self.path = None if path is None else Path(path)
        self.enabled = self.path is not None or spawn_viewer
        self.logged = Logged()
        self._rec: Any = None
        self._stream: Any = None
        self._want_blueprint = False
        self._home: dict[str, Mechanism] = {}  # machine -> its nominal mechanism
        if not self.enabled:
            return
        import rerun as rr
        from rerun.error_utils import default_strict_mode

        self.rr = rr
        self._strict = default_strict_mode()  # RERUN_STRICT as it is now, not at import
        self._rec = rr.RecordingStream(app_id)
        # the study's timeline only: a wall-clock timeline would be a face of the recording
        # where the views of data sent as columns (the poses) are empty
        self._rec.set_log_time_enabled(False)
        self._rec.set_log_tick_enabled(False)
        if self.path is not None and spawn_viewer:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._rec.save(self.path)
        elif self.path is not None:
            self._stream = self._rec.binary_stream()
        if spawn_viewer:
            self._rec.spawn()

    def __enter__(self) -> RecorderBase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Finish (series styles, the machine on the active timeline, the blueprint), flush
        and write the footer (a file without it cannot be read back)."""
        if self._rec is None:
            return
        try:
            with self._checked():
                self._finish()
            if self._stream is not None:
                data = self._stream.read(flush=True, flush_timeout_sec=FLUSH_TIMEOUT_S)
                write_bytes_atomic(self.path, data or b"")
        finally:
            self._rec.disconnect()
            self._rec = self._stream = None

    def _checked(self) -> contextlib.AbstractContextManager[Any]:
        if not self._strict:
            return contextlib.nullcontext()
        from rerun.error_utils import catch_and_log_exceptions

        return catch_and_log_exceptions("Recorder", strict=True)

    def _time(self, timeline: str, index: int) -> None:
        self.logged.use_timeline(timeline)
        self._rec.reset_time()
        self._rec.set_time(timeline, sequence=int(index))

    @_active
    def send_blueprint(self) -> None:
        """Ask for a blueprint: it is built from what was logged and sent on ``close``."""
        self._want_blueprint = True

    def _finish(self) -> None:
        rr, log = self.rr, self.logged
        seen: dict[str, int] = {}
        for path, s in log.series.items():  # one point draws nothing as a line
            name = path.split("/")[-1]
            family = path.rsplit("/", 1)[0]
            color = [PALETTE[seen.setdefault(family, 0) % len(PALETTE)]]
            seen[family] += 1
            style = (
                rr.SeriesPoints(names=[name], colors=color, markers=["circle"], marker_sizes=[4.0])
                if s.as_points
                else rr.SeriesLines(names=[name], colors=color, widths=[2.0])
            )
            self._rec.log(path, style, static=True)
        for machine, mech in self._home.items():
            if not log.poses:  # never posed: the home pose, on any timeline
                self._log_bodies(mech, mech.home_qpos, machine, static=True)
        if self._want_blueprint:
            self._rec.send_blueprint(build_blueprint(log))
