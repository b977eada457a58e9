"""The gap workflow's figures: a log without a pose draws them without warnings."""
from __future__ import annotations

import types
import warnings

import matplotlib.image

from helpers import legends_off_the_panels
from simrunner.workflows.gap.plots import plot_regimes


def _stats(signals, scale):
    return [{"signal": s, "regime": g, "count": 40, "rmse": scale * (1 + k), "bias": 0.1 * scale}
            for s in signals for k, g in enumerate(("all", "braking", "coasting"))]


def test_regime_figure_of_a_speed_and_gyro_log_has_its_legend_on_a_panel_with_data(tmp_path):
    signals = ("speed_mps", "yaw_rate_radps")  # what an encoder + gyro log compares
    result = types.SimpleNamespace(stats_before=_stats(signals, 0.4), stats_after=_stats(signals, 0.2),
                                   effect="steering_lag")
    out = tmp_path / "regimes.png"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib warned "No artists with labels" here
        plot_regimes(result, out)
    assert matplotlib.image.imread(out).shape[0] > 100


def test_titles_break_between_items_within_the_width():
    """Issue 50 (cosmetic): the held-out RMSE subtitle of gap_before_after.png ran past the
    figure's edge ("... yaw rate 0.18->" cut); it is broken between items now."""
    from simrunner.workflows.gap.plots import _lines

    items = ["position 0.137 -> 0.00909", "speed 0.161 -> 0.0197", "yaw rate 0.18 -> 0.0315"]
    text = _lines(items, 70)
    assert text == "position 0.137 -> 0.00909, speed 0.161 -> 0.0197,\nyaw rate 0.18 -> 0.0315"
    assert text.replace(",\n", ", ") == ", ".join(items)
    assert _lines(items[:1], 10) == items[0]  # an item longer than the width is kept whole


def _figure_of(monkeypatch, plot, result, path):
    """The figure ``plot`` draws (kept from its ``plt.close``)."""
    from simrunner.workflows.gap import plots

    drawn = []
    monkeypatch.setattr(plots.plt, "close", drawn.append)
    plot(result, path)
    fig, = drawn
    fig.canvas.draw()
    return fig


def test_regime_figure_legend_hides_no_bar(tmp_path, monkeypatch):
    """Issue 50 (cosmetic): the legend sat in the first panel, over its tallest bars."""
    signals = ("position_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps", "along_m")
    result = types.SimpleNamespace(stats_before=_stats(signals, 0.4), stats_after=_stats(signals, 0.2),
                                   effect="steering_lag")
    legends_off_the_panels(_figure_of(monkeypatch, plot_regimes, result, tmp_path / "regimes.png"))


def test_before_after_figure_legends_hide_no_curve(tmp_path, monkeypatch):
    """Issue 50 (cosmetic): the speed and position-error legends sat upper right, over the
    fastest part of the run (a real log's speed peak, the largest errors)."""
    import numpy as np

    from simrunner.workflows.gap.plots import plot_before_after

    class Log(types.SimpleNamespace):
        def __len__(self):
            return len(self.t_s)

    t = np.linspace(0.0, 20.0, 401)
    log = Log(t_s=t, x_m=np.cos(t), y_m=np.sin(t), yaw_rad=t + np.pi / 2, speed_mps=t / 4,
              yaw_rate_radps=np.ones_like(t), source="run.csv")
    pred = types.SimpleNamespace(x_m=np.cos(t) + 0.01 * t, y_m=np.sin(t), speed_mps=t / 4 + 0.1,
                                 yaw_rate_radps=np.ones_like(t) * 1.1)
    rmse = {"position_m": 0.2, "speed_mps": 0.1, "yaw_rate_radps": 0.1}
    result = types.SimpleNamespace(log=log, derived=log, pred_before=pred, pred_after=pred,
                                   held_windows=[types.SimpleNamespace(start=100, stop=140)],
                                   rmse_before=rmse, rmse_after=rmse, effect="steering_lag",
                                   parameters={"steering_lag_s": 0.1})
    legends_off_the_panels(_figure_of(monkeypatch, plot_before_after, result, tmp_path / "before_after.png"))
