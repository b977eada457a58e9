"""The standard error of each kept parameter (simrunner.workflows.gap.uncertainty)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from simrunner.car.effects import neutral_car
from simrunner.workflows.gap.fit import Problem, Segment
from simrunner.workflows.gap.replay import default_sim_factory
from simrunner.workflows.gap.report import summary_text
from simrunner.workflows.gap.workflow import run_gap
from simrunner.workflows.gap.synth import NOISE_POS_M, NOISE_SPEED_MPS, NOISE_YAW_RAD, make_measured_log
from simrunner.workflows.gap.uncertainty import parameter_sigma
from vehicle.description import CarDescription

OFFSET_RAD = -0.03
# a problem for the stand-in window costs below (which ignore it): at any physics step the same
_NO_WINDOWS = Problem(CarDescription(), (), {})


@pytest.fixture(scope="module")
def exact_log():
    """20 s of the plan with a steering offset, exact states (noise added by the tests), and
    the car that drove it without the offset (its mass and grip nuisance included, so the
    offset and the noise are all that the model misses)."""
    log, truth = make_measured_log("steering_offset", rng=np.random.default_rng(11), value=OFFSET_RAD,
                                   start_s=0.0, duration_s=20.0, noise=False)
    return log, neutral_car(truth.car)


def _noisy(log, factor: float, seed: int = 3):
    """``log`` with the synthetic logs' sensor noise times ``factor``."""
    rng = np.random.default_rng(seed)
    n = len(log)
    return log.with_columns(x_m=log.x_m + rng.normal(0.0, factor * NOISE_POS_M, n),
                            y_m=log.y_m + rng.normal(0.0, factor * NOISE_POS_M, n),
                            yaw_rad=log.yaw_rad + rng.normal(0.0, factor * NOISE_YAW_RAD, n),
                            speed_mps=log.speed_mps + rng.normal(0.0, factor * NOISE_SPEED_MPS, n))


@pytest.fixture(scope="module")
def runs(exact_log):
    log, car = exact_log
    return {f: run_gap(_noisy(log, f), car, jobs=1, effects=["steering_offset"]) for f in (1.0, 4.0)}


def test_a_kept_parameter_has_a_standard_error_that_covers_the_truth(runs):
    r = runs[1.0]
    assert r.effects == ["steering_offset"]
    sigma = r.parameter_sigma["steering_offset_rad"]
    assert 0.0 < sigma < 0.1 * abs(OFFSET_RAD)
    assert abs(r.parameters["steering_offset_rad"] - OFFSET_RAD) <= 3.0 * sigma
    assert f"steering_offset_rad = {r.parameters['steering_offset_rad']:.4g} +- {sigma:.2g}" in summary_text(r)
    assert r.to_json()["parameter_sigma"] == {"steering_offset_rad": sigma}


def test_noisier_sensors_give_a_larger_standard_error(runs):
    """Four times the noise, the model otherwise exact: 1.7 times the standard error (measured;
    the windows also differ by what no noise causes: each restarts from states smoothed out of
    the log, which a noise-free log gives too)."""
    quiet, noisy = (runs[f].parameter_sigma["steering_offset_rad"] for f in (1.0, 4.0))
    assert 1.4 * quiet < noisy < 4.0 * quiet


def _fit_problem(result, car) -> Problem:
    """The fit windows' problem of ``result`` (as ``run_gap`` builds it)."""
    s = result.settings
    segs = tuple(Segment(p.log, p.derived, p.fit_windows) for p in result.parts if p.fit_windows)
    problem = Problem(car, segs, s["scales"], tuple(s["signals"]), s["dt_s"], default_sim_factory)
    return dataclasses.replace(problem, robust_scale=s["robust_scale"])


def test_the_standard_error_is_that_of_the_fit_windows_and_nan_where_nothing_pins_it(exact_log, runs):
    _, car = exact_log
    r = runs[1.0]
    problem = _fit_problem(r, car)  # 20 s: the screening windows are all the fit windows
    again = parameter_sigma(problem, car, ["steering_offset"], r.parameters)
    assert again == r.parameter_sigma
    # this part of the plan never commands reverse while rolling forward: the ESC's delay changes nothing
    flat = parameter_sigma(problem, car, ["esc_brake_reverse"], {"esc_reverse_delay_s": 0.3})
    assert math.isnan(flat["esc_reverse_delay_s"])
    assert parameter_sigma(problem, car, [], {}) == {}


