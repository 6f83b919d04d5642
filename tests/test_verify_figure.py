"""verify's figure scales to many poses: one line of markers per side, the worst few named."""

from __future__ import annotations

import numpy as np

from calib.cli.verify_figure import (
    LABELLED_POSES,
    WORST,
    save_verification_png,
    verification_figure,
)
from calib.fit.position_error import stats_mm
from calib.fit.verify import Side, Verification


def _verification(n: int, seed: int = 0) -> tuple[Verification, np.ndarray]:
    rng = np.random.default_rng(seed)
    before = rng.uniform(0.5e-3, 2e-3, (n, 1))
    after = rng.uniform(5e-6, 5e-5, (n, 1))
    worst = rng.choice(n, size=WORST, replace=False)
    after[worst] = 1e-3 * (1 + np.arange(WORST))[:, None]  # the poses to be named
    sides = [Side(stats_mm(x), x, None) for x in (before, after)]
    v = Verification(np.arange(1000, 1000 + n), ("target_1",), *sides, note="")
    return v, worst


def _texts(fig) -> list[str]:
    ax = fig.axes[0]
    return [t.get_text() for t in ax.texts]


def test_many_poses_name_only_the_worst_after():
    import matplotlib.pyplot as plt

    v, worst = _verification(924)
    fig = verification_figure(v)
    try:
        ax = fig.axes[0]
        assert sorted(_texts(fig)) == sorted(str(1000 + k) for k in worst)
        assert len(ax.lines) == 2 and not ax.patches  # a line per side, no bar per pose
        assert all(len(line.get_xdata()) == 924 for line in ax.lines)
        assert len(ax.get_xticklabels()) < 30  # numbers on the axis, not 924 pose_ids
    finally:
        plt.close(fig)


def test_few_poses_keep_every_pose_id_on_the_axis(tmp_path):
    import matplotlib.pyplot as plt

    v, _ = _verification(12)
    fig = verification_figure(v)
    try:
        labels = [t.get_text() for t in fig.axes[0].get_xticklabels()]
        assert labels == [str(1000 + k) for k in range(12)] and 12 <= LABELLED_POSES
        assert not _texts(fig)
    finally:
        plt.close(fig)
    assert save_verification_png(v, tmp_path / "v.png").stat().st_size > 1000
