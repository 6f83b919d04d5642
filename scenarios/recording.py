"""A rerun recording of a scenario: the machine, the targets, the errors, the estimates.

Headless by default: the recording is encoded in memory (``rec.binary_stream`` before any
logging) and written to its ``.rrd`` file on ``close`` by Python, atomically, so that a full
disk raises an OSError instead of stalling rerun's own file writer (it deadlocked after "No
space left on device"); the flush waits at most FLUSH_TIMEOUT_S. ``spawn_viewer`` also opens
the viewer (then rerun saves the file itself, as before). A Recorder made with no path and
no viewer does nothing, cheaply (rerun is not even imported). See docs/recordings.md for
what each scenario's recording looks like.

A recording has one timeline at most, the poses' (rerun's own wall-clock timelines are off):
the viewer plots and poses against the timeline selected, so a second one would be a face of
the recording where the other views are empty. A second timeline raises
``recording_blueprints.SecondTimeline``. What a study logs, and where:

* ``log_mechanism``: MJCF has no rerun loader, so each body is logged flat under
  ``world/bodies/<body>`` (``world/<machine>/bodies`` for one of several machines) and its
  geoms as static shapes in body coordinates below it; ``log_pose`` / ``log_poses`` place the
  bodies (a world Transform3D each, from ``xpos``/``xquat``) at indices of the pose timeline,
  with the nominal and measured targets, the error arrows (magnified to be seen, the factor in
  the view's title) and each error in mm as a label set off from the target, under
  ``world/targets/<group>`` (recording_targets).
* ``log_error_map``: static nodes coloured by error (viridis, grey for NaN) with a colour
  scale in mm beside them, under ``error_maps/<stage>/<layer>``.
* ``log_figure``: a static figure (a PNG, a report's figure), for any curve that is not
  against the poses: an iteration count, a rank index, a variable that explains an effect.
* ``log_metric`` / ``log_points``: one point of ``metrics/<family>/<curve>`` on the timeline,
  drawn as a line or as markers (a curve of one point is always drawn as a marker).
* ``log_parameters``, ``log_text``, ``log_report``, ``log_verdict``: markdown text views (the
  estimates by name with standard errors, the report's key numbers, the named effect);
  ``log_loop`` the loop-closing residuals before and after.

Each call notes what it logged in ``self.logged`` (``recording_blueprints.Logged``). On
``close`` the series styles are written, a machine never posed is placed at its home pose
(static), and, if asked for with ``send_blueprint``, the blueprint is built from
``self.logged`` (``build_blueprint``). Every timed log call sets its own time only (the
stream's time is reset first). ``RERUN_STRICT`` is read when a Recorder is made (rerun itself
reads it once, at import): when set, a rerun usage mistake raises instead of becoming a
warning.
"""

from __future__ import annotations

import contextlib
import functools
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from calib.atomic_files import write_bytes_atomic
from scenarios.recording_blueprints import (
    Bounds,
    ErrorMap,
    Logged,
    Series,
    TargetGroup,
    build_blueprint,
)
from scenarios.recording_parts import (
    _name,
    _xyzw,
    colour_scale,
    error_colors,
    geom_shape,
    merge_nodes,
    node_spacing,
    parameter_table,
)
from scenarios.recording_targets import (
    arrow_scale,
    error_labels,
    label_positions,
    radii,
    spread,
)
from twin.mechanism import Mechanism

FLUSH_TIMEOUT_S = 120.0  # encoding a recording of a few MB takes well under a second
ERROR_MAP_RADIUS = 0.004  # metres
NOMINAL_COLOUR, MEASURED_COLOUR, ERROR_COLOUR = [110, 130, 255], [255, 130, 60], [230, 40, 40]
PALETTE = [(220, 60, 50), (40, 110, 220), (40, 160, 80), (150, 80, 200), (230, 150, 30)]


