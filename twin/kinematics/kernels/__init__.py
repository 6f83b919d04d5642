"""Compiled kernels (numba) of batched forward kinematics: one pose at a time in machine code.

The numpy path (twin.kinematics.batch with twin.kinematics.tree and twin.kinematics.reduced)
spends its time passing over arrays: each Newton step makes some thirty passes over every
pose's frames, at about a nanosecond per element. Here each pose runs the whole Newton in
registers and a few hundred bytes of scratch, from the same model arrays: MuJoCo's
``mj_kinematics`` (bodies parents first, hinge, slide, ball and free joints), the closure
residual (position rows, and the rotation vector of ``R_a R_b^T`` for a weld), the closure
Jacobian over the free dofs (a rotational dof moves a site by ``w x (p - anchor)`` and turns
it by ``w``, a translational one moves it by ``w``; a closure's column is its first site's
motion less its second's), the solve by elimination per closure (each closure's private
columns eliminated, partial pivoting when the system is square, Householder when it is
over-determined, then the reduced system over the shared columns), back substitution, the
damped step and ``mj_integratePos``. Steps, damping of long steps, tolerance and stall rule
are those of twin.kinematics.single_pose. The identification Jacobian
(:func:`jacobian_batch`) reuses the tree, the closure blocks and their elimination for the
adjoint solve.

Everything is read from arrays the caller builds from the MJCF (twin.kinematics.compiled),
so every machine goes through this one code path. ``nogil``: the caller's threads run poses
side by side. ``cache``: compiled once per environment (numba writes the machine code next
to these files, or to NUMBA_CACHE_DIR). Numba's cache notices a change of a function's own
file, not of the files its callees are in: :mod:`.jit` drops the whole package's cache when
any of its files changed (a digest of their text), before any kernel is loaded.

* :mod:`.frames`: ``mj_kinematics`` of one pose, site positions and frames, rotation vectors;
* :mod:`.elimination`: Householder, Gauss, back substitution, the closure blocks and step;
* :mod:`.newton`: the whole forward-kinematics Newton of a batch of poses (:func:`newton_batch`);
* :mod:`.jacobian`: the identification Jacobian by the adjoint solve (:func:`jacobian_batch`).
"""

from __future__ import annotations

from twin.kinematics.kernels.jit import drop_stale_cache

drop_stale_cache()

from twin.kinematics.kernels.frames import site_frame, site_position, tree  # noqa: E402
from twin.kinematics.kernels.jacobian import jacobian_batch  # noqa: E402
from twin.kinematics.kernels.newton import newton_batch  # noqa: E402

__all__ = ["jacobian_batch", "newton_batch", "site_frame", "site_position", "tree"]