def test_a_value_away_from_the_minimum_widens_the_standard_error_by_its_distance(exact_log, runs):
    """Reported 3 mrad (about four of its standard errors) off the fitted minimum, the offset's
    standard error grows to about that distance: the Newton step back to the minimum is in it."""
    _, car = exact_log
    r = runs[1.0]
    problem = _fit_problem(r, car)
    fitted, sigma = r.parameters["steering_offset_rad"], r.parameter_sigma["steering_offset_rad"]
    off = parameter_sigma(problem, car, ["steering_offset"], {"steering_offset_rad": fitted + 0.003})
    assert 0.7 * 0.003 < off["steering_offset_rad"] < 1.5 * 0.003 + sigma, (sigma, off)


def test_a_parameter_nothing_pins_leaves_the_others_their_standard_error(exact_log, runs):
    """The offset beside the ESC delay (which this part of the plan never exercises): the delay
    gets nan, the offset the standard error it has alone."""
    _, car = exact_log
    r = runs[1.0]
    both = parameter_sigma(_fit_problem(r, car), car, ["steering_offset", "esc_brake_reverse"],
                           {**r.parameters, "esc_reverse_delay_s": 0.3})
    assert math.isnan(both["esc_reverse_delay_s"])
    assert both["steering_offset_rad"] == pytest.approx(r.parameter_sigma["steering_offset_rad"], rel=1e-6)



def test_a_parameter_at_an_end_of_its_fit_range_gets_no_standard_error_and_the_others_keep_theirs(monkeypatch):
    """Window costs that are exact quadratics (so the Hessian is known): the offset's minimum
    inside its range, the gain's beyond the top of its range, where the fit stopped (1.5). The
    bound, not the cost's curvature, made the gain's value (the report warns of it), so it
    gets nan; the offset gets the sandwich of its own curvature and spread, the gain held
    (DS3's pose-only rolling resistance at its bound once took every other sigma with it)."""
    from simrunner.workflows.gap import uncertainty
    from simrunner.workflows.gap.fit import CANDIDATES

    rng = np.random.default_rng(5)
    spread_a, spread_b = rng.normal(0.0, 0.01, 40), rng.normal(0.0, 0.01, 40)
    spread_a -= spread_a.mean()  # the offset fitted at its minimum: no Newton step in its error
    off, gain = CANDIDATES["steering_offset"], CANDIDATES["steering_gain"]

    def window_values(problem, car):
        ua, ub = off.u(car.effects.steering_offset_rad), gain.u(car.effects.steering_gain)
        # the gain's coordinate unclipped (its minimum lies outside the range, at u = 1.2)
        ub = (car.effects.steering_gain - gain.lo) / (gain.hi - gain.lo) if ub >= 1.0 else ub
        return 100.0 * (ua - 0.5 - spread_a) ** 2 + 100.0 * (ub - 1.2 - spread_b) ** 2

    monkeypatch.setattr(uncertainty, "window_values", window_values)
    values = {"steering_offset_rad": 0.0, "steering_gain": 1.5}
    sigma = parameter_sigma(_NO_WINDOWS, CarDescription(), ["steering_offset", "steering_gain"], values)
    assert math.isnan(sigma["steering_gain"])
    # the offset alone: H = 2 * 100 * 40 in u, B = n/(n-1) * sum (200 spread_a)^2 centred
    g = 200.0 * spread_a
    expected_u = math.sqrt(g @ g * 40 / 39) / (200.0 * 40)
    assert sigma["steering_offset_rad"] == pytest.approx(expected_u * (off.hi - off.lo), rel=0.05)
    inside = parameter_sigma(_NO_WINDOWS, CarDescription(), ["steering_offset", "steering_gain"],
                             {**values, "steering_gain": 1.4})
    assert math.isfinite(inside["steering_gain"]) and inside["steering_gain"] > 0.0


