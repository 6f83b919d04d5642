"""The machine in a recording: its bodies and geoms, its poses on pose timelines, and the
nominal and measured targets with their errors magnified."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from scenarios.recording.session import _active, _error_labels, entity_part
from twin.mechanism import Mechanism

TARGET_RADIUS = 0.003  # metres


NOMINAL_COLOUR, MEASURED_COLOUR, ERROR_COLOUR = [110, 130, 255], [255, 130, 60], [230, 40, 40]


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


def _log_pose_set(
    rec: MachineViews,
    timeline: str,
    mech: Mechanism,
    commands: np.ndarray,
    poses: np.ndarray,
    group: str,
    scale: float,
) -> None:
    from twin.kinematics import forward_batch, pose_to_frame

    sol = forward_batch(mech, commands)
    local = mech.target_local()
    nominal = np.einsum("nij,tj->nti", pose_to_frame(poses)[0], local) + poses[:, None, :3]
    rec.log_poses(
        timeline, range(len(commands)), mech, sol.qpos, nominal, sol.targets, group, scale
    )


class MachineViews:
    """The machine, its poses and its targets (a mixin of Recorder)."""

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
