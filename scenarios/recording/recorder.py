"""A rerun recording of a scenario: the machine, the targets, the errors, the estimates.

Headless by default: the recording is encoded in memory (``rec.binary_stream`` before any
logging) and written to its ``.rrd`` file on ``close`` by Python, atomically, so that a full
disk raises an OSError instead of stalling rerun's own file writer (it deadlocked after "No
space left on device"); the flush waits at most FLUSH_TIMEOUT_S. ``spawn_viewer`` also opens
the viewer (then rerun saves the file itself, as before). A Recorder made with no path and
no viewer does nothing, cheaply (rerun is not even imported). See docs/recordings.md for
what each scenario's recording looks like.

A recording has one timeline at most, the poses' (rerun's own wall-clock timelines are off):
the viewer plots and poses against the timeline selected, so a second one would be a face of
the recording where the other views are empty. A second timeline raises
``blueprints.SecondTimeline``. What a study logs, and where:

* ``log_mechanism``: MJCF has no rerun loader, so each body is logged flat under
  ``world/bodies/<body>`` (``world/<machine>/bodies`` for one of several machines) and its
  geoms as static shapes in body coordinates below it; ``log_pose`` / ``log_poses`` place the
  bodies (a world Transform3D each, from ``xpos``/``xquat``) at indices of the pose timeline,
  with the nominal and measured targets, the error arrows (magnified to be seen, the factor in
  the view's title) and each error in mm as a label set off from the target, under
  ``world/targets/<group>`` (targets).
* ``log_error_map``: static nodes coloured by error (viridis, grey for NaN) with a colour
  scale in mm beside them, under ``error_maps/<stage>/<layer>``.
* ``log_figure``: a static figure (a PNG, a report's figure), for any curve that is not
  against the poses: an iteration count, a rank index, a variable that explains an effect.
* ``log_metric`` / ``log_points``: one point of ``metrics/<family>/<curve>`` on the timeline,
  drawn as a line or as markers (a curve of one point is always drawn as a marker).
* ``log_parameters``, ``log_text``, ``log_report``, ``log_verdict``: markdown text views (the
  estimates by name with standard errors, the report's key numbers, the named effect);
  ``log_loop`` the loop-closing residuals before and after.

Each call notes what it logged in ``self.logged`` (``blueprints.Logged``). On
``close`` the series styles are written, a machine never posed is placed at its home pose
(static), and, if asked for with ``send_blueprint``, the blueprint is built from
``self.logged`` (``build_blueprint``). Every timed log call sets its own time only (the
stream's time is reset first). ``RERUN_STRICT`` is read when a Recorder is made (rerun itself
reads it once, at import): when set, a rerun usage mistake raises instead of becoming a
warning.
"""

from __future__ import annotations

from scenarios.recording.charts import ChartViews
from scenarios.recording.machine import MachineViews
from scenarios.recording.session import RecorderBase


class Recorder(MachineViews, ChartViews, RecorderBase):
    """Logs a scenario to rerun; disabled (every method a no-op) without path and viewer.

    What is logged is noted in ``self.logged``; on ``close`` the blueprint (if asked for with
    ``send_blueprint``) is built from it, so every view it holds has data."""
