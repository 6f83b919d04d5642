"""Report figures: real PNG files, readable back, written atomically."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from scenarios import figures

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _grid(n: int = 7, half: float = 150.0) -> np.ndarray:
    x, y = np.meshgrid(np.linspace(-half, half, n), np.linspace(-half, half, n))
    return np.column_stack([x.ravel(), y.ravel()])


def _read(path: Path) -> np.ndarray:
    """Check the file is a PNG and return its pixels (H, W, channels)."""
    assert path.is_file() and path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
    assert np.ptp(img[..., :3]) > 0.5  # something is drawn, not a blank page
    return img


def _no_leftovers(folder: Path) -> None:
    assert not [p for p in folder.iterdir() if p.name.startswith(".")]


def test_error_map_png(tmp_path):
    xy = _grid()
    err = 0.01 + 1e-4 * np.hypot(*xy.T)
    out = figures.error_map_png(
        tmp_path / "map.png", "layer z = 220 mm", xy, err, "position error (mm)"
    )
    assert out == tmp_path / "map.png"
    img = _read(out)
    assert 0.9 < img.shape[1] / img.shape[0] < 1.5  # about as wide as tall (6 x 5 in)
    _no_leftovers(tmp_path)


def test_error_map_png_degenerate_layers(tmp_path):
    # a single row of nodes (no area), a constant error, and a node without value
    xy = np.column_stack([np.linspace(0, 100, 5), np.zeros(5)])
    _read(figures.error_map_png(tmp_path / "a.png", "row", xy, np.full(5, 0.02), "e (mm)"))
    err = np.linspace(0, 1, 49)
    err[3] = np.nan
    _read(figures.error_map_png(tmp_path / "b.png", "gap", _grid(), err, "e (mm)", vmax=2.0))
    with pytest.raises(ValueError, match="49 node positions but 3"):
        figures.error_map_png(tmp_path / "c.png", "bad", _grid(), np.ones(3), "e (mm)")
    assert not (tmp_path / "c.png").exists()


@pytest.mark.parametrize("shared", [True, False])
def test_error_maps_png_side_by_side(tmp_path, shared):
    xy = _grid()
    panels = [
        ("before, z = 200", xy, 0.2 + 1e-3 * np.abs(xy[:, 0])),
        ("after, z = 200", xy, 0.01 + 1e-5 * np.abs(xy[:, 1])),
        ("before, z = 240", xy, 0.3 + 1e-3 * np.abs(xy[:, 1])),
    ]
    img = _read(
        figures.error_maps_png(
            tmp_path / "maps.png", "before / after", panels, "error (mm)", shared_scale=shared
        )
    )
    assert img.shape[1] > 2 * img.shape[0]  # three panels in a row
    with pytest.raises(ValueError, match="at least one panel"):
        figures.error_maps_png(tmp_path / "none.png", "t", [], "e (mm)")


def test_parameter_bars_png_grows_with_the_count(tmp_path):
    rng = np.random.default_rng(0)
    heights = {}
    for n in (6, 54):
        names = [f"leg{k // 9 + 1}.p{k % 9}" for k in range(n)]
        est = rng.normal(0, 0.5, n)
        img = _read(
            figures.parameter_bars_png(
                tmp_path / f"bars{n}.png",
                f"{n} estimates",
                names,
                est,
                std=np.abs(rng.normal(0, 0.05, n)),
                truth=est + rng.normal(0, 0.05, n),
            )
        )
        heights[n] = img.shape[0]
    assert heights[54] > 3 * heights[6]
    assert heights[54] / 54 > 15  # at least 15 px a name at 54 parameters
    _read(figures.parameter_bars_png(tmp_path / "plain.png", "no std", ["a", "b"], [1.0, -1.0]))
    with pytest.raises(ValueError, match="2 parameter names"):
        figures.parameter_bars_png(tmp_path / "bad.png", "t", ["a", "b"], np.ones(3))


def test_index_vs_count_png(tmp_path):
    counts = list(range(9, 41))
    series = {
        "D-optimal": list(np.geomspace(1e-3, 1e-1, len(counts))),
        "random": list(np.geomspace(1e-4, 3e-2, 20)),  # shorter: covers the first counts
    }
    img = _read(figures.index_vs_count_png(tmp_path / "idx.png", "O1", counts, series, "O1"))
    assert img.shape[1] > img.shape[0]
    _read(figures.index_vs_count_png(tmp_path / "lin.png", "t", counts, series, "O1", log_y=False))


def test_histogram_png(tmp_path):
    rng = np.random.default_rng(1)
    values = {"OLS": rng.normal(0, 1.0, 2000), "Liu": rng.normal(0.1, 0.5, 2000)}
    img = _read(figures.histogram_png(tmp_path / "h.png", "Monte Carlo", values, "dl (mm)"))
    assert img.shape[1] > img.shape[0]
    with pytest.raises(ValueError, match="no finite values"):
        figures.histogram_png(tmp_path / "e.png", "t", {"a": np.array([np.nan])}, "x")


def test_a_failing_write_keeps_the_existing_file(tmp_path, monkeypatch):
    path = tmp_path / "keep.png"
    figures.histogram_png(path, "first", {"a": np.arange(10.0)}, "x")
    before = path.read_bytes()

    def refuse(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(OSError, match="disk full"):
        figures.error_map_png(path, "second", _grid(), np.ones(49), "e (mm)")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]  # no temporary left


def _pixels(path: Path) -> np.ndarray:
    return mpimg.imread(path)


def test_save_pngs_frames_equal_full_draws(tmp_path):
    """Each frame drawn over the shared background is the picture a full draw (savefig) of
    the figure in that frame's state gives, pixel for pixel."""
    fig, axes = figures.plt.subplots(1, 2, figsize=(5, 2.5))
    images = [ax.imshow(np.zeros((4, 5)), vmin=0) for ax in axes]
    heading = fig.suptitle("")
    changed = [heading, *images, *(s for ax in axes for s in ax.spines.values())]
    changed += [ax.title for ax in axes]
    rng = np.random.default_rng(2)

    def frames():
        for k in range(3):
            for i, (ax, image) in enumerate(zip(axes, images, strict=True)):
                image.set_data(rng.random((4, 5)))
                image.set_clim(0, 1 + k)
                ax.set_title(f"panel {i}\nframe {k}", fontsize=7, y=1.0)
            heading.set_text(f"frame {k}")
            yield tmp_path / f"frame{k}.png", changed
            for artist in changed:  # a figure's draw leaves out animated artists, even saving
                artist.set_animated(False)
            fig.savefig(tmp_path / f"full{k}.png", dpi=figures.DPI)  # the frame's state, whole

    written = figures.save_pngs(fig, frames(), close=False)
    assert written == [tmp_path / f"frame{k}.png" for k in range(3)]
    assert not any(a.get_animated() for a in changed)  # a later savefig draws them again
    figures.plt.close(fig)
    for k in range(3):
        a, b = _pixels(tmp_path / f"frame{k}.png"), _pixels(tmp_path / f"full{k}.png")
        assert a.shape == b.shape
        np.testing.assert_array_equal(a, b)
    assert _pixels(tmp_path / "frame0.png").tolist() != _pixels(tmp_path / "frame1.png").tolist()


