"""A rerun recording of a scenario: the machine, the targets, the errors, the estimates.

Headless by default: the recording is encoded in memory (``rec.binary_stream`` before any
logging) and written to its ``.rrd`` file on ``close`` by Python, atomically, so that a full
disk raises an OSError instead of stalling rerun's own file writer (it deadlocked after "No
space left on device"); the flush waits at most FLUSH_TIMEOUT_S. ``spawn_viewer`` also opens
the viewer (then rerun saves the file itself, as before). A Recorder made with no path and
no viewer does nothing, cheaply (rerun is not even imported). See docs/recordings.md for
what each scenario's recording looks like.

What a study logs, and where:

* ``log_mechanism``: MJCF has no rerun loader, so each body is logged flat under
  ``world/bodies/<body>`` and its geoms as static shapes in body coordinates below it;
  ``log_pose`` places the bodies (a world Transform3D each, from ``xpos``/``xquat``) at one
  index of a pose timeline, ``log_targets`` the nominal and measured targets of that pose and
  the error magnified ``scale`` times (labelled in mm) under ``world/targets/<group>``.
* ``log_error_map``: static nodes coloured by error (viridis, grey for NaN) with a colour
  scale in mm beside them, under ``error_maps/<stage>/<layer>``.
* ``log_metric`` / ``log_points``: one point of ``metrics/<family>/<curve>`` on a timeline,
  drawn as a line or as markers (a curve of one point is always drawn as a marker).
* ``log_parameters``, ``log_text``, ``log_report``, ``log_verdict``: markdown text views (the
  estimates by name with standard errors, the report's key numbers, the named effect);
  ``log_bars`` a static bar chart; ``log_image`` a report's figure (a PNG) as an image;
  ``log_loop`` the loop-closing residuals before and after.

Each call notes what it logged in ``self.logged`` (``recording_blueprints.Logged``). On
``close`` the series styles are written, the first pose is copied onto the active timeline
when that is not a pose timeline (so the machine is not empty there), and, if asked for with
``send_blueprint``, the blueprint is built from ``self.logged`` (``build_blueprint``): only
views that have data on the timeline the viewer opens on. Every timed log call sets its own
timeline only (the stream's time is reset first), so a metric logged after a pose does not
inherit the pose's time point. ``RERUN_STRICT`` is read when a Recorder is made (rerun itself
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

from common.atomic_files import write_bytes_atomic
from scenarios.recording_blueprints import Bounds, ErrorMap, Logged, Series, build_blueprint
from twin.mechanism import Mechanism

FLUSH_TIMEOUT_S = 120.0  # encoding a recording of a few MB takes well under a second
ERROR_MAP_RADIUS = 0.004  # metres
TARGET_RADIUS = 0.003  # metres
NOMINAL_COLOUR, MEASURED_COLOUR, ERROR_COLOUR = [110, 130, 255], [255, 130, 60], [230, 40, 40]
PALETTE = [(220, 60, 50), (40, 110, 220), (40, 160, 80), (150, 80, 200), (230, 150, 30)]


@functools.cache
def _viridis() -> Any:
    """The viridis colour map, looked up once (each lookup copies it and builds its table)."""
    from matplotlib import colormaps

    return colormaps["viridis"]


def error_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """RGB (N, 3) uint8 from viridis over [0, vmax]; NaN values come out grey."""
    v = np.asarray(values, dtype=float)
    rgb = _viridis()(np.clip(np.nan_to_num(v) / max(vmax, 1e-300), 0.0, 1.0))[:, :3]
    rgb[~np.isfinite(v)] = 0.5
    return np.round(rgb * 255).astype(np.uint8)


def _error_labels(error_mm: np.ndarray, scale: float) -> list[str]:
    return [f"{e:.3f} mm (arrow x{scale:g})" for e in error_mm]


def entity_part(name: str) -> str:
    """A display name as one plain entity-path part: ``test layer, ols`` -> ``test_layer_ols``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "_"


