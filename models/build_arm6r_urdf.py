"""Write models/arm6r.urdf: the generic 6R arm of arm6r.mdh.csv as a URDF, as vendors ship one.

    python models/build_arm6r_urdf.py

One link per DH frame (``base``, ``link1`` .. ``link6``), one revolute joint per row, named
as in the table (A1 .. A6): joint i's origin is the modified-DH transform Rx(alpha_{i-1})
Tx(a_{i-1}) Rz(theta_i) Tz(d_i) as ``xyz`` and ``rpy`` (R = Rz(y) Ry(p) Rx(r)), its axis z,
its limits the table's. No reflector or tool in the URDF (URDFs have none): ``python -m
twin.formats.from_urdf models/arm6r.urdf --target target_1=link6@50,0,110 --tool link6@0,0,120
--out-dir DIR`` places them as in arm6r.xml, and its forward kinematics equals arm6r.xml's
(tests/test_from_urdf.py). Every number keeps all its digits.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _clean(r: np.ndarray) -> np.ndarray:
    """Entries within 1e-15 of 0 or +-1 set to them (the table's angles are multiples of 90)."""
    out = r.copy()
    for target in (0.0, 1.0, -1.0):
        out[np.abs(out - target) < 1e-15] = target
    return out


def rpy(r: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of ``r`` (R = Rz(y) Ry(p) Rx(r)); at pitch +-90 deg roll is 0."""
    r = _clean(r)
    if abs(abs(r[2, 0]) - 1.0) < 1e-12:
        return 0.0, -math.asin(r[2, 0]), math.atan2(-r[0, 1], r[1, 1])
    return math.atan2(r[2, 1], r[2, 2]), -math.asin(r[2, 0]), math.atan2(r[1, 0], r[0, 0])


def _text(values) -> str:
    return " ".join(repr(float(v)) if v else "0" for v in values)


def build() -> str:
    import sys

    sys.path.insert(0, str(HERE.parent))
    from twin.formats.dh_table import read_dh_table

    table = read_dh_table(HERE / "arm6r.mdh.csv")
    lines = [
        '<?xml version="1.0"?>',
        "<!-- arm6r: the generic 6R arm of arm6r.mdh.csv as a URDF (metres, radians), written",
        "     by models/build_arm6r_urdf.py: joint i's origin is Rx(alpha) Tx(a) Rz(theta) Tz(d)",
        "     of row i. No inertia, no meshes: kinematics only. -->",
        '<robot name="arm6r">',
        '  <link name="base"/>',
    ]
    parent = "base"
    for i, j in enumerate(table.joints, start=1):
        rot = _rx(j.alpha) @ _rz(j.theta)
        xyz = np.array([j.a, 0.0, 0.0]) + _rx(j.alpha) @ np.array([0.0, 0.0, j.d])
        xyz[np.abs(xyz) < 1e-15] = 0.0
        lines += [
            f'  <link name="link{i}"/>',
            f'  <joint name="{j.name}" type="revolute">',
            f'    <parent link="{parent}"/>',
            f'    <child link="link{i}"/>',
            f'    <origin xyz="{_text(xyz)}" rpy="{_text(rpy(rot))}"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{j.lower!r}" upper="{j.upper!r}" effort="100" velocity="2"/>',
            "  </joint>",
        ]
        parent = f"link{i}"
    lines += ["</robot>", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    out = HERE / "arm6r.urdf"
    out.write_text(build(), encoding="utf-8")
    print(f"wrote {out}")
