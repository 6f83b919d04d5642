"""The committed models are what their generators make, on any CPU, within tolerance.

Generated files are compared numerically (``twin.formats.mjcf_numbers`` explains why text is not
enough): the same elements and attributes in the same order, strings equal, numbers equal
to 1e-9 (metres, radians, unitless axes). Regenerating under two OpenBLAS core types gives
the same numbers too.
"""

from __future__ import annotations

import importlib.util
import json
import os
import platform
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from twin.formats.mjcf_numbers import canonical_quat, fmt, snap

ROOT = Path(__file__).resolve().parent.parent
MODELS = {"hexapod": "hexapod_rrrprr", "polisher": "polisher"}
ATOL = 1e-9


def _builder(machine: str):
    spec = importlib.util.spec_from_file_location(
        f"build_{machine}_under_test", ROOT / "models" / f"build_{machine}.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _numbers(text: str) -> np.ndarray | None:
    try:
        return np.array([float(t) for t in text.split()])
    except ValueError:
        return None


def xml_differences(a: str, b: str, atol: float = ATOL) -> list[str]:
    """Where two MJCF texts differ beyond ``atol`` (empty: numerically the same)."""
    out: list[str] = []
    ea, eb = ET.fromstring(a), ET.fromstring(b)
    la, lb = list(ea.iter()), list(eb.iter())
    if len(la) != len(lb):
        return [f"{len(la)} elements against {len(lb)}"]
    for x, y in zip(la, lb, strict=True):
        where = f"<{x.tag} name={x.get('name')!r}>"
        if x.tag != y.tag or list(x.attrib) != list(y.attrib):
            out.append(f"{where}: tag or attribute names differ from <{y.tag} {list(y.attrib)}>")
            continue
        for key, va in x.attrib.items():
            vb = y.attrib[key]
            na, nb = _numbers(va), _numbers(vb)
            if na is None or nb is None:
                if va != vb:
                    out.append(f"{where} {key}: {va!r} != {vb!r}")
            elif na.shape != nb.shape or not np.allclose(na, nb, rtol=0, atol=atol):
                out.append(f"{where} {key}: {va} != {vb}")
    return out


def toml_differences(a: str, b: str, atol: float = ATOL) -> list[str]:
    """Where two TOML texts differ beyond ``atol`` in their numbers."""
    out: list[str] = []

    def walk(x: object, y: object, where: str) -> None:
        if isinstance(x, dict) and isinstance(y, dict):
            if list(x) != list(y):
                out.append(f"{where}: keys {list(x)} != {list(y)}")
                return
            for k in x:
                walk(x[k], y[k], f"{where}.{k}")
        elif isinstance(x, list) and isinstance(y, list):
            if len(x) != len(y):
                out.append(f"{where}: {len(x)} items != {len(y)}")
                return
            for i, (u, v) in enumerate(zip(x, y, strict=True)):
                walk(u, v, f"{where}[{i}]")
        elif isinstance(x, (int, float)) and isinstance(y, (int, float)):
            if abs(float(x) - float(y)) > atol:
                out.append(f"{where}: {x} != {y}")
        elif x != y:
            out.append(f"{where}: {x!r} != {y!r}")

    walk(tomllib.loads(a), tomllib.loads(b), "")
    return out


@pytest.mark.parametrize("machine", sorted(MODELS))
def test_committed_files_equal_generator_output_numerically(machine):
    mod, stem = _builder(machine), MODELS[machine]
    xml = (ROOT / "models" / f"{stem}.xml").read_text()
    params = (ROOT / "models" / f"{stem}.params.toml").read_text()
    assert xml_differences(xml, mod.build_xml()) == []
    assert toml_differences(params, mod.build_parameters()) == []


@pytest.mark.parametrize("machine", sorted(MODELS))
def test_committed_quaternions_are_canonical(machine):
    """Unit norm, no tiny components written, first non-zero component positive."""
    root = ET.fromstring((ROOT / "models" / f"{MODELS[machine]}.xml").read_text())
    quats = [
        np.array([float(t) for t in e.get("quat").split()]) for e in root.iter() if e.get("quat")
    ]
    assert len(quats) > 10
    for q in quats:
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-10)
        assert np.all((q == 0) | (np.abs(q) >= 1e-12))
        assert q[np.flatnonzero(q)[0]] > 0


def test_comparison_catches_a_real_difference():
    """The numerical comparison is not vacuous: 1e-6 m in one coordinate is found."""
    mod = _builder("hexapod")
    xml = mod.build_xml()
    changed = xml.replace('pos="0 0 0.005"', 'pos="0 0 0.005001"', 1)
    assert changed != xml
    assert len(xml_differences(xml, changed)) == 1
    params = mod.build_parameters()
    assert toml_differences(params, params.replace("axis = [0, 0, 1]", "axis = [0, 1, 1]", 1))


def test_snap_and_canonical_quaternion():
    assert fmt([1e-17, -1e-30, -0.0, 0.25]) == "0 0 0 0.25"
    np.testing.assert_array_equal(snap([-3e-13, 2e-12]), [0.0, 2e-12])
    # a 180-degree rotation about z: w is 0 up to rounding, either sign
    for w in (1e-17, -1e-17, 0.0):
        np.testing.assert_array_equal(canonical_quat([w, 0.0, 0.0, -1.0]), [0, 0, 0, 1])
    np.testing.assert_allclose(canonical_quat([-1, 1, 0, 0]), [0.5**0.5, -(0.5**0.5), 0, 0])


def _cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


GENERATE = """
import importlib.util, json, sys, threadpoolctl, numpy
numpy.ones(3) @ numpy.ones(3)
out = {"blas": [i.get("architecture") for i in threadpoolctl.threadpool_info()]}
for machine in ("hexapod", "polisher"):
    spec = importlib.util.spec_from_file_location("b", f"models/build_{machine}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out[machine] = [mod.build_xml(), mod.build_parameters()]
json.dump(out, sys.stdout)
"""


def test_generators_agree_under_two_openblas_kernels():
    """Prescott (SSE3) and Haswell (AVX2) kernels give numerically the same models."""
    flags = _cpu_flags()
    if platform.machine() not in ("x86_64", "AMD64") or "avx2" not in flags:
        pytest.skip("needs an x86-64 CPU with AVX2 to force two OpenBLAS kernels")
    runs = {}
    for core in ("Prescott", "Haswell"):
        env = {**os.environ, "OPENBLAS_CORETYPE": core}
        proc = subprocess.run(
            [sys.executable, "-c", GENERATE],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        runs[core] = json.loads(proc.stdout)
    if not all(runs[c]["blas"] for c in runs):
        pytest.skip("numpy is not linked to OpenBLAS here")
    assert runs["Prescott"]["blas"] != runs["Haswell"]["blas"]  # two kernels really ran
    for machine in ("hexapod", "polisher"):
        (xa, pa), (xb, pb) = runs["Prescott"][machine], runs["Haswell"][machine]
        assert xml_differences(xa, xb) == []
        assert toml_differences(pa, pb) == []
        committed = (ROOT / "models" / f"{MODELS[machine]}.xml").read_text()
        assert xml_differences(committed, xb) == []