def _name(m: mujoco.MjModel, kind: mujoco.mjtObj, i: int, fallback: str) -> str:
    return mujoco.mj_id2name(m, kind, i) or f"{fallback}{i}"


def _xyzw(wxyz: np.ndarray) -> list[float]:
    w, x, y, z = (float(c) for c in wxyz)
    return [x, y, z, w]


def geom_shape(rr: Any, m: mujoco.MjModel, g: int) -> Any | None:
    """Geom ``g`` as a rerun archetype in the geom's own frame (None: planes, height fields)."""
    size, kind, t = m.geom_size[g], int(m.geom_type[g]), mujoco.mjtGeom
    color = [np.round(np.asarray(m.geom_rgba[g]) * 255).astype(np.uint8)]
    if kind == t.mjGEOM_CAPSULE:  # rerun's capsule runs from z = 0 to z = length
        half = float(size[1])
        return rr.Capsules3D(
            lengths=[2 * half], radii=[size[0]], translations=[[0, 0, -half]], colors=color
        )
    if kind in (t.mjGEOM_SPHERE, t.mjGEOM_ELLIPSOID):
        half_sizes = [[size[0]] * 3] if kind == t.mjGEOM_SPHERE else [size]
        return rr.Ellipsoids3D(half_sizes=half_sizes, colors=color, fill_mode="solid")
    if kind == t.mjGEOM_CYLINDER:  # both centred on the origin, along z
        return rr.Cylinders3D(lengths=[2 * float(size[1])], radii=[size[0]], colors=color)
    if kind == t.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[size], colors=color, fill_mode="solid")
    if kind == t.mjGEOM_MESH and m.geom_dataid[g] >= 0:
        k = int(m.geom_dataid[g])
        v0, f0 = int(m.mesh_vertadr[k]), int(m.mesh_faceadr[k])
        return rr.Mesh3D(
            vertex_positions=m.mesh_vert[v0 : v0 + int(m.mesh_vertnum[k])],
            triangle_indices=m.mesh_face[f0 : f0 + int(m.mesh_facenum[k])],
            albedo_factor=color[0],
        )
    return None


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
        self._home: Mechanism | None = None
        self._reference: dict[str, list[Any]] = {}  # entity -> its first pose's archetypes
        if not self.enabled:
            return
        import rerun as rr
        from rerun.error_utils import default_strict_mode

        self.rr = rr
        self._strict = default_strict_mode()  # RERUN_STRICT as it is now, not at import
        self._rec = rr.RecordingStream(app_id)
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
        if self._home is not None and not log.pose_timelines:  # no pose: show the home pose
            self._log_bodies(self._home, self._home.home_qpos, static=True)
        active = log.active_timeline()
        if active is not None and active not in log.pose_timelines and self._reference:
            self._time(
                active, min(next(s.indices for s in log.series.values() if s.timeline == active))
            )
            for path, archetypes in self._reference.items():  # the first pose on this timeline too
                self._rec.log(path, *archetypes)
        if self._want_blueprint:
            self._rec.send_blueprint(build_blueprint(log))

    def _body_path(self, m: mujoco.MjModel, b: int) -> str:
        name = _name(m, mujoco.mjtObj.mjOBJ_BODY, b, "body")
        return f"world/bodies/{self.rr.escape_entity_path_part(name)}"

    @_active
    def log_mechanism(self, mech: Mechanism) -> None:
        """Every geom as a static shape under its body, placed by geom_pos/geom_quat."""
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
            path = f"{self._body_path(m, int(m.geom_bodyid[g]))}/{geom}"
            self._rec.log(path, pose, shape, static=True)
        self.logged.mechanism = True
        self._home = mech
        d = mujoco.MjData(m)
        d.qpos[:] = mech.home_qpos
        mujoco.mj_kinematics(m, d)
        shown = np.array([geom_shape(rr, m, g) is not None for g in range(m.ngeom)], dtype=bool)
        r = np.minimum(m.geom_rbound, 1.0)[shown, None]  # a sphere around each shown geom
        self.logged.machine_bounds.add(np.vstack([d.geom_xpos[shown] - r, d.geom_xpos[shown] + r]))

    def _log_bodies(self, mech: Mechanism, qpos: np.ndarray, static: bool = False) -> None:
        rr, m, d = self.rr, mech.model, mech.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        self.logged.machine_bounds.add(d.xpos[1:])
        for b in range(1, m.nbody):
            path = self._body_path(m, b)
            t = rr.Transform3D(
                translation=d.xpos[b], quaternion=rr.Quaternion(xyzw=_xyzw(d.xquat[b]))
            )
            self._rec.log(path, t, static=static)
            if not static:
                self._reference.setdefault(path, [t])

    @_active
    def log_pose(self, timeline: str, index: int, mech: Mechanism, qpos: np.ndarray) -> None:
        """One configuration: a world Transform3D per body (flat under world/bodies)."""
        self._time(timeline, index)
        self._log_bodies(mech, qpos)
        self.logged.pose_timelines.setdefault(timeline, set()).add(int(index))

    @_active
    def log_targets(
        self,
        timeline: str,
        index: int,
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float = 100.0,
        group: str = "targets",
    ) -> None:
        """Nominal and measured targets (T, 3) in metres, and the error magnified ``scale``x,
        under ``world/targets/<group>`` (one 3D view per group)."""
        nominal = np.atleast_2d(np.asarray(nominal, dtype=float))
        measured = np.atleast_2d(np.asarray(measured, dtype=float))
        self._time(timeline, index)
        root = f"world/targets/{entity_part(group)}"
        for part, archetype in self._target_archetypes(nominal, measured, scale).items():
            self._rec.log(f"{root}/{part}", archetype)
            self._reference.setdefault(f"{root}/{part}", [archetype])
        self._note_targets(timeline, [index], nominal, group)

    def _target_archetypes(
        self, nominal: np.ndarray, measured: np.ndarray, scale: float
    ) -> dict[str, Any]:
        """What log_targets logs of one pose, by entity below the group's."""
        rr = self.rr
        error_mm = np.linalg.norm(measured - nominal, axis=1) * 1e3
        return {
            "nominal": rr.Points3D(nominal, radii=TARGET_RADIUS, colors=[NOMINAL_COLOUR]),
            "measured": rr.Points3D(measured, radii=TARGET_RADIUS, colors=[MEASURED_COLOUR]),
            "error": rr.Arrows3D(
                origins=nominal,
                vectors=(measured - nominal) * scale,
                radii=TARGET_RADIUS / 2,
                labels=_error_labels(error_mm, scale),
                show_labels=True,
                colors=[ERROR_COLOUR],
            ),
        }

    def _note_targets(
        self, timeline: str, indices: Sequence[int], nominal: np.ndarray, group: str
    ) -> None:
        self.logged.machine_bounds.add(nominal.reshape(-1, 3))
        self.logged.pose_timelines.setdefault(timeline, set()).update(int(k) for k in indices)
        self.logged.target_groups.setdefault(entity_part(group), group)
        self.logged.group_timelines.setdefault(entity_part(group), timeline)

    @_active
    def _log_targets_columns(
        self,
        timeline: str,
        indices: list[int],
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float,
        group: str,
    ) -> None:
        """log_targets of every pose (P, T, 3) in one column per entity: each row the
        same components as log_targets logs at that pose."""
        rr = self.rr
        n_poses, n_targets = nominal.shape[:2]
        lengths = [n_targets] * n_poses
        flat_nominal, flat_measured = nominal.reshape(-1, 3), measured.reshape(-1, 3)
        error_mm = np.linalg.norm(flat_measured - flat_nominal, axis=1) * 1e3
        times = [rr.TimeColumn(timeline, sequence=indices)]
        root = f"world/targets/{entity_part(group)}"
        columns = {
            "nominal": [
                *rr.Points3D.columns(positions=flat_nominal).partition(lengths),
                *rr.Points3D.columns(
                    radii=[TARGET_RADIUS] * n_poses, colors=[NOMINAL_COLOUR] * n_poses
                ),
            ],
            "measured": [
                *rr.Points3D.columns(positions=flat_measured).partition(lengths),
                *rr.Points3D.columns(
                    radii=[TARGET_RADIUS] * n_poses, colors=[MEASURED_COLOUR] * n_poses
                ),
            ],
            "error": [
                *rr.Arrows3D.columns(
                    origins=flat_nominal,
                    vectors=(flat_measured - flat_nominal) * scale,
                    labels=_error_labels(error_mm, scale),
                ).partition(lengths),
                *rr.Arrows3D.columns(
                    radii=[TARGET_RADIUS / 2] * n_poses,
                    show_labels=[True] * n_poses,
                    colors=[ERROR_COLOUR] * n_poses,
                ),
            ],
        }
        for part, cols in columns.items():
            self._rec.send_columns(f"{root}/{part}", indexes=times, columns=cols)
        if any(f"{root}/{part}" not in self._reference for part in columns):
            first = self._target_archetypes(nominal[0], measured[0], scale)
            for part, archetype in first.items():
                self._reference.setdefault(f"{root}/{part}", [archetype])
        self._note_targets(timeline, indices, nominal, group)

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
        scale: float = 100.0,
    ) -> None:
        """Poses (P, nq) at ``indices`` of ``timeline``, each with its targets (P, T, 3).

        The bodies' transforms and the targets of all poses go out as one column per entity
        (what :meth:`log_pose` and :meth:`log_targets` log pose by pose, in one call per
        entity instead of one per entity and pose)."""
        indices = [int(k) for k in indices]
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        nominal, measured = np.asarray(nominal, dtype=float), np.asarray(measured, dtype=float)
        shape = (len(indices), nominal.shape[1] if nominal.ndim == 3 else 0, 3)
        if (
            self._rec is not None
            and len(indices) == len(qpos) > 0
            and nominal.shape == measured.shape == shape
            and shape[1] > 0
        ):
            self._log_bodies_columns(timeline, indices, mech, qpos)
            self._log_targets_columns(timeline, indices, nominal, measured, scale, group)
            return
        for k, q, a, b in zip(indices, qpos, nominal, measured, strict=True):
            self.log_pose(timeline, k, mech, q)
            self.log_targets(timeline, k, a, b, scale=scale, group=group)

    @_active
    def _log_bodies_columns(
        self, timeline: str, indices: list[int], mech: Mechanism, qpos: np.ndarray
    ) -> None:
        rr, m, d = self.rr, mech.model, mech.data
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
            path = self._body_path(m, b)
            self._rec.send_columns(
                path,
                indexes=times,
                columns=rr.Transform3D.columns(translation=xpos[:, b], quaternion=xyzw[:, b]),
            )
            if path not in self._reference:
                self._reference[path] = [
                    rr.Transform3D(
                        translation=xpos[0, b], quaternion=rr.Quaternion(xyzw=xyzw[0, b])
                    )
                ]
        self.logged.pose_timelines.setdefault(timeline, set()).update(indices)

    def log_pose_set(
        self,
        timeline: str,
        mech: Mechanism,
        commands: np.ndarray,
        poses: np.ndarray,
        group: str,
        scale: float = 100.0,
    ) -> None:
        """The machine ``mech`` driven by ``commands`` (N, A) at pose k of ``timeline``, its
        targets against those of the commanded ``poses`` (N, 6) and the error arrows."""
        if self._rec is not None:
            _log_pose_set(self, timeline, mech, commands, np.asarray(poses), group, scale)

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
    def log_bars(self, name: str, labels: Sequence[str], values: np.ndarray, unit: str) -> None:
        """A static bar chart ``bars/<name>``; the view's name lists the bars in order."""
        values = np.nan_to_num(np.asarray(values, dtype=float))
        self._rec.log(f"bars/{name}", self.rr.BarChart(values), static=True)
        self.logged.bars[f"bars/{name}"] = f"{name.replace('_', ' ')} ({unit}): " + ", ".join(
            labels
        )

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
        """A figure of the report (a PNG written beside the recording) as a static image,
        ``figures/<name>``, in a 2D view of its own."""
        path = f"figures/{entity_part(name)}"
        self._rec.log(path, self.rr.EncodedImage(path=Path(png)), static=True)
        self.logged.images[path] = name.replace("_", " ")

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