def test_parameter_bars_pngs_equal_one_chart_at_a_time(tmp_path):
    """Several charts of one figure (the names drawn once) are the charts drawn alone."""
    rng = np.random.default_rng(3)
    names = [f"limb{k // 9 + 1}.j{k % 9}.dx" for k in range(30)]
    charts = [
        figures.Bars(
            tmp_path / "a.png", "first", rng.normal(0, 1, 30), np.abs(rng.normal(0, 0.2, 30))
        ),
        figures.Bars(
            tmp_path / "b.png", "second, wider", rng.normal(0, 9, 30), None, rng.normal(0, 9, 30)
        ),
        figures.Bars(tmp_path / "c.png", "third", np.abs(rng.normal(0, 1, 30)), np.full(30, 0.1)),
    ]
    assert figures.parameter_bars_pngs(names, charts, "mm") == [c.path for c in charts]
    for c in charts:
        alone = tmp_path / f"alone_{c.path.name}"
        figures.parameter_bars_png(alone, c.title, names, c.estimates, c.std, c.truth, "mm")
        np.testing.assert_array_equal(_pixels(c.path), _pixels(alone))
    with pytest.raises(ValueError, match="30 parameter names"):
        figures.parameter_bars_pngs(names, [charts[0], charts[1]._replace(estimates=np.ones(3))])
    assert not (tmp_path / "x.png").exists()
    _no_leftovers(tmp_path)


def test_liu_vs_ols_error_maps_equal_full_draws(tmp_path, monkeypatch):
    """The error maps (axes drawn once for both quantities) are, pixel for pixel, what a whole
    savefig of each quantity's figure gives."""
    from types import SimpleNamespace

    import scenarios.studies.liu_vs_ols.figures as liu_vs_ols_figures

    rng = np.random.default_rng(4)
    xy = _grid(5, 0.2)  # metres, a 5 x 5 layer

    def layer(z: float) -> np.ndarray:
        return np.column_stack([xy, np.full(len(xy), z), np.zeros((len(xy), 3))])

    maps: dict = {"calibration": {}, "test": {}}
    for stage in ("uncalibrated", "coarse", "ols", "loop"):
        poses = np.vstack([layer(0.06), layer(-0.06)])
        errs = SimpleNamespace(position=rng.random(len(poses)), orientation=rng.random(len(poses)))
        maps["calibration"][stage] = (poses, errs)
        test_errs = SimpleNamespace(position=rng.random(len(xy)), orientation=rng.random(len(xy)))
        maps["test"][stage] = (layer(0.0), test_errs)
    (tmp_path / "shared").mkdir()
    (tmp_path / "full").mkdir()
    written = liu_vs_ols_figures.write_figures(tmp_path / "shared", maps)

    def full_draws(fig, frames):
        try:
            for path, _changed in frames:
                fig.savefig(path, dpi=figures.DPI)
        finally:
            figures.plt.close(fig)

    monkeypatch.setattr(liu_vs_ols_figures, "save_pngs", full_draws)
    assert liu_vs_ols_figures.write_figures(tmp_path / "full", maps) == written
    for name in written.values():
        a, b = _pixels(tmp_path / "shared" / name), _pixels(tmp_path / "full" / name)
        assert a.shape == b.shape and a.shape[1] > a.shape[0]  # 4 stages by 3 layers
        np.testing.assert_array_equal(a, b)


def test_collection_paused_restores_the_collector_state():
    import gc

    assert gc.isenabled()
    with pytest.raises(RuntimeError), figures.collection_paused():
        assert not gc.isenabled()
        raise RuntimeError("a failing figure")
    assert gc.isenabled()
    gc.disable()
    try:
        with figures.collection_paused():
            pass
        assert not gc.isenabled()  # paused by someone else before: left so
    finally:
        gc.enable()
