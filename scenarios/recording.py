"""A rerun recording of a scenario: the machine, the targets, the errors, the estimates.

Headless by default: the recording is saved to ``results/<name>/<name>.rrd`` (``rec.save``
before logging, ``rec.disconnect`` to flush the footer); ``spawn_viewer`` also opens the
viewer (``make scenario NAME=... VIEW=1``). MJCF has no rerun loader, so each body is logged
as a Transform3D (from ``xpos``/``xquat``) with its geoms as shapes in body coordinates.
A Recorder made with no path and no viewer does nothing, cheaply.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib
import mujoco
import numpy as np

from twin.mechanism import Mechanism

matplotlib.use("Agg")


def _colors(values: np.ndarray, vmax: float) -> np.ndarray:
    from matplotlib import colormaps

    rgba = colormaps["viridis"](np.clip(values / max(vmax, 1e-300), 0.0, 1.0))
    return (rgba[:, :3] * 255).astype(np.uint8)


def _body_name(m: mujoco.MjModel, b: int) -> str:
    return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"


class Recorder:
    def __init__(self, path: Path | None, app_id: str, spawn_viewer: bool = False) -> None:
        self.enabled = path is not None or spawn_viewer
        self.path = path
        self._rec = None
        if not self.enabled:
            return
        import rerun as rr

        self.rr = rr
        self._rec = rr.RecordingStream(app_id)
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            self._rec.save(str(path))
        if spawn_viewer:
            self._rec.spawn()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._rec is not None:
            self._rec.disconnect()
            self._rec = None

    def send_blueprint(self) -> None:
        if self._rec is None:
            return
        import rerun.blueprint as rrb

        self._rec.send_blueprint(
            rrb.Blueprint(
                rrb.Horizontal(
                    rrb.Spatial3DView(origin="world", name="machine and targets"),
                    rrb.Vertical(
                        rrb.Spatial3DView(origin="error_maps", name="error maps"),
                        rrb.BarChartView(origin="parameters", name="parameters"),
                        rrb.TimeSeriesView(origin="metrics", name="metrics"),
                    ),
                )
            )
        )

    def log_mechanism(self, mech: Mechanism) -> None:
        """Every geom as a static shape in its body's frame (capsules, spheres, boxes)."""
        if self._rec is None:
            return
        rr, m = self.rr, mech.model
        for g in range(m.ngeom):
            b = int(m.geom_bodyid[g])
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
            path = f"world/bodies/{_body_name(m, b)}/{name}"
            pos, size = m.geom_pos[g], m.geom_size[g]
            w, x, y, z = m.geom_quat[g]
            color = (np.asarray(m.geom_rgba[g][:3]) * 255).astype(np.uint8)
            gtype = int(m.geom_type[g])
            self._rec.log(
                path,
                rr.Transform3D(translation=pos, quaternion=rr.Quaternion(xyzw=[x, y, z, w])),
                static=True,
            )
            if gtype == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
                half = float(size[1])
                shape = rr.Capsules3D(
                    lengths=[2 * half],
                    radii=[float(size[0])],
                    translations=[[0, 0, -half]],
                    colors=[color],
                )
            elif gtype == int(mujoco.mjtGeom.mjGEOM_SPHERE):
                shape = rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], colors=[color])
            elif gtype == int(mujoco.mjtGeom.mjGEOM_CYLINDER):
                shape = rr.Cylinders3D(
                    lengths=[2 * float(size[1])], radii=[float(size[0])], colors=[color]
                )
            elif gtype == int(mujoco.mjtGeom.mjGEOM_BOX):
                shape = rr.Boxes3D(half_sizes=[size], colors=[color])
            else:
                continue
            self._rec.log(path, shape, static=True)

    def log_pose(self, timeline: str, index: int, mech: Mechanism, qpos: np.ndarray) -> None:
        """One configuration: a Transform3D per body (world coordinates, flat under bodies/)."""
        if self._rec is None:
            return
        rr, m, d = self.rr, mech.model, mech.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        self._rec.set_time(timeline, sequence=int(index))
        for b in range(1, m.nbody):
            w, x, y, z = d.xquat[b]
            self._rec.log(
                f"world/bodies/{_body_name(m, b)}",
                rr.Transform3D(translation=d.xpos[b], quaternion=rr.Quaternion(xyzw=[x, y, z, w])),
            )

    def log_targets(
        self,
        timeline: str,
        index: int,
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float = 100.0,
    ) -> None:
        """Nominal and measured targets, and their difference magnified ``scale`` times."""
        if self._rec is None:
            return
        rr = self.rr
        self._rec.set_time(timeline, sequence=int(index))
        self._rec.log(
            "world/targets/nominal", rr.Points3D(nominal, radii=0.004, colors=[[120, 120, 255]])
        )
        self._rec.log(
            "world/targets/measured", rr.Points3D(measured, radii=0.004, colors=[[255, 120, 60]])
        )
        self._rec.log(
            "world/targets/error",
            rr.Arrows3D(
                origins=nominal,
                vectors=(measured - nominal) * scale,
                labels=[f"x{scale:g}"] * len(nominal),
                colors=[[255, 40, 40]],
            ),
        )

    def log_error_map(
        self,
        stage: str,
        layer: str,
        positions: np.ndarray,
        errors_mm: np.ndarray,
        vmax_mm: float | None = None,
    ) -> None:
        """Nodes of a layer coloured by their error (viridis, shared scale ``vmax_mm``)."""
        if self._rec is None:
            return
        vmax = float(np.max(errors_mm)) if vmax_mm is None else vmax_mm
        self._rec.log(
            f"error_maps/{stage}/{layer}",
            self.rr.Points3D(
                positions,
                colors=_colors(np.asarray(errors_mm), vmax),
                radii=0.008,
                labels=[f"{e:.3f} mm" for e in errors_mm],
            ),
            static=True,
        )

    def log_parameters(
        self,
        stage: str,
        names: Sequence[str],
        estimates: np.ndarray,
        std: np.ndarray | None = None,
        truth: np.ndarray | None = None,
    ) -> None:
        """Estimates (bars), their standard errors and the truth, plus a table."""
        if self._rec is None:
            return
        rr = self.rr
        self._rec.log(
            f"parameters/{stage}/estimate", rr.BarChart(np.asarray(estimates)), static=True
        )
        if std is not None:
            self._rec.log(f"parameters/{stage}/std", rr.BarChart(np.nan_to_num(std)), static=True)
        if truth is not None:
            self._rec.log(f"parameters/{stage}/truth", rr.BarChart(np.asarray(truth)), static=True)
        rows = ["| parameter | estimate | std | truth |", "|---|---|---|---|"]
        for k, n in enumerate(names):
            s = "" if std is None else f"{std[k]:.4g}"
            t = "" if truth is None else f"{truth[k]:.4g}"
            rows.append(f"| {n} | {estimates[k]:.4g} | {s} | {t} |")
        self.log_text(f"parameters/{stage}/table", "\n".join(rows))

    def log_metric(self, name: str, timeline: str, index: int, value: float) -> None:
        if self._rec is None:
            return
        self._rec.set_time(timeline, sequence=int(index))
        self._rec.log(f"metrics/{name}", self.rr.Scalars(float(value)))

    def log_text(self, path: str, markdown: str) -> None:
        if self._rec is None:
            return
        self._rec.log(
            path, self.rr.TextDocument(markdown, media_type=self.rr.MediaType.MARKDOWN), static=True
        )
