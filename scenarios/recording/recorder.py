"""A rerun recording of a scenario: the machine, the targets, the errors, the estimates.

Headless by default: the recording is encoded in memory (``rec.binary_stream`` before any
logging) and written to its ``.rrd`` file on ``close`` by Python, atomically, so that a full
disk raises an OSError instead of stalling rerun's own file writer (it deadlocked after "No
space left on device"); the flush waits at most FLUSH_TIMEOUT_S. ``spawn_viewer`` also opens
the viewer (then rerun saves the file itself, as before). A Recorder made with no path and
no viewer does nothing, cheaply (rerun is not even imported). See docs/recordings.md for
what each scenario's recording looks like.

What a study logs, and where:

* ``log_mechanism``: MJCF has no rerun loader, so each body is logged flat under
  ``world/bodies/<body>`` and its geoms as static shapes in body coordinates below it;
  ``log_pose`` places the bodies (a world Transform3D each, from ``xpos``/``xquat``) at one
  index of a pose timeline, ``log_targets`` the nominal and measured targets of that pose and
  the error magnified ``scale`` times (labelled in mm) under ``world/targets/<group>``.
* ``log_error_map``: static nodes coloured by error (viridis, grey for NaN) with a colour
  scale in mm beside them, under ``error_maps/<stage>/<layer>``.
* ``log_metric`` / ``log_points``: one point of ``metrics/<family>/<curve>`` on a timeline,
  drawn as a line or as markers (a curve of one point is always drawn as a marker).
* ``log_parameters``, ``log_text``, ``log_report``, ``log_verdict``: markdown text views (the
  estimates by name with standard errors, the report's key numbers, the named effect);
  ``log_bars`` a static bar chart; ``log_image`` a report's figure (a PNG) as an image;
  ``log_loop`` the loop-closing residuals before and after.

Each call notes what it logged in ``self.logged`` (``recording_blueprints.Logged``). On
``close`` the series styles are written, the first pose is copied onto the active timeline
when that is not a pose timeline (so the machine is not empty there), and, if asked for with
``send_blueprint``, the blueprint is built from ``self.logged`` (``build_blueprint``): only
views that have data on the timeline the viewer opens on. Every timed log call sets its own
timeline only (the stream's time is reset first), so a metric logged after a pose does not
inherit the pose's time point. ``RERUN_STRICT`` is read when a Recorder is made (rerun itself
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
