"""Written contracts of the simulator: the car-model protocol, run settings validated once,
enums for outcomes and events, the run recorder's row convention, and runs that share
nothing (two runs in one process, even in two threads, give what they give alone)."""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from simrunner.car import CarModel
from simrunner.car.effects import EffectSim, make_sim, with_effects
from simrunner.car.physics import CarSim
from simrunner.car.protocol import protocol_members
from simrunner.errors import SimError
from simrunner.run.judge import EventKind
from simrunner.telemetry.log import RunRecorder
from simrunner.run.result import Outcome
from simrunner.run.runner import drive, resolve_track
from simrunner.run.settings import RunSettings, SettingsError
from vehicle import CarDescription

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
CAR = CarDescription()


def test_carsim_and_effectsim_satisfy_the_car_model_protocol_by_their_own_members():
    plain = make_sim(CAR)
    effected = make_sim(with_effects(CAR, motor_lag_s=0.1))
    assert type(plain) is CarSim and type(effected) is EffectSim
    for sim in (plain, effected):
        assert isinstance(sim, CarModel)
    assert "__getattr__" not in EffectSim.__dict__  # no forwarding
    members = protocol_members()
    assert {"pose", "set_command", "wheel_contacts", "place", "save_state"} <= set(members)
    for name in members:
        if name != "car":  # car is an attribute of both
            assert any(name in klass.__dict__ for klass in EffectSim.__mro__ if klass is not object), name
        assert hasattr(plain, name), name


def test_effectsim_read_outs_are_the_inner_cars():
    sim = make_sim(with_effects(CAR, steering_offset_rad=0.02, motor_lag_s=0.05))
    sim.set_command(1.0, 0.1)
    sim.step(100)
    inner = sim.sim
    assert sim.pose == inner.pose and sim.z_m == inner.z_m
    assert sim.wheel_contacts() == inner.wheel_contacts()
    assert sim.knuckle_angles_rad() == inner.knuckle_angles_rad()
    np.testing.assert_array_equal(sim.wheel_speeds_radps(), inner.wheel_speeds_radps())


@pytest.mark.parametrize("field, value, match", [
    ("laps", 0, "laps = 0: expected a whole number >= 1"),
    ("laps", True, "laps = True"),
    ("laps", 1.5, "laps = 1.5"),
    ("seed", -1, "seed = -1: expected a whole number >= 0"),
    ("dt_s", 0.05, r"dt_s = 0.05: expected a number in \(0, 0.02\]"),
    ("time_limit_s", float("nan"), "time_limit_s = nan"),
    ("wall_limit_s", 0, "wall_limit_s = 0"),
])
def test_run_settings_are_validated_once_with_one_line_errors(field, value, match):
    with pytest.raises(SettingsError, match=match):
        RunSettings(**{field: value})
    with pytest.raises(SimError, match=match):  # drive() checks them before loading anything
        drive(EXAMPLES / "line_follower.py", **{field: value})


def test_run_settings_normalise_numpy_numbers():
    s = RunSettings(laps=np.int64(2), seed=np.uint8(3), dt_s=np.float64(0.002))
    assert (type(s.laps), type(s.seed), type(s.dt_s)) == (int, int, float)


def test_outcomes_and_event_kinds_are_string_enums():
    assert Outcome.FINISHED == "finished" and f"{Outcome.OFF_TRACK}" == "off_track"
    assert Outcome.FINISHED.ok and Outcome.CONTROLLER_RETURNED.ok and not Outcome.TIMEOUT.ok
    assert {k.value for k in EventKind} == {"lap_start", "lap", "lap_short", "finished",
                                            "gate_backward", "off_track", "on_track", "off_course"}


def test_recorder_closes_each_row_with_the_command_of_the_first_step_after_it():
    rec = RunRecorder()
    state = (0.0,) * 6
    rec.frame(0, 0.0, *state, (0.0, 0.0, 0.0), None, 0, False)
    rec.text(["frame 0 text"])
    rec.frame(1, 0.02, *state, (1.0, 0.1, 0.0), (1.0, 0.1, 0.0), 0, False)  # applied after t0
    rec.text(["a"])
    rec.text(["b"])
    rec.frame(2, 0.04, *state, (2.0, 0.2, 0.0), (1.5, 0.1, 0.0), 1, True)
    log = rec.freeze()
    assert log.speed_cmd_mps.tolist() == [1.0, 1.5, 2.0]  # last row: the command in force
    assert log.data_text == ("frame 0 text", "a | b", "")
    assert log.lap.tolist() == [0, 0, 1] and log.off_track.tolist() == [False, False, True]
    assert not log.x_m.flags.writeable


def test_two_runs_in_two_threads_give_what_they_give_alone():
    track, _ = resolve_track(None, CAR)
    ctrl = EXAMPLES / "line_follower.py"
    alone = [drive(ctrl, track=track, time_limit_s=1.5, seed=s).log for s in (1, 2)]
    together: dict[int, object] = {}

    def run(seed: int) -> None:
        together[seed] = drive(ctrl, track=track, time_limit_s=1.5, seed=seed).log

    threads = [threading.Thread(target=run, args=(s,)) for s in (1, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    for seed, log in zip((1, 2), alone):
        other = together[seed]
        assert len(other) == len(log) > 50
        for name in ("x_m", "y_m", "yaw_rad", "speed_mps", "steer_cmd_rad"):
            np.testing.assert_array_equal(getattr(other, name), getattr(log, name))


def test_the_log_schema_is_documented_once_in_docs_telemetry():
    from simrunner.telemetry.log import COLUMNS, FORMAT_LINE

    doc = (Path(__file__).resolve().parents[1] / "docs" / "telemetry.md").read_text()
    assert FORMAT_LINE in doc
    for column in COLUMNS:
        assert f"| `{column.name}` | {column.unit} |" in doc, column.name
