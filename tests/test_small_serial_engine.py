"""A small serial campaign runs on the numpy path (twin.kinematics.compiled.kernels_pay):

* below SERIAL_KERNEL_MIN poses a serial chain's forward kinematics and identification
  Jacobian by default are the numpy path's, and equal the compiled kernels' bit for bit (a
  serial chain has no Newton: both compute the same expressions), so no number depends on
  which one ran; a closed chain takes the kernels at any size;
* a command-line identify of a 20-pose serial arm therefore never imports numba (its first
  use costs more than the whole fit).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from test_kinematics_fast import machines_with_commands

from calib.fit.model import CalibrationModel, Prediction
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics import compiled
from twin.kinematics.batch import forward_batch
from twin.kinematics.compiled import (
    SERIAL_KERNEL_MIN,
    SERIAL_PARALLEL_MIN,
    kernels_pay,
    parallel_min,
)
from twin.kinematics.structure import fast_kinematics

ROOT = Path(__file__).resolve().parents[1]


def test_only_a_small_serial_batch_leaves_the_kernels():
    machines = machines_with_commands(4, 1)
    arm, hexapod = machines["arm6r"][0], machines["hexapod_rrrprr"][0]
    assert not kernels_pay(fast_kinematics(arm), SERIAL_KERNEL_MIN - 1)
    assert kernels_pay(fast_kinematics(arm), SERIAL_KERNEL_MIN)
    assert kernels_pay(fast_kinematics(hexapod), 1)
    # threads only for a closed chain's batches, or a serial chain's very large ones
    assert parallel_min(fast_kinematics(hexapod), 256) == 256
    assert parallel_min(fast_kinematics(arm), 256) == SERIAL_PARALLEL_MIN > 256


def test_small_serial_batch_equals_the_kernels_bit_for_bit(monkeypatch):
    mech, commands = machines_with_commands(SERIAL_KERNEL_MIN - 4, 5)["arm6r"]
    params = load_parameter_set(ROOT / "models/arm6r.params.toml", mech.model)
    values = np.random.default_rng(2).normal(0.0, 1e-4, len(params))
    model = CalibrationModel(mech, params)
    moved = model.mechanism(values)
    default = forward_batch(moved, commands)
    kernels = forward_batch(moved, commands, compiled=True)
    numpy_path = forward_batch(moved, commands, compiled=False)
    for a in (default, kernels):
        np.testing.assert_array_equal(a.targets, numpy_path.targets)
        np.testing.assert_array_equal(a.qpos, numpy_path.qpos)
        np.testing.assert_array_equal(a.tool_rotation, numpy_path.tool_rotation)
    pred = Prediction(default.targets, default.qpos, commands)
    jac = model.jacobian(values, pred)  # the numpy path at this size
    monkeypatch.setattr(compiled, "SERIAL_KERNEL_MIN", 0)  # the kernel at any size
    jac_kernel = model.jacobian(values, pred)
    assert np.abs(jac).max() > 0.1  # not a vacuous comparison
    np.testing.assert_array_equal(jac, jac_kernel)


def test_a_small_serial_identify_never_imports_numba(tmp_path):
    """20 poses of the 6R arm's twin through the command line's own workflow."""
    script = f"""
import sys
import numpy as np
from calib.fit.observations import Observations
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.workspace import uniform_commands
mech = Mechanism.from_xml("{ROOT}/models/arm6r.xml")
params = load_parameter_set("{ROOT}/models/arm6r.params.toml", mech.model)
model = CalibrationModel(mech, params)
cmds = uniform_commands(mech, 20, 0.8, np.random.default_rng(4))
truth = np.random.default_rng(5).normal(0.0, 1e-4, len(params))
obs = Observations(cmds, model.predict(truth, cmds).targets)
res = identify(CalibrationModel(mech, params), obs, unidentifiable="fix")
assert res.converged and res.residual_rms < 1e-9, (res.converged, res.residual_rms)
print("numba" in sys.modules)
"""
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"
