"""A rerun recording of a scenario: the machine, the targets, the errors, the estimates.

Headless by default: the recording is saved to a ``.rrd`` file (``rec.save`` before any
logging, ``rec.disconnect`` to write the footer); ``spawn_viewer`` also opens the viewer.
MJCF has no rerun loader, so each body is logged flat under ``world/bodies/<body>`` as a
Transform3D in world coordinates (from ``xpos``/``xquat``), with its geoms as static shapes
in body coordinates below it. A Recorder made with no path and no viewer does nothing,
cheaply (rerun is not even imported).

Every timed log call sets its own timeline only (the stream's time is reset first), so a
metric logged after a pose does not inherit the pose's time point. ``RERUN_STRICT`` is read
when a Recorder is made (rerun itself reads it once, at import): when set, a rerun usage
mistake raises instead of becoming a warning.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from twin.mechanism import Mechanism

ERROR_MAP_RADIUS = 0.004  # metres
TARGET_RADIUS = 0.003  # metres


def error_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """RGB (N, 3) uint8 from viridis over [0, vmax]; NaN values come out grey."""
    from matplotlib import colormaps

    v = np.asarray(values, dtype=float)
    rgb = colormaps["viridis"](np.clip(np.nan_to_num(v) / max(vmax, 1e-300), 0.0, 1.0))[:, :3]
    rgb[~np.isfinite(v)] = 0.5
    return np.round(rgb * 255).astype(np.uint8)


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
    """Logs a scenario to rerun; disabled (every method a no-op) without path and viewer."""

    def __init__(self, path: Path | None, app_id: str, spawn_viewer: bool = False) -> None:
        self.path = None if path is None else Path(path)
        self.enabled = self.path is not None or spawn_viewer
        self._rec: Any = None
        if not self.enabled:
            return
        import rerun as rr
        from rerun.error_utils import default_strict_mode

        self.rr = rr
        self._strict = default_strict_mode()  # RERUN_STRICT as it is now, not at import
        self._rec = rr.RecordingStream(app_id)
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._rec.save(self.path)
        if spawn_viewer:
            self._rec.spawn()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Flush and write the footer (a file without it cannot be read back)."""
        if self._rec is not None:
            self._rec.disconnect()
            self._rec = None

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
        """Machine and targets, error maps, parameter bars and tables, metric curves."""
        import rerun.blueprint as rrb

        self._rec.send_blueprint(
            rrb.Blueprint(
                rrb.Horizontal(
                    rrb.Vertical(
                        rrb.Spatial3DView(origin="world", name="machine and targets"),
                        rrb.TimeSeriesView(origin="metrics", name="metrics"),
                        row_shares=[2, 1],
                    ),
                    rrb.Vertical(
                        rrb.Spatial3DView(origin="error_maps", name="error maps"),
                        rrb.Tabs(
                            rrb.BarChartView(origin="parameters", name="parameters"),
                            rrb.TextDocumentView(origin="/", name="tables and notes"),
                        ),
                    ),
                )
            )
        )

    def _body_path(self, m: mujoco.MjModel, b: int) -> str:
        name = _name(m, mujoco.mjtObj.mjOBJ_BODY, b, "body")
        return f"world/bodies/{self.rr.escape_entity_path_part(name)}"

    @_active
    def log_mechanism(self, mech: Mechanism) -> None:
        """Every geom as a static shape under its body, placed by geom_pos/geom_quat."""
        rr, m = self.rr, mech.model
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

    @_active
    def log_pose(self, timeline: str, index: int, mech: Mechanism, qpos: np.ndarray) -> None:
        """One configuration: a world Transform3D per body (flat under world/bodies)."""
        rr, m, d = self.rr, mech.model, mech.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        self._time(timeline, index)
        for b in range(1, m.nbody):
            self._rec.log(
                self._body_path(m, b),
                rr.Transform3D(
                    translation=d.xpos[b], quaternion=rr.Quaternion(xyzw=_xyzw(d.xquat[b]))
                ),
            )

    @_active
    def log_targets(
        self,
        timeline: str,
        index: int,
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float = 100.0,
    ) -> None:
        """Nominal and measured targets (T, 3) in metres, and the error magnified ``scale``x."""
        rr = self.rr
        nominal = np.atleast_2d(np.asarray(nominal, dtype=float))
        measured = np.atleast_2d(np.asarray(measured, dtype=float))
        error_mm = np.linalg.norm(measured - nominal, axis=1) * 1e3
        self._time(timeline, index)
        self._rec.log(
            "world/targets/nominal",
            rr.Points3D(nominal, radii=TARGET_RADIUS, colors=[[110, 130, 255]]),
        )
        self._rec.log(
            "world/targets/measured",
            rr.Points3D(measured, radii=TARGET_RADIUS, colors=[[255, 130, 60]]),
        )
        self._rec.log(
            "world/targets/error",
            rr.Arrows3D(
                origins=nominal,
                vectors=(measured - nominal) * scale,
                labels=[f"{e:.3f} mm (arrow x{scale:g})" for e in error_mm],
                colors=[[230, 40, 40]],
            ),
        )

    @_active
    def log_error_map(
        self,
        stage: str,
        layer: str,
        positions: np.ndarray,
        errors_mm: np.ndarray,
        vmax_mm: float | None = None,
    ) -> None:
        """Nodes (N, 3, metres) coloured by error (viridis over [0, vmax_mm]), static."""
        errors = np.asarray(errors_mm, dtype=float).ravel()
        finite = errors[np.isfinite(errors)]
        vmax = float(vmax_mm) if vmax_mm is not None else float(finite.max(initial=0.0))
        self._rec.log(
            f"error_maps/{stage}/{layer}",
            self.rr.Points3D(
                np.asarray(positions, dtype=float),
                colors=error_colors(errors, vmax),
                radii=ERROR_MAP_RADIUS,
                labels=[f"{e:.3f} mm" for e in errors],
            ),
            static=True,
        )

    @_active
    def log_parameters(
        self,
        stage: str,
        names: Sequence[str],
        estimates: np.ndarray,
        std: np.ndarray | None = None,
        truth: np.ndarray | None = None,
    ) -> None:
        """Bar charts of estimates, standard errors and truth, plus a markdown table."""
        rr, root = self.rr, f"parameters/{stage}"
        est = np.asarray(estimates, dtype=float)
        columns = {"estimate": est, "std": std, "truth": truth}
        for key, values in columns.items():
            if values is not None:
                bars = rr.BarChart(np.nan_to_num(np.asarray(values, dtype=float)))
                self._rec.log(f"{root}/{key}", bars, static=True)
        rows = [f"### {stage}", "", "| parameter | estimate | std | truth |", "|---|---|---|---|"]
        for k, name in enumerate(names):
            s = "" if std is None else f"{std[k]:.4g}"
            t = "" if truth is None else f"{truth[k]:.4g}"
            rows.append(f"| {name} | {est[k]:.4g} | {s} | {t} |")
        self.log_text(f"{root}/table", "\n".join(rows))

    @_active
    def log_metric(self, name: str, timeline: str, index: int, value: float) -> None:
        """One point of the curve ``metrics/<name>`` against ``timeline``."""
        self._time(timeline, index)
        self._rec.log(f"metrics/{name}", self.rr.Scalars(float(value)))

    @_active
    def log_text(self, path: str, markdown: str) -> None:
        """A static markdown document (a table, a residual diagnosis ...)."""
        doc = self.rr.TextDocument(markdown, media_type=self.rr.MediaType.MARKDOWN)
        self._rec.log(path, doc, static=True)
