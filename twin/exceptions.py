"""Errors a user can cause in the twin, each naming its cause."""

from __future__ import annotations


class TwinError(Exception):
    """Base class of the twin's errors."""


class ModelError(TwinError):
    """The MJCF lacks what the twin needs (actuators, targets, site-based closures, ...)."""


class ClosureError(TwinError):
    """A closed-chain solve (forward or inverse kinematics) did not converge."""


class WorkspaceError(TwinError):
    """A pose or an actuator command lies outside the workspace or the stroke."""


class ParameterError(TwinError):
    """A geometric parameter is unknown, malformed or refers to a missing MJCF element."""
