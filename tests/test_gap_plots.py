"""The gap workflow's figures: a log without a pose draws them without warnings."""
from __future__ import annotations

import types
import warnings

import matplotlib.image

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