def _quadratic_windows(monkeypatch, curvature_a, centre_a, curvature_b, centre_b):
    """Window costs ``curvature_a[w] (u_offset - centre_a[w])^2 + curvature_b[w] (u_gain -
    centre_b[w])^2`` (exact quadratics: the Hessians are known) in place of the replays."""
    from simrunner.workflows.gap import uncertainty
    from simrunner.workflows.gap.fit import CANDIDATES

    off, gain = CANDIDATES["steering_offset"], CANDIDATES["steering_gain"]
    assert not (off.log_scale or gain.log_scale)  # u linear in the value: the expected sigmas below

    def window_values(problem, car):
        ua, ub = off.u(car.effects.steering_offset_rad), gain.u(car.effects.steering_gain)
        return curvature_a * (ua - centre_a) ** 2 + curvature_b * (ub - centre_b) ** 2

    monkeypatch.setattr(uncertainty, "window_values", window_values)
    return off, gain


def test_a_parameter_few_windows_pin_gets_the_spread_of_the_fits_that_leave_one_out(monkeypatch):
    """The gain curves in two of 20 windows only, whose minima lie +-0.02 (in u) either side
    of the fit: leaving either out moves the fit by the whole 0.02, so the jackknife's
    variance is 19/20 * 2 * 0.02^2, against the sandwich's 20/19 * 0.02^2 / 2 (which
    estimates the scores' spread from the two gradients as if every window had a share of the
    curvature: 1.9 times too narrow here; measured 7-15 times on the bench's ESC and steering
    limit). The offset, spread over all windows with no leverage, keeps the sandwich's."""
    from simrunner.workflows.gap.uncertainty import parameter_uncertainty

    n = 20
    rng = np.random.default_rng(2)
    spread = rng.normal(0.0, 0.01, n)
    spread -= spread.mean()
    curv_b = np.zeros(n)
    curv_b[[3, 11]] = 50.0
    centre_b = np.full(n, 0.5)
    centre_b[3], centre_b[11] = 0.52, 0.48
    off, gain = _quadratic_windows(monkeypatch, np.full(n, 100.0), 0.5 + spread, curv_b, centre_b)
    values = {"steering_offset_rad": 0.5 * (off.lo + off.hi), "steering_gain": 0.5 * (gain.lo + gain.hi)}
    got = parameter_uncertainty(_NO_WINDOWS, CarDescription(), ["steering_offset", "steering_gain"], values)
    assert got.one_window == {}
    assert got.sigma["steering_gain"] == pytest.approx(math.sqrt(19 / 20 * 2 * 0.02 ** 2) * (gain.hi - gain.lo),
                                                       rel=1e-6)
    g = 200.0 * spread  # the offset: the sandwich of its own curvature and spread (no leverage)
    assert got.sigma["steering_offset_rad"] == pytest.approx(
        math.sqrt(g @ g * n / (n - 1)) / (200.0 * n) * (off.hi - off.lo), rel=1e-6)


def test_a_parameter_one_window_alone_pins_gets_no_standard_error_and_names_the_window(monkeypatch):
    """The gain curves in window 7 alone: without it the log would not pin the gain, so the
    spread between windows cannot say how well it is pinned: nan, and the window is named;
    the offset keeps its standard error (the gain held)."""
    from simrunner.workflows.gap.uncertainty import parameter_uncertainty

    n = 12
    spread = np.linspace(-0.01, 0.01, n)
    curv_b = np.zeros(n)
    curv_b[7] = 80.0
    off, gain = _quadratic_windows(monkeypatch, np.full(n, 100.0), 0.5 + spread, curv_b, np.full(n, 0.5))
    values = {"steering_offset_rad": 0.5 * (off.lo + off.hi), "steering_gain": 0.5 * (gain.lo + gain.hi)}
    got = parameter_uncertainty(_NO_WINDOWS, CarDescription(), ["steering_offset", "steering_gain"], values)
    assert got.one_window == {"steering_gain": 7}
    assert math.isnan(got.sigma["steering_gain"])
    g = 200.0 * spread
    assert got.sigma["steering_offset_rad"] == pytest.approx(
        math.sqrt(g @ g * n / (n - 1)) / (200.0 * n) * (off.hi - off.lo), rel=1e-6)


