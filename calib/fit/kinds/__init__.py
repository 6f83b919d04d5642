"""The error-model kinds that offset the joint values by the commands and the machine's state
at each reading (twin.offset_kinds): what each reading's state is (:mod:`.state`) and the
offsets and their identification columns (:mod:`.offsets`)."""

from calib.fit.kinds.offsets import OffsetMap
from calib.fit.kinds.state import PoseState, approach_directions, with_directions

__all__ = ["OffsetMap", "PoseState", "approach_directions", "with_directions"]
