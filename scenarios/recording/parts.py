"""Pieces of a recording that are pure functions: the geoms of an MJCF as rerun shapes, the
colours and colour scale of an error map, a parameter table as markdown
(used by ``scenarios.recording.recorder``)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from scenarios.recording.blueprints import Bounds


def _name(m: mujoco.MjModel, kind: mujoco.mjtObj, i: int, fallback: str) -> str:
    return mujoco.mj_id2name(m, kind, i) or f"{fallback}{i}"


def _xyzw(wxyz: np.ndarray) -> list[float]:
    w, x, y, z = (float(c) for c in wxyz)
    return [x, y, z, w]


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