def entity_part(name: str) -> str:
    """A display name as one plain entity-path part: ``test layer, ols`` -> ``test_layer_ols``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "_"


def _active(method: Callable[..., None]) -> Callable[..., None]:
    """A no-op on a disabled or closed recorder; rerun usage mistakes raise under strict mode."""

    @functools.wraps(method)
    def wrapper(self: Recorder, *args: Any, **kwargs: Any) -> None:
        if self._rec is None:
            return
        with self._checked():
            method(self, *args, **kwargs)

    return wrapper


class Recorder:
    """Logs a scenario to rerun; disabled (every method a no-op) without path and viewer.

    What is logged is noted in ``self.logged``; on ``close`` the blueprint (if asked for with
    ``send_blueprint``) is built from it, so every view it holds has data."""

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

    def __enter__(self) -> Recorder:
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

    def _body_path(self, m: mujoco.MjModel, b: int, machine: str = "") -> str:
        name = self.rr.escape_entity_path_part(_name(m, mujoco.mjtObj.mjOBJ_BODY, b, "body"))
        return f"world/{entity_part(machine)}/bodies/{name}" if machine else f"world/bodies/{name}"

    @_active
    def log_mechanism(self, mech: Mechanism, machine: str = "") -> None:
        """Every geom as a static shape under its body, placed by geom_pos/geom_quat; under
        ``world/<machine>/bodies`` when a recording shows several machines (``machine``
        names it in log_pose and log_targets too), else ``world/bodies``."""
        rr, m = self.rr, mech.model
        self._rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for g in range(m.ngeom):
            shape = geom_shape(rr, m, g)
            if shape is None:
                continue
            geom = rr.escape_entity_path_part(_name(m, mujoco.mjtObj.mjOBJ_GEOM, g, "geom"))
            pose = rr.Transform3D(
                translation=m.geom_pos[g], quaternion=rr.Quaternion(xyzw=_xyzw(m.geom_quat[g]))
            )
            path = f"{self._body_path(m, int(m.geom_bodyid[g]), machine)}/{geom}"
            self._rec.log(path, pose, shape, static=True)
        if machine not in self.logged.machines:
            self.logged.machines.append(machine)
        self._home[machine] = mech
        d = mujoco.MjData(m)
        d.qpos[:] = mech.home_qpos
        mujoco.mj_kinematics(m, d)
        shown = np.array([geom_shape(rr, m, g) is not None for g in range(m.ngeom)], dtype=bool)
        r = np.minimum(m.geom_rbound, 1.0)[shown, None]  # a sphere around each shown geom
        self.logged.machine_bounds.add(np.vstack([d.geom_xpos[shown] - r, d.geom_xpos[shown] + r]))

    def _log_bodies(
        self, mech: Mechanism, qpos: np.ndarray, machine: str = "", static: bool = False
    ) -> None:
        rr, m, d = self.rr, mech.model, mech.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        self.logged.machine_bounds.add(d.xpos[1:])
        for b in range(1, m.nbody):
            t = rr.Transform3D(
                translation=d.xpos[b], quaternion=rr.Quaternion(xyzw=_xyzw(d.xquat[b]))
            )
            self._rec.log(self._body_path(m, b, machine), t, static=static)

    @_active
    def log_pose(
        self, timeline: str, index: int, mech: Mechanism, qpos: np.ndarray, machine: str = ""
    ) -> None:
        """One configuration: a world Transform3D per body (flat under world/bodies)."""
        self._time(timeline, index)
        self._log_bodies(mech, qpos, machine)
        self.logged.poses.add(int(index))

    @_active
    def log_targets(
        self,
        timeline: str,
        index: int,
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float = 100.0,
        group: str = "targets",
        machine: str = "",
    ) -> None:
        """Nominal and measured targets (T, 3) in metres, and the error magnified ``scale``x,
        under ``world/targets/<group>`` (one 3D view per group, with ``machine``'s bodies)."""
        self._log_targets(timeline, [int(index)], nominal, measured, scale, group, machine)

    @_active
    def log_poses(
        self,
        timeline: str,
        indices: Sequence[int],
        mech: Mechanism,
        qpos: np.ndarray,
        nominal: np.ndarray,
        measured: np.ndarray,
        group: str,
        scale: float | None = None,
        machine: str = "",
    ) -> None:
        """Poses (P, nq) at ``indices`` of ``timeline``, each with its targets (P, T, 3); the
        error arrows magnified ``scale`` times (None: the 1-2-5 factor that draws the largest
        error as a fifth of the targets' spread, recording_targets.arrow_scale).

        The bodies' transforms and the targets of all poses go out as one column per entity
        (what :meth:`log_pose` and :meth:`log_targets` log pose by pose)."""
        indices = [int(k) for k in indices]
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        nominal, measured = np.asarray(nominal, dtype=float), np.asarray(measured, dtype=float)
        if nominal.ndim == 2:
            nominal, measured = nominal[:, None], measured[:, None]
        if not (len(indices) == len(qpos) == len(nominal) and nominal.shape == measured.shape):
            raise ValueError(
                f"{group}: {len(indices)} indices, {len(qpos)} configurations, targets "
                f"{nominal.shape} and {measured.shape}: one of each per pose"
            )
        scale = arrow_scale(nominal, measured) if scale is None else float(scale)
        self._log_bodies_columns(timeline, indices, mech, qpos, machine)
        self._log_targets(timeline, indices, nominal, measured, scale, group, machine)

    def _log_targets(
        self,
        timeline: str,
        indices: list[int],
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float,
        group: str,
        machine: str,
    ) -> None:
        """The targets of every pose (P, T, 3) in one column per entity."""
        rr = self.rr
        nominal = np.asarray(nominal, dtype=float).reshape(len(indices), -1, 3)
        measured = np.asarray(measured, dtype=float).reshape(nominal.shape)
        self.logged.use_timeline(timeline)
        n_poses, n_targets = nominal.shape[:2]
        lengths = [n_targets] * n_poses
        flat_nominal, flat_measured = nominal.reshape(-1, 3), measured.reshape(-1, 3)
        span = spread(nominal)
        point_radius, arrow_radius = radii(span)
        labels_at = label_positions(nominal, span).reshape(-1, 3)
        times = [rr.TimeColumn(timeline, sequence=indices)]
        part = entity_part(group)
        root = f"world/targets/{part}"

        def points(positions: np.ndarray, colour: list[int], radius: float) -> list[Any]:
            return [
                *rr.Points3D.columns(positions=positions).partition(lengths),
                *rr.Points3D.columns(radii=[radius] * n_poses, colors=[colour] * n_poses),
            ]

        columns = {
            "nominal": points(flat_nominal, NOMINAL_COLOUR, point_radius),
            "measured": points(flat_measured, MEASURED_COLOUR, point_radius),
            "error": [
                *rr.Arrows3D.columns(
                    origins=flat_nominal, vectors=(flat_measured - flat_nominal) * scale
                ).partition(lengths),
                *rr.Arrows3D.columns(
                    radii=[arrow_radius] * n_poses, colors=[ERROR_COLOUR] * n_poses
                ),
            ],
            "error_mm": [
                *rr.Points3D.columns(
                    positions=labels_at, labels=error_labels(flat_nominal, flat_measured)
                ).partition(lengths),
                *rr.Points3D.columns(
                    radii=[point_radius / 3] * n_poses,
                    colors=[ERROR_COLOUR] * n_poses,
                    show_labels=[True] * n_poses,
                ),
            ],
        }
        for name, cols in columns.items():
            self._rec.send_columns(f"{root}/{name}", indexes=times, columns=cols)
        self.logged.machine_bounds.add(flat_nominal)
        self.logged.poses.update(indices)
        entry = self.logged.target_groups.setdefault(
            part, TargetGroup(f"{group}: errors x{scale:g}", machine)
        )
        entry.bounds.add(flat_nominal)
        entry.bounds.add(labels_at)

    @_active
    def _log_bodies_columns(
        self,
        timeline: str,
        indices: list[int],
        mech: Mechanism,
        qpos: np.ndarray,
        machine: str = "",
    ) -> None:
        rr, m, d = self.rr, mech.model, mech.data
        self.logged.use_timeline(timeline)
        xpos = np.empty((len(qpos), m.nbody, 3))
        xquat = np.empty((len(qpos), m.nbody, 4))
        for i, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            self.logged.machine_bounds.add(d.xpos[1:])
            xpos[i], xquat[i] = d.xpos, d.xquat
        xyzw = xquat[:, :, [1, 2, 3, 0]]
        times = [rr.TimeColumn(timeline, sequence=indices)]
        for b in range(1, m.nbody):
            self._rec.send_columns(
                self._body_path(m, b, machine),
                indexes=times,
                columns=rr.Transform3D.columns(translation=xpos[:, b], quaternion=xyzw[:, b]),
            )
        self.logged.poses.update(indices)

    def log_pose_set(
        self,
        timeline: str,
        mech: Mechanism,
        commands: np.ndarray,
        poses: np.ndarray,
        group: str,
        scale: float | None = None,
        machine: str = "",
    ) -> None:
        """The machine ``mech`` driven by ``commands`` (N, A) at pose k of ``timeline``, its
        targets against those of the commanded ``poses`` (N, 6) and the error arrows."""
        if self._rec is not None:
            _log_pose_set(self, timeline, mech, commands, np.asarray(poses), group, scale, machine)

    @_active
    def log_error_map(
        self,
        stage: str,
        layer: str,
        positions: np.ndarray,
        errors_mm: np.ndarray,
        vmax_mm: float | None = None,
    ) -> None:
        """Nodes (N, 3, metres) coloured by error (viridis over [0, vmax_mm]), static, with a
        colour scale in mm beside them. Nodes at one position (several orientations) show the
        largest error there; spheres are sized to the node spacing."""
        rr = self.rr
        positions = np.asarray(positions, dtype=float)
        errors = np.asarray(errors_mm, dtype=float).ravel()
        finite = errors[np.isfinite(errors)]
        vmax = float(vmax_mm) if vmax_mm is not None else float(finite.max(initial=0.0))
        if positions.ndim != 2 or positions.shape[1] != 3:  # rerun names the mistake
            self._rec.log("error_maps/invalid", rr.Points3D(positions), static=True)
            return
        nodes, worst, repeats = merge_nodes(positions, errors)
        root = f"error_maps/{entity_part(stage)}/{entity_part(layer)}"
        spacing = node_spacing(nodes)
        many = "max over " if np.any(repeats > 1) else ""
        labels = [f"{many}{e:.3f} mm" for e in worst]
        self._rec.log("error_maps", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._rec.log(
            f"{root}/nodes",
            rr.Points3D(
                nodes,
                colors=error_colors(worst, vmax),
                radii=min(ERROR_MAP_RADIUS, 0.3 * spacing),
                labels=labels,
                show_labels=False,
            ),
            static=True,
        )
        bounds = Bounds()
        bounds.add(nodes)
        if not bounds.empty:
            centres, half, ticks, tick_labels = colour_scale(bounds, spacing, vmax)
            self._rec.log(
                f"{root}/scale_mm",
                rr.Boxes3D(
                    centers=centres,
                    half_sizes=half,
                    colors=error_colors(np.linspace(0, vmax, len(centres)), vmax),
                    fill_mode="solid",
                ),
                static=True,
            )
            self._rec.log(
                f"{root}/scale_mm/ticks",
                rr.Points3D(ticks, radii=1e-4, labels=tick_labels, show_labels=True),
                static=True,
            )
            bounds.add(centres)
            bounds.add(ticks + np.array([0.3 * float(np.max(bounds.hi - bounds.lo)), 0.0, 0.0]))
        self.logged.error_maps[root] = ErrorMap(stage, layer, vmax, bounds)

    @_active
    def log_parameters(
        self,
        stage: str,
        names: Sequence[str],
        estimates: np.ndarray,
        std: np.ndarray | None = None,
        truth: np.ndarray | None = None,
        unit: str = "mm or deg",
    ) -> None:
        """A markdown table of estimates by name, with standard errors and, when the truth is
        known, the deviation from it in standard errors (one table view per stage)."""
        self.log_text(
            f"parameters/{stage}",
            parameter_table(stage, names, estimates, std, truth, unit),
            name=f"parameters: {stage}",
        )

    @_active
    def log_metric(self, name: str, timeline: str, index: int, value: float) -> None:
        """One point of the curve ``metrics/<name>`` against ``timeline``."""
        self._scalar(name, timeline, index, value, points=False)

    @_active
    def log_points(self, name: str, timeline: str, index: int, value: float) -> None:
        """One point of ``metrics/<name>`` against ``timeline``, drawn as a marker (a scatter
        of a per-pose value against the variable the timeline is)."""
        self._scalar(name, timeline, index, value, points=True)

    def _scalar(self, name: str, timeline: str, index: int, value: float, points: bool) -> None:
        path = f"metrics/{name}"
        self._time(timeline, index)
        self._rec.log(path, self.rr.Scalars(float(value)))
        s = self.logged.series.setdefault(path, Series(timeline, points=points))
        if s.timeline != timeline:
            raise ValueError(f"{path}: logged against {s.timeline} and {timeline}")
        s.indices.add(int(index))

    @_active
    def log_figure(self, name: str, png: bytes | str | Path, title: str) -> None:
        """A static figure (PNG bytes, or a PNG file such as a report's figure) in a 2D view
        titled ``title``: shown on any timeline, with the axes, names and log scales that a
        plot of rerun's cannot draw. ``figures.png_bytes`` turns a matplotlib figure into it."""
        data = Path(png).read_bytes() if isinstance(png, str | Path) else bytes(png)
        path = f"figures/{entity_part(name)}"
        image = self.rr.EncodedImage(contents=data, media_type="image/png")
        self._rec.log(path, image, static=True)
        self.logged.figures[path] = title

    @_active
    def log_text(self, path: str, markdown: str, name: str | None = None) -> None:
        """A static markdown document (a table, a residual diagnosis ...), one text view.
        A figure a report links by a relative path is named instead (:func:`viewer_markdown`):
        the viewer cannot open files beside the recording."""
        doc = self.rr.TextDocument(viewer_markdown(markdown), media_type=self.rr.MediaType.MARKDOWN)
        self._rec.log(path, doc, static=True)
        self.logged.texts[path] = name or path.replace("_", " ")

    @_active
    def log_image(self, name: str, png: Path) -> None:
        """A figure of the report (a PNG written beside the recording): :meth:`log_figure`
        titled by its name."""
        self.log_figure(name, png, name.replace("_", " "))

    @_active
    def log_loop(
        self,
        mech: Mechanism,
        order: np.ndarray,
        prediction: Any,
        measured: np.ndarray,
        after: np.ndarray,
    ) -> None:
        """Loop closing: each pose's residual before (``prediction``, a geometric fit's) and
        after the named effect (``after`` targets), as arrows and against measurement order."""
        from scenarios.recording_loop import log_loop

        log_loop(self, mech, order, prediction, measured, after)

    @_active
    def log_causes(self, diag: Any, figure: Path | None, plots: list[Any], noise_mm: float) -> None:
        """The loop's cause: one figure per named effect against the variable that explains
        it (the diagnosis's own ``figure`` for the first), and the candidates held out."""
        from scenarios.recording_loop import log_causes

        log_causes(self, diag, figure, plots, noise_mm)

    @_active
    def log_verdict(
        self, diagnosis: Any, before_mm: float, after_mm: float, noise_mm: float
    ) -> None:
        """The named effect, why, and the residual before and after, as the verdict view."""
        from scenarios.recording_loop import verdict_markdown

        self.log_text(
            "verdict", verdict_markdown(diagnosis, before_mm, after_mm, noise_mm), "verdict"
        )

    @_active
    def log_report(self, study: str, summary: dict[str, Any]) -> None:
        """The study's report.md (its key numbers and tables) as the ``report`` text view."""
        import importlib

        from scenarios.runner import STUDIES

        report = importlib.import_module(STUDIES[study][1]).report
        self.log_text("report", report(summary), name="report: key numbers")


RELATIVE_IMAGE = re.compile(r"!\[([^\]]*)\]\((?![a-zA-Z][a-zA-Z0-9+.-]*:)([^)\s]+)\)")


def viewer_markdown(markdown: str) -> str:
    """``markdown`` with each image linked by a relative path (a report's figure beside it)
    replaced by its name and file, in italics: the viewer shows such a link as a broken
    image."""
    return RELATIVE_IMAGE.sub(r"*Figure: \1 (`\2`, beside the recording)*", markdown)


def _log_pose_set(
    rec: Recorder,
    timeline: str,
    mech: Mechanism,
    commands: np.ndarray,
    poses: np.ndarray,
    group: str,
    scale: float | None,
    machine: str,
) -> None:
    from twin.kinematics import pose_to_frame
    from twin.kinematics_batch import forward_batch

    sol = forward_batch(mech, commands)
    local = mech.target_local()
    nominal = np.einsum("nij,tj->nti", pose_to_frame(poses)[0], local) + poses[:, None, :3]
    rec.log_poses(
        timeline, range(len(commands)), mech, sol.qpos, nominal, sol.targets, group, scale, machine
    )
