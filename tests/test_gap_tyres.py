"""The slip tyres' numbers in the gap catalogue (issue 51 item 3): offered for a car on slip
tyres only, and named when a log hides them."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simrunner.car.effects import EFFECTS, built_car, with_effects
from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.report import summary_text
from simrunner.workflows.gap.synth import make_measured_log
from simrunner.workflows.gap.workflow import not_applicable_to, run_gap
from vehicle.description import CarDescription

RIGID = CarDescription()
SLIP = RIGID.replace(wheels=dataclasses.replace(RIGID.wheels, tyre_model="slip"))
DUTY = RIGID.replace(drive=dataclasses.replace(RIGID.drive, command="duty"))
TYRES = ["tyre_stiffness", "tyre_balance", "tyre_relaxation"]


def test_the_tyre_effects_scale_the_slip_tyres_numbers():
    w = built_car(with_effects(SLIP, tyre_stiffness_scale=2.0, tyre_balance=0.25, tyre_relaxation_scale=3.0)).wheels
    assert w.cornering_stiffness_front_per_rad == pytest.approx(SLIP.wheels.cornering_stiffness_front_per_rad * 2.5)
    assert w.cornering_stiffness_rear_per_rad == pytest.approx(SLIP.wheels.cornering_stiffness_rear_per_rad * 1.5)
    assert w.relaxation_length_m == pytest.approx(SLIP.wheels.relaxation_length_m * 3.0)
    assert built_car(SLIP) is SLIP  # neutral: the car file's own numbers


def test_effects_the_car_cannot_have_are_not_tried():
    assert list(not_applicable_to(list(EFFECTS), RIGID)) == TYRES
    assert not_applicable_to(list(EFFECTS), SLIP) == {}
    assert list(not_applicable_to(list(EFFECTS), DUTY)) == ["front_drive"] + TYRES
    assert all(EFFECTS[e].requirement.startswith('wheels.tyre_model = "slip"') for e in TYRES)


@pytest.fixture(scope="module")
def soft_tyres():
    log, truth = make_measured_log("tyre_stiffness", rng=np.random.default_rng(5), value=0.55, car=SLIP,
                                   start_s=20.0, duration_s=16.0)
    return log, truth


def test_a_rigid_car_file_says_what_it_did_not_try_and_refuses_to_be_asked(soft_tyres):
    log, _ = soft_tyres
    with pytest.raises(GapError, match=r"^tyre_stiffness acts only on a car with wheels.tyre_model = \"slip\" "
                                       r"\(docs/tyres.md\): expected other effects or a car file on slip tyres"):
        run_gap(log, RIGID, jobs=1, effects=["tyre_stiffness"])
    result = run_gap(log, RIGID, jobs=1, effects=["steering_gain"], max_effects=0)
    assert result.not_applicable == {}  # only what was asked is judged
    everything = run_gap(log, RIGID, jobs=1, max_effects=0)
    assert list(everything.not_applicable) == TYRES and everything.to_json()["not_applicable"]
    assert everything.to_json()["settings_changed"] == {"max_effects": 0}
    assert "not tried: tyre_stiffness, tyre_balance, tyre_relaxation (they need wheels.tyre_model" \
        in summary_text(everything)


def test_softer_tyres_are_named_on_a_slip_tyre_car_file(soft_tyres):
    log, truth = soft_tyres
    result = run_gap(log, SLIP, jobs=1, effects=["tyre_stiffness", "tyre_balance", "steering_gain"])
    assert result.effects[:1] == ["tyre_stiffness"]
    assert result.parameters["tyre_stiffness_scale"] == pytest.approx(0.55, rel=0.15)
    assert result.gap_after < 0.5 * result.gap_before
