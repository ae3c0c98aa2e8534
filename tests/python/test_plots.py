"""evstwin.plots: every figure is written, non-empty, of the asked pixel size, with labelled axes."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_hex, to_rgb
from matplotlib.figure import Figure
from matplotlib.image import imread

from evstwin import plots, validation
from evstwin.sensor import EVENT_DTYPE

W, H = 64, 48


def random_events(seed, n, duration_us=300_000):
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, dtype=EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, duration_us, n))
    ev["x"] = rng.integers(0, W, n)
    ev["y"] = rng.integers(0, H, n)
    ev["p"] = rng.integers(0, 2, n)
    return ev


REAL = random_events(1, 4000)
SIM = random_events(2, 6000)
RECS = [("real", REAL), ("sim", SIM)]
META = {"width": W, "height": H, "duration_s": 0.3}
COMP = validation.compare(REAL, dict(META, path="real"), [(SIM, dict(META, path="sim"))])


def check_labels(fig: Figure, zlabel: bool = False) -> None:
    axes = [ax for ax in fig.axes if ax.get_visible() and ax.get_label() != "<colorbar>"]
    main = [ax for ax in axes if ax.get_title()]
    assert main, "no titled axes"
    for ax in main:
        assert ax.get_xlabel(), f"x label missing on {ax.get_title()!r}"
        assert ax.get_ylabel() or ax.get_subplotspec().colspan.start > 0, (
            f"y label missing on {ax.get_title()!r}"
        )
        if zlabel:
            assert ax.get_zlabel()  # type: ignore[attr-defined]
    assert fig.get_suptitle()


def check_png(path, fig_size_in, dpi=plots.DPI):
    assert path.exists() and path.stat().st_size > 1000
    img = imread(path)
    w_in, h_in = fig_size_in
    assert img.shape[:2] == (round(h_in * dpi), round(w_in * dpi))
    assert img[..., :3].std() > 0.01  # not a blank image


def test_frames(tmp_path):
    fig = plots.fig_frames(RECS, W, H, window_s=0.05, n_windows=3, figsize=(8.0, 4.0))
    check_labels(fig)
    assert "ON" in fig.axes[0].get_title() and "ms frames overlaid" in fig.get_suptitle()
    p = plots.plot_frames(RECS, W, H, tmp_path / "frames.png", window_s=0.05, figsize=(8.0, 4.0))
    check_png(p, (8.0, 4.0))


def test_frame_colours_are_fixed():
    rgb = plots.frame_rgb(np.array([[2, 0, 0]]), np.array([[0, 2, 0]]))
    np.testing.assert_allclose(rgb[0, 0], to_rgb(plots.ON_COLOUR))
    np.testing.assert_allclose(rgb[0, 1], to_rgb(plots.OFF_COLOUR))
    np.testing.assert_allclose(rgb[0, 2], [1, 1, 1])


def test_xyt_scatter_and_cap(tmp_path):
    fig = plots.fig_xyt(RECS, W, H, duration_s=0.2, max_points=500, figsize=(9.0, 4.5))
    check_labels(fig, zlabel=True)
    assert "500 of" in fig.axes[1].get_title()
    drawn = sum(len(c.get_offsets()) for c in fig.axes[1].collections)
    assert drawn == 500
    p = plots.plot_xyt(RECS, W, H, tmp_path / "xyt.png", duration_s=0.2, figsize=(9.0, 4.5), dpi=80)
    check_png(p, (9.0, 4.5), dpi=80)


def test_subsample():
    assert plots.subsample(REAL, 10_000).size == REAL.size
    sub = plots.subsample(REAL, 100)
    assert sub.size == 100 and sub["t"][0] == REAL["t"][0] and sub["t"][-1] == REAL["t"][-1]


def test_histograms(tmp_path):
    hists = [("real", COMP.real_hist), ("sim", COMP.sims[0].hist)]
    fig = plots.fig_count_histograms(COMP.edges, hists, figsize=(8.0, 7.0))
    check_labels(fig)
    assert fig.axes[0].get_ylabel() == "fraction of pixels"
    assert "events per pixel" in fig.axes[0].get_xlabel()
    # row colours: all, ON, OFF
    colours = [to_hex(fig.axes[i].patches[0].get_facecolor()[:3]) for i in (0, 2, 4)]
    assert colours == [plots.TOTAL_COLOUR.lower(), plots.ON_COLOUR.lower(), plots.OFF_COLOUR.lower()]
    p = plots.plot_comparison_histograms(COMP, tmp_path / "hist.png", figsize=(8.0, 7.0))
    check_png(p, (8.0, 7.0))


def test_percent_error(tmp_path):
    sims = [(s.label, s.percent_error) for s in COMP.sims]
    fig = plots.fig_percent_error(COMP.edges, sims, figsize=(6.0, 4.0))
    check_labels(fig)
    ax = fig.axes[0]
    assert "percent error" in ax.get_ylabel() and "[%]" in ax.get_ylabel()
    assert [to_hex(line.get_color()) for line in ax.get_lines()[:3]] == [
        plots.TOTAL_COLOUR.lower(),
        plots.ON_COLOUR.lower(),
        plots.OFF_COLOUR.lower(),
    ]
    p = plots.plot_comparison_percent_error(COMP, tmp_path / "pct.png", figsize=(6.0, 4.0))
    check_png(p, (6.0, 4.0))


def test_percent_error_switches_to_symlog_for_huge_errors():
    edges = {k: np.arange(0, 8, 2.0) for k in ("total", "on", "off")}
    small = {k: np.array([5.0, -3.0, 10.0]) for k in edges}
    huge = {k: np.array([5.0, -3.0, 1e5]) for k in edges}
    assert plots.fig_percent_error(edges, [("a", small)]).axes[0].get_yscale() == "linear"
    assert plots.fig_percent_error(edges, [("a", huge)]).axes[0].get_yscale() == "symlog"


def test_bin_error_has_pixel_share_axis(tmp_path):
    sims = [(s.label, s.error_pixels) for s in COMP.sims]
    fig = plots.fig_bin_error(COMP.edges, sims, COMP.pixel_count, figsize=(6.0, 4.0))
    check_labels(fig)
    ax = fig.axes[0]
    assert ax.get_ylabel() == "bin error [pixels]"
    secondary = [c for c in ax.child_axes]
    assert len(secondary) == 1 and "share of compared pixels [%]" in secondary[0].get_ylabel()
    p = plots.plot_comparison_bin_error(COMP, tmp_path / "err.png", figsize=(6.0, 4.0))
    check_png(p, (6.0, 4.0))


def test_event_rate(tmp_path):
    fig = plots.fig_event_rate(RECS, bin_s=0.01, figsize=(7.0, 5.0))
    ax = fig.axes[0]
    assert ax.get_ylabel() == "event rate [events/s]"
    assert fig.axes[-1].get_xlabel() == "time since first event [s]"
    assert [to_hex(line.get_color()) for line in ax.get_lines()[:2]] == [
        plots.ON_COLOUR.lower(),
        plots.OFF_COLOUR.lower(),
    ]
    p = plots.plot_event_rate(RECS, tmp_path / "rate.png", bin_s=0.01, figsize=(7.0, 5.0))
    check_png(p, (7.0, 5.0))


def test_monte_carlo_figures(tmp_path):
    comps = [
        validation.compare(
            REAL, dict(META, path="real"), [(random_events(10 + i, 6000), dict(META, path="sim"))]
        )
        for i in range(3)
    ]
    out = plots.plot_monte_carlo(validation.aggregate(comps), tmp_path)
    for p in out.values():
        assert p.exists() and imread(p).shape[:2] == (round(4.2 * plots.DPI), round(5.8 * plots.DPI))


def test_timing_bias_figure(tmp_path):
    rng = np.random.default_rng(7)
    n = 400
    track = {
        "t_s": np.array([0.0, 1.0]),
        "x_px": np.array([0.0, 1.0]),
        "y_px": np.array([0.0, 0.0]),
        "flux_ph_s": np.array([1.0, 1.0]),
    }
    tab = np.zeros(n, dtype=validation.timing_bias(REAL[:0], {"star": track}).dtype)
    tab["p"] = rng.integers(0, 2, n)
    tab["flux_ph_s"] = 10 ** rng.uniform(3, 6, n)
    tab["speed_px_s"] = rng.uniform(5, 200, n)
    tab["delay_s"] = 1e-3 / np.sqrt(tab["flux_ph_s"] / 1e3) + rng.normal(0, 1e-4, n)
    fig = plots.fig_timing_bias(tab, figsize=(10.0, 4.0))
    check_labels(fig)
    assert fig.axes[0].get_xscale() == "log"
    assert fig.axes[0].get_xlabel() == "source flux [photons/s]"
    assert fig.axes[1].get_xlabel() == "source speed [px/s]"
    p = plots.plot_timing_bias(tab, tmp_path / "tb.png", figsize=(10.0, 4.0))
    check_png(p, (10.0, 4.0))


@pytest.mark.parametrize("dpi", [72, 150])
def test_dpi_sets_pixel_size(tmp_path, dpi):
    p = plots.plot_event_rate(RECS[:1], tmp_path / "r.png", dpi=dpi, bin_s=0.02, figsize=(4.0, 3.0))
    assert imread(p).shape[:2] == (3 * dpi, 4 * dpi)


def test_percent_error_gaps_for_bins_empty_in_both():
    v = plots.comparison._mask_empty([0.0, 50.0, 0.0, -100.0], [0.0, 0.2, 0.0, 0.1], [0.0, 0.3, 0.1, 0.0])
    np.testing.assert_array_equal(np.isnan(v), [True, False, False, False])


def test_one_panel_titles_stay_inside_the_figure():
    # A Monte Carlo figure has one panel and the longest title: it used to run off both edges.
    sims = [(s.label, s.percent_error) for s in COMP.sims]
    fig = plots.fig_percent_error(COMP.edges, sims, std=[s.percent_error for s in COMP.sims])
    fig.canvas.draw()
    box = fig._suptitle.get_window_extent()
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width


def test_event_rate_rows_share_the_rate_scale_and_the_first_recordings_time():
    long_sim = random_events(3, 6000, duration_us=3_000_000)  # ten times the real one
    fig = plots.fig_event_rate([("real", REAL), ("sim", long_sim)], bin_s=0.01)
    top, bottom = fig.axes[0], fig.axes[1]
    assert top.get_ylim() == bottom.get_ylim()
    span_s = (int(REAL["t"][-1]) - int(REAL["t"][0]) + 1) * 1e-6
    assert bottom.get_xlim()[1] == pytest.approx(span_s)


def test_timing_figure_has_one_legend_and_medians_per_polarity():
    truth_t = np.linspace(0.0, 0.3, 50)
    table = np.zeros(200, dtype=[("delay_s", "f8"), ("p", "u1"), ("flux_ph_s", "f8"), ("speed_px_s", "f8")])
    table["p"] = np.arange(200) % 2
    table["delay_s"] = np.where(table["p"] == 1, 0.005, 0.1)
    table["flux_ph_s"] = 1e9  # one brightness: a plain axis, no 1e-12+1e9 offset
    table["speed_px_s"] = np.repeat(truth_t[:4] * 1000 + 100, 50)
    fig = plots.fig_timing_bias(table)
    assert all(ax.get_legend() is None for ax in fig.axes) and len(fig.legends) == 1
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "ON median, 25-75 %" in labels and "OFF median, 25-75 %" in labels
    fig.canvas.draw()
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == ["1e+09"]
    assert fig.axes[0].xaxis.get_offset_text().get_text() == ""


def test_timing_speeds_that_agree_to_the_tolerance_are_one_value():
    # geo-stare's GEO target: its speed in pixels changes in the last digits along the track
    # (7.882807..7.883281 px/s); the axis showed a tick per digit ("7.882807.3832808...") and
    # the summary a row per value.
    rng = np.random.default_rng(3)
    n = 300
    track = {"t_s": np.array([0.0, 1.0]), "x_px": np.array([0.0, 1.0]), "y_px": np.array([0.0, 0.0]),
             "flux_ph_s": np.array([1.0, 1.0])}
    tab = np.zeros(n, dtype=validation.timing_bias(REAL[:0], {"star": track}).dtype)
    tab["p"] = rng.integers(0, 2, n)
    tab["flux_ph_s"] = 1e5
    tab["speed_px_s"] = 7.882807 + rng.uniform(0.0, 0.000474, n)  # 60 ppm apart: one value at 0.1 %
    tab["delay_s"] = rng.uniform(0.0, 0.02, n)
    fig = plots.fig_timing_bias(tab)
    fig.canvas.draw()
    speed = fig.axes[1]
    labels = [t.get_text() for t in speed.get_xticklabels() if t.get_text()]
    assert labels == ["7.883"] and "one value" in speed.get_xlabel()
    rows = validation.timing_bias_summary(tab, by="speed")
    assert len(rows) == 1 and rows[0]["group"] == pytest.approx(7.883, abs=5e-4) and rows[0]["n"] == n
    # Values 1 % apart stay apart.
    tab["speed_px_s"][: n // 2] *= 1.01
    assert len(validation.timing_bias_summary(tab, by="speed")) == 2
