"""``python -m twin.kinematics.warm_up`` (``make setup``): the compiled kernels into numba's
cache."""

from __future__ import annotations

import numpy as np

from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity_batch import target_jacobian_batch
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet

WARM_UP_MODEL = """
<mujoco>
  <worldbody>
    <body name="crank">
      <joint name="j1" type="hinge" axis="0 0 1"/>
      <site name="tip" pos="0.3 0 0"/>
      <site name="tool" pos="0.2 0 0"/>
    </body>
    <body name="held">
      <freejoint/>
      <site name="end"/>
      <site name="target_1" pos="0 0 0.1"/>
    </body>
  </worldbody>
  <equality><weld site1="end" site2="tip"/></equality>
  <actuator><position name="crank" joint="j1"/></actuator>
</mujoco>
"""


def warm_up() -> None:
    """Compile the kernels (forward kinematics, the identification Jacobian) into numba's
    cache now (``make setup`` calls this: the first compilation takes tens of seconds, which
    a test run or a scenario should not pay)."""

    mech = Mechanism.from_xml_string(WARM_UP_MODEL)
    solution = forward_batch(mech, np.array([[0.1]]))
    params = ParameterSet([Parameter("tip_x", "site_pos", "tip", (1.0, 0.0, 0.0))], mech.model)
    target_jacobian_batch(mech, params, np.zeros(1), solution.qpos)


if __name__ == "__main__":
    warm_up()
