"""The standard error of each kept parameter (simrunner.workflows.gap.uncertainty)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from simrunner.car.effects import neutral_car
from simrunner.workflows.gap.fit import Problem, Segment
from simrunner.workflows.gap.replay import default_sim_factory
from simrunner.workflows.gap.report import run_gap, summary_text
from simrunner.workflows.gap.synth import NOISE_POS_M, NOISE_SPEED_MPS, NOISE_YAW_RAD, make_measured_log
from simrunner.workflows.gap.uncertainty import parameter_sigma

OFFSET_RAD = -0.03


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