def merge_nodes(positions: np.ndarray, errors: np.ndarray) -> tuple[np.ndarray, ...]:
    """Unique positions (to 0.1 um), the largest error at each, and how many shared it."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    if len(positions) != len(errors):
        return positions, errors, np.ones(len(positions), dtype=int)
    keys = np.round(positions * 1e7).astype(np.int64)
    _, first, inverse, counts = np.unique(
        keys, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    inverse = inverse.ravel()
    worst = np.full(len(first), -np.inf)
    np.maximum.at(worst, inverse, np.where(np.isfinite(errors), errors, -np.inf))
    worst[~np.isfinite(worst)] = np.nan
    order = np.argsort(first)  # keep the logged order of first appearance
    return positions[first[order]], worst[order], counts[order]


def node_spacing(nodes: np.ndarray) -> float:
    """The smallest distance between two nodes (metres); 1 cm for fewer than two."""
    if len(nodes) < 2:
        return 0.01
    d = np.linalg.norm(nodes[:, None, :] - nodes[None, :, :], axis=-1)
    d[np.diag_indices(len(nodes))] = np.inf
    return float(max(d.min(), 1e-4))


def colour_scale(
    bounds: Bounds, spacing: float, vmax: float, n: int = 10
) -> tuple[np.ndarray, list[float], np.ndarray, list[str]]:
    """A vertical column of ``n`` boxes beside the nodes (viridis, 0 at the bottom) and two
    labelled ticks, 0 and vmax in mm (a middle label overlaps them in a small view)."""
    size = bounds.hi - bounds.lo
    height = max(float(size.max()), 4 * spacing)
    x = bounds.hi[0] + 1.5 * spacing
    y = (bounds.lo[1] + bounds.hi[1]) / 2
    z0 = (bounds.lo[2] + bounds.hi[2]) / 2 - height / 2
    step = height / n
    centres = np.array([[x, y, z0 + (k + 0.5) * step] for k in range(n)])
    half = [0.25 * spacing, 0.25 * spacing, step / 2]
    ticks = np.array([[x + 0.4 * spacing, y, z0 + f * height] for f in (0.0, 1.0)])
    return centres, half, ticks, [f"{f * vmax:.3g} mm" for f in (0.0, 1.0)]


def parameter_table(
    stage: str,
    names: Sequence[str],
    estimates: np.ndarray,
    std: np.ndarray | None,
    truth: np.ndarray | None,
    unit: str,
) -> str:
    est = np.asarray(estimates, dtype=float)
    head = ["parameter", f"estimate ({unit})", "std"]
    if truth is not None:
        head += ["truth", "estimate - truth", "|dev| / std"]
    rows = [f"### {stage}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k, name in enumerate(names):
        s = float("nan") if std is None else float(std[k])
        cells = [name, f"{est[k]:.4g}", "" if std is None else f"{s:.4g}"]
        if truth is not None:
            dev = est[k] - float(truth[k])
            z = abs(dev) / s if np.isfinite(s) and s > 0 else float("nan")
            cells += [f"{float(truth[k]):.4g}", f"{dev:+.3g}", f"{z:.2g}"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def _log_pose_set(
    rec: Recorder,
    timeline: str,
    mech: Mechanism,
    commands: np.ndarray,
    poses: np.ndarray,
    group: str,
    scale: float,
) -> None:
    from twin.kinematics.batch import forward_batch
    from twin.kinematics.single_pose import pose_to_frame

    sol = forward_batch(mech, commands)
    local = mech.target_local()
    nominal = np.einsum("nij,tj->nti", pose_to_frame(poses)[0], local) + poses[:, None, :3]
    rec.log_poses(
        timeline, range(len(commands)), mech, sol.qpos, nominal, sol.targets, group, scale
    )