def test_the_physics_steps_bias_is_added_from_the_minimum_at_half_the_step(monkeypatch):
    """Window costs whose minima move with the physics step, ``u* = 0.5 + slope * dt`` (an
    error of first order in the step, as a steering lag's at 5 ms): fitted at the 5-ms minimum,
    the gradient at 2.5 ms says the minimum moves by ``-slope * 2.5 ms``, so the value at step
    zero lies ``slope * 5 ms`` away, and that distance is added in quadrature to the spread."""
    from simrunner.workflows.gap import uncertainty
    from simrunner.workflows.gap.fit import CANDIDATES
    from simrunner.workflows.gap.uncertainty import parameter_uncertainty

    lag = CANDIDATES["steering_lag"]
    n, slope, dt_s = 16, 4.0, 0.005
    spread = np.linspace(-0.01, 0.01, n)

    def window_values(problem, car):
        return 100.0 * (lag.u(car.effects.steering_lag_s) - 0.5 - slope * problem.dt_s - spread) ** 2

    monkeypatch.setattr(uncertainty, "window_values", window_values)
    problem = Problem(CarDescription(), (), {}, dt_s=dt_s)
    value = {"steering_lag_s": lag.lo + (0.5 + slope * dt_s) * (lag.hi - lag.lo)}
    got = parameter_uncertainty(problem, CarDescription(), ["steering_lag"], value).sigma["steering_lag_s"]
    g = 200.0 * spread
    jackknife_u = math.sqrt(g @ g * n / (n - 1)) / (200.0 * n)
    assert got == pytest.approx(math.hypot(jackknife_u, slope * dt_s) * (lag.hi - lag.lo), rel=1e-6)
    # a replay that fails at half the step (nan) leaves that term out, not the standard error
    monkeypatch.setattr(uncertainty, "window_values", lambda problem, car: window_values(problem, car)
                        if problem.dt_s == dt_s else np.full(n, np.nan))
    failed = parameter_uncertainty(problem, CarDescription(), ["steering_lag"], value).sigma["steering_lag_s"]
    assert failed == pytest.approx(jackknife_u * (lag.hi - lag.lo), rel=1e-6)
    # no dependence on the step: the spread alone
    monkeypatch.setattr(uncertainty, "window_values",
                        lambda problem, car: 100.0 * (lag.u(car.effects.steering_lag_s) - 0.5 - spread) ** 2)
    flat = parameter_uncertainty(problem, CarDescription(), ["steering_lag"],
                                 {"steering_lag_s": 0.5 * (lag.lo + lag.hi)}).sigma["steering_lag_s"]
    assert flat == pytest.approx(jackknife_u * (lag.hi - lag.lo), rel=1e-6)


@pytest.mark.parametrize("dt_s, substep_s", [(0.005, 0.005), (0.001, 0.004), (0.002, 0.004)])
def test_a_latency_is_known_no_better_than_to_its_control_sub_step(monkeypatch, dt_s, substep_s):
    """The command latency acts at whole control sub-steps (4 ms rounded to whole physics
    steps): values within one give the same replay, so a uniform variance of ``sub-step^2 / 12``
    is added to what the windows say; the steering lag (continuous) gets none."""
    from simrunner.car.effects import control_steps
    from simrunner.workflows.gap import uncertainty
    from simrunner.workflows.gap.fit import CANDIDATES
    from simrunner.workflows.gap.uncertainty import parameter_uncertainty

    assert control_steps(dt_s) * dt_s == pytest.approx(substep_s)
    lat, lag = CANDIDATES["command_latency"], CANDIDATES["steering_lag"]
    n = 10
    spread = np.linspace(-0.02, 0.02, n)

    def window_values(problem, car):
        return sum(100.0 * (c.u(getattr(car.effects, c.field)) - 0.5 - spread) ** 2 for c in (lat, lag))

    monkeypatch.setattr(uncertainty, "window_values", window_values)
    values = {"command_latency_s": 0.5 * (lat.lo + lat.hi), "steering_lag_s": 0.5 * (lag.lo + lag.hi)}
    got = parameter_uncertainty(Problem(CarDescription(), (), {}, dt_s=dt_s), CarDescription(),
                                ["command_latency", "steering_lag"], values).sigma
    g = 200.0 * spread
    jackknife_u = math.sqrt(g @ g * n / (n - 1)) / (200.0 * n)
    assert got["steering_lag_s"] == pytest.approx(jackknife_u * (lag.hi - lag.lo), rel=1e-6)
    assert got["command_latency_s"] ** 2 == pytest.approx((jackknife_u * (lat.hi - lat.lo)) ** 2 + substep_s ** 2 / 12,
                                                          rel=1e-6)
