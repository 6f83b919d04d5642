"""The machine in a recording: its bodies and geoms, its poses on the pose timeline, and the
nominal and measured targets with their errors magnified and labelled in mm."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from scenarios.recording.blueprints import TargetGroup
from scenarios.recording.parts import _name, _xyzw, geom_shape
from scenarios.recording.session import _active, entity_part
from scenarios.recording.targets import (
    ARROW_SHARE,
    ERROR_COLOUR,
    LEADER_COLOUR,
    MEASURED_COLOUR,
    arrow_scale,
    error_labels,
    label_positions,
    radii,
    spread,
    target_colours,
)
from twin.mechanism import Mechanism

FIELD_COLOUR = [235, 120, 120]  # every pose's arrow at once: lighter than the pose's own


def _log_pose_set(
    rec: MachineViews,
    timeline: str,
    mech: Mechanism,
    commands: np.ndarray,
    poses: np.ndarray,
    group: str,
    scale: float | None,
    machine: str,
) -> None:
    from twin.kinematics import forward_batch, pose_to_frame

    sol = forward_batch(mech, commands)
    local = mech.target_local()
    nominal = np.einsum("nij,tj->nti", pose_to_frame(poses)[0], local) + poses[:, None, :3]
    rec.log_poses(
        timeline, range(len(commands)), mech, sol.qpos, nominal, sol.targets, group, scale, machine
    )


class MachineViews:
    """The machine's views of a Recorder (a mixin of session.RecorderBase)."""

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
        field: bool = False,
    ) -> None:
        """Poses (P, nq) at ``indices`` of ``timeline``, each with its targets (P, T, 3); the
        error arrows magnified ``scale`` times (None: the 1-2-5 factor that draws the largest
        error as at most 80 % of the targets' spread or of the tool head's size, whichever is
        larger: a share of what the view frames, targets.arrow_scale); ``field``: every
        pose's arrow shown at once as well (a layer of nodes, one target each).

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
        head = self._log_bodies_columns(timeline, indices, mech, qpos, machine)
        if scale is None:  # a share of what the view frames: the targets or the head
            extent = max(spread(nominal), spread(head, least=0.0))
            scale = arrow_scale(nominal, measured, ARROW_SHARE * extent)
        self._log_targets(timeline, indices, nominal, measured, scale, group, machine, field, head)

    def _log_targets(
        self,
        timeline: str,
        indices: list[int],
        nominal: np.ndarray,
        measured: np.ndarray,
        scale: float,
        group: str,
        machine: str,
        field: bool = False,
        head: np.ndarray | None = None,
    ) -> None:
        """The targets of every pose (P, T, 3) in one column per entity: each target's nominal
        point in its colour, the measured point at the tip of the error arrow (magnified
        ``scale`` times), the error in mm on a label set off with a leader line; ``field``:
        every pose's arrow shown at once too (static, lighter). The group's view is framed on
        the targets, their arrows and labels and the points ``head`` (the tool's body)."""
        rr = self.rr
        nominal = np.asarray(nominal, dtype=float).reshape(len(indices), -1, 3)
        measured = np.asarray(measured, dtype=float).reshape(nominal.shape)
        self.logged.use_timeline(timeline)
        n_poses, n_targets = nominal.shape[:2]
        lengths = [n_targets] * n_poses
        flat_nominal, flat_measured = nominal.reshape(-1, 3), measured.reshape(-1, 3)
        arrows = (flat_measured - flat_nominal) * scale
        span = spread(nominal)
        point_radius, arrow_radius = radii(span)
        labels_at = label_positions(nominal, span).reshape(-1, 3)
        times = [rr.TimeColumn(timeline, sequence=indices)]
        part = entity_part(group)
        root = f"world/targets/{part}"

        def points(positions: np.ndarray, colours: Any, radius: float) -> list[Any]:
            return [
                *rr.Points3D.columns(positions=positions, colors=colours).partition(lengths),
                *rr.Points3D.columns(radii=[radius] * n_poses),
            ]

        columns = {
            "nominal": points(flat_nominal, target_colours(n_poses, n_targets), point_radius),
            "measured_magnified": points(
                flat_nominal + arrows, [MEASURED_COLOUR] * len(flat_nominal), point_radius / 2
            ),
            "error": [
                *rr.Arrows3D.columns(origins=flat_nominal, vectors=arrows).partition(lengths),
                *rr.Arrows3D.columns(
                    radii=[arrow_radius] * n_poses, colors=[ERROR_COLOUR] * n_poses
                ),
            ],
            "error_mm": [
                *rr.Points3D.columns(
                    positions=labels_at, labels=error_labels(flat_nominal, flat_measured)
                ).partition(lengths),
                *rr.Points3D.columns(
                    radii=[point_radius / 4] * n_poses,
                    colors=[ERROR_COLOUR] * n_poses,
                    show_labels=[True] * n_poses,
                ),
            ],
            "error_mm/leader": [
                *rr.LineStrips3D.columns(
                    strips=np.stack([flat_nominal, labels_at], axis=1)
                ).partition(lengths),
                *rr.LineStrips3D.columns(
                    radii=[arrow_radius / 4] * n_poses, colors=[LEADER_COLOUR] * n_poses
                ),
            ],
        }
        for name, cols in columns.items():
            self._rec.send_columns(f"{root}/{name}", indexes=times, columns=cols)
        if field:
            self._rec.log(
                f"{root}/field",
                rr.Arrows3D(
                    origins=flat_nominal,
                    vectors=arrows,
                    radii=arrow_radius,
                    colors=[FIELD_COLOUR],
                ),
                rr.Points3D(flat_nominal, radii=point_radius / 2, colors=[FIELD_COLOUR]),
                static=True,
            )
        self.logged.machine_bounds.add(flat_nominal)
        self.logged.poses.update(indices)
        entry = self.logged.target_groups.setdefault(
            part, TargetGroup(f"{group}: errors x{scale:g}", machine)
        )
        entry.bounds.add(flat_nominal)
        entry.targets.add(flat_nominal)
        entry.bounds.add(labels_at)
        entry.bounds.add(flat_nominal + arrows)
        if head is not None:
            entry.bounds.add(head)

    def _log_bodies_columns(
        self,
        timeline: str,
        indices: list[int],
        mech: Mechanism,
        qpos: np.ndarray,
        machine: str = "",
    ) -> np.ndarray:
        """The bodies' transforms at every pose, one column per body; returns the corners of
        the boxes around the tool body's shown geoms at the first pose (metres, (K, 3)): the
        tool head as the view opens, which it frames with the targets (at the other poses
        the head moves over the targets, whose box the view holds)."""
        rr, m, d = self.rr, mech.model, mech.data
        self.logged.use_timeline(timeline)
        xpos = np.empty((len(qpos), m.nbody, 3))
        xquat = np.empty((len(qpos), m.nbody, 4))
        tool = [
            g
            for g in range(m.ngeom)
            if m.geom_bodyid[g] == mech.tool_body and geom_shape(self.rr, m, g) is not None
        ]
        # each geom's box in its own frame (MuJoCo's geom_aabb: centre, half sides): corners
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
        local = m.geom_aabb[tool, None, :3] + signs[None] * m.geom_aabb[tool, None, 3:]
        head = []
        for i, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            self.logged.machine_bounds.add(d.xpos[1:])
            xpos[i], xquat[i] = d.xpos, d.xquat
            rot = d.geom_xmat[tool].reshape(-1, 3, 3)
            if i == 0:
                head.append(d.geom_xpos[tool, None] + np.einsum("gij,gcj->gci", rot, local))
        xyzw = xquat[:, :, [1, 2, 3, 0]]
        times = [rr.TimeColumn(timeline, sequence=indices)]
        for b in range(1, m.nbody):
            self._rec.send_columns(
                self._body_path(m, b, machine),
                indexes=times,
                columns=rr.Transform3D.columns(translation=xpos[:, b], quaternion=xyzw[:, b]),
            )
        self.logged.poses.update(indices)
        return head[0].reshape(-1, 3) if head else np.empty((0, 3))

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
