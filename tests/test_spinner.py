"""Spinner API and lockstep clock against a tiny fake sim (no dartpy, no track): fast."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner import CommandError, RunFinished, SimError, Spinner
from simrunner.run.clock import LockstepClock
from simrunner.run.spinner import Session
from vehicle.description import CarDescription

DT = 0.002
CAR = CarDescription()  # camera 128 x 128 at 50 fps -> 10 steps per frame


class FakeSim:
    """Kinematic stand-in for CarSim that records what the clock asks of it."""

    def __init__(self):
        self.step_calls: list[int] = []
        self.commands: list[tuple[int, tuple]] = []  # (steps done when set, command)
        self.steps = 0
        self.x = 0.0
        self.v = 0.0
        self.cmd = (0.0, 0.0, 0.0)

    def set_command(self, speed_mps, steer_rad, yaw_rate_radps):
        self.commands.append((self.steps, (speed_mps, steer_rad, yaw_rate_radps)))
        self.cmd = (speed_mps, steer_rad, yaw_rate_radps)

    def step(self, n=1):
        self.step_calls.append(n)
        for _ in range(n):
            self.v = self.cmd[0]
            self.x += self.v * DT
        self.steps += n

    @property
    def pose(self):
        return Pose2(self.x, 0.0, 0.0)

    z_m = 0.01
    steer_rad = 0.0
    yaw_rate_radps = 0.0

    @property
    def speed_mps(self):
        return self.v

    def wheel_contacts_xy(self):
        return np.zeros((4, 2))


class FakeCamera:
    def render(self, pose):
        return np.full((128, 128), 100, np.uint8)

    def render_row(self, pose, row):
        return np.full(128, row, np.uint8)

    def add_noise(self, img, rng):
        noise = np.rint(rng.standard_normal(img.shape) * 2.0).astype(np.int16)
        return (img.astype(np.int16) + noise).clip(0, 255).astype(np.uint8)

    def line_image(self, pose, row, normals=None):
        img = self.render_row(pose, row).reshape(1, -1)
        return img if normals is None else self.add_noise(img, normals)


def make(frames: list | None = None):
    sim = FakeSim()
    clock = LockstepClock(sim, dt_s=DT, frame_period_s=1 / CAR.camera.fps_hz,
                          on_frame=((lambda k, *state: frames.append(k)) if frames is not None else None))
    session = Session(clock=clock, camera=FakeCamera(), car=CAR, rng=np.random.default_rng(0))
    return Spinner(session=session), sim, clock


def test_api_surface_and_camelcase_aliases():
    s, _, _ = make()
    pairs = {"setServo": "set_servo", "setSpeed": "set_speed", "setSpeedAndServo": "set_speed_and_servo",
             "getImage": "get_image", "getSpeed": "get_speed", "getPosition": "get_position",
             "getTime": "get_time", "addData": "add_data", "addNoise": "add_noise"}
    for camel, snake in pairs.items():
        assert getattr(Spinner, camel) is getattr(Spinner, snake)
    assert callable(s.sleep) and callable(s.configure)
    assert Spinner.LINE_ROW == CAR.camera.default_row == s.line_row == 60
    assert s.image_shape == (128, 128)


def test_busy_wait_on_get_time_terminates_one_step_per_call():
    s, sim, clock = make()
    t0 = s.get_time()
    calls = 0
    while s.get_time() - t0 < 1.0:
        calls += 1
    assert clock.step_index == sim.steps
    assert s.get_time() - t0 == pytest.approx(1.0 + DT, abs=1e-12)
    assert calls == round(1.0 / DT) - 1


def test_get_image_waits_for_the_next_frame_boundary():
    s, sim, clock = make()
    s.get_image()
    assert clock.step_index == 10  # 20 ms frames of 2 ms steps
    s.get_time()  # one step
    s.get_image(5)
    assert clock.step_index == 20
    s.get_image()
    assert clock.step_index == 30


def test_sleep_steps_in_frame_sized_chunks_and_runs_every_frame():
    frames: list[int] = []
    s, sim, clock = make(frames)
    clock.start()
    s.sleep(1.0)
    assert clock.step_index == 500
    assert sim.step_calls == [10] * 50  # as large as possible: up to each frame boundary
    assert frames == list(range(51))  # frame work ran at every boundary without get_image
    s.sleep(0.0031)  # ceil(0.0031 / 0.002) = 2 steps
    assert clock.step_index == 502
    s.sleep(0)  # at least one step
    assert clock.step_index == 503


def test_commands_reach_the_sim_once_before_the_next_step():
    s, sim, clock = make()
    s.set_speed(1.5)
    s.set_servo(0.1)
    assert sim.commands == []  # nothing until time passes
    s.sleep(0.1)
    assert len(sim.commands) == 1 and sim.commands[0][0] == 0
    speed, steer, yaw = sim.commands[0][1]
    assert (speed, steer) == (1.5, 0.1)
    assert yaw == pytest.approx(1.5 * math.sin(0.1) / CAR.chassis.wheelbase_m)  # thesis eq. 5.2/5.3
    s.sleep(0.1)
    assert len(sim.commands) == 1  # unchanged commands are not re-sent
    assert sim.x == pytest.approx(1.5 * 0.2)


def test_norm_functions_real_car_servo_units_and_denorm():
    s, sim, clock = make()
    out = s.configure(turn_norm=lambda speed, angle: -angle / 512 * 0.4,
                      speed_norm=lambda speed, angle: speed * 0.01,
                      speed_denorm=lambda v, angle: v / 0.01,
                      diff_norm=lambda v, d: 0.0)
    assert out is s
    s.setSpeedAndServo(200, 256)  # thesis units: 256 = half right
    s.sleep(0.02)
    assert sim.commands[-1][1] == pytest.approx((2.0, -0.2, 0.0))
    assert s.getSpeed() == pytest.approx(200)
    s.set_servo(-512, speed=100)  # speed only feeds turn_norm
    s.sleep(0.02)
    assert sim.commands[-1][1] == pytest.approx((2.0, 0.4, 0.0))


def test_get_image_shapes_and_noise_is_seeded():
    s, _, _ = make()
    full = s.get_image()
    assert full.shape == (128, 128) and full.dtype == np.uint8
    row = s.getImage(60, add_noise=False)
    assert row.shape == (1, 128) and row.dtype == np.uint8 and (row == 60).all()
    a = make()[0].get_image(3)
    b = make()[0].get_image(3)
    assert np.array_equal(a, b)
    with pytest.raises(CommandError, match=r"get_image\(line=128\)"):
        make()[0].get_image(128)


@pytest.mark.parametrize("call, text", [
    (lambda s: s.set_speed(float("nan")), r"set_speed\(speed=nan\)"),
    (lambda s: s.set_servo(float("inf")), r"set_servo\(angle=inf\)"),
    (lambda s: s.set_speed_and_servo(1.0, "left"), r"set_speed_and_servo\(angle='left'\)"),
    (lambda s: s.sleep(-1), r"sleep\(seconds=-1\)"),
])
def test_bad_command_is_a_clear_error_and_ends_the_run(call, text):
    s, _, clock = make()
    with pytest.raises(CommandError, match=text):
        call(s)
    assert clock.finished is not None and clock.finished.outcome == "controller_error"
    with pytest.raises(RunFinished):
        s.get_time()


def test_norm_returning_nan_names_the_norm():
    s, _, _ = make()
    s.configure(turn_norm=lambda speed, angle: math.nan)
    with pytest.raises(CommandError, match=r"set_servo\(.*angle=0.1\): turn_norm returned nan"):
        s.set_servo(0.1)


def test_run_finished_is_not_an_exception_and_every_later_call_raises():
    assert not issubclass(RunFinished, Exception)
    s, _, clock = make()
    clock.finish("timeout", "time limit")
    for call in (s.get_time, s.get_image, s.get_speed, s.get_position, lambda: s.sleep(1),
                 lambda: s.set_speed(1)):
        with pytest.raises(RunFinished) as info:
            try:
                call()
            except Exception:  # what a controller might write: must not swallow it
                pytest.fail("RunFinished was caught by except Exception")
        assert info.value.outcome == "timeout"


def test_finish_during_a_wait_stops_stepping_at_that_frame():
    frames: list[int] = []
    s, sim, clock = make(frames)

    def on_frame(k, t_s, pose, command, row_command):
        return ("finished", "laps done") if k == 3 else None

    clock.on_frame = on_frame
    with pytest.raises(RunFinished, match="laps done"):
        s.sleep(10.0)
    assert clock.step_index == 30


def test_add_data_accepts_text_and_image_lines_and_rejects_others():
    s, _, _ = make()
    s.add_data(["a", "b"])
    s.addData("image_row:5")
    s.add_data(np.zeros(128, np.uint8))
    s.add_data(np.zeros((2, 128), np.uint8))
    with pytest.raises(CommandError, match="add_data"):
        s.add_data(42)
    with pytest.raises(CommandError, match="add_data"):
        s.add_data(["text", 3])  # every item must be a str, also without a video
    assert s.recording is False  # no video: add_data shows nothing


def test_add_noise_works_in_place():
    s, _, _ = make()
    img = np.full((4, 128), 100, np.uint8)
    out = s.add_noise(img)
    assert out is img and not (img == 100).all()


def test_get_position_and_get_speed_after_driving():
    s, _, _ = make()
    s.set_speed_and_servo(2.0, 0.0)
    s.sleep(0.5)
    x, y, z = s.get_position()
    assert x == pytest.approx(2.0 * (0.5 + DT)) and y == 0.0 and z == 0.01
    assert s.get_speed() == 2.0


def test_spinner_outside_a_run_is_a_clear_error():
    with pytest.raises(SimError, match="simrunner drive"):
        Spinner()


def test_frame_schedule_with_a_period_that_is_not_a_whole_number_of_steps():
    sim = FakeSim()
    clock = LockstepClock(sim, dt_s=0.003, frame_period_s=0.02)  # 6.67 steps per frame
    boundaries = []
    for _ in range(6):
        clock.advance_to_next_frame()
        boundaries.append(clock.step_index)
    assert boundaries == [7, 13, 20, 27, 33, 40]  # round(k * 20 / 3)


def test_a_latched_stop_keeps_the_pending_call_until_the_unmask_and_unpend_clears_it():
    """``remove_interrupt(latch=True)`` (an NVIC source turned off): a call held by the mask runs
    once at the unmask, at its step, then never again; without a pending call nothing is kept;
    ``unpend_interrupt`` (NVIC_ClearPendingIRQ) drops the kept call."""
    sim = FakeSim()
    clock = LockstepClock(sim, dt_s=0.002, frame_period_s=0.02)
    ticks = []

    def tick():
        ticks.append(clock.step_index)

    for unpend, expected in ((False, [3, 8]), (True, [3])):
        ticks.clear()
        clock.add_interrupt(0.006, tick)
        clock.advance(4)
        clock.mask()
        clock.advance(4)                   # due at step 6 (of this pass): held
        assert clock.remove_interrupt(tick, latch=True) == 1
        if unpend:
            assert clock.unpend_interrupt(tick) == 1
        clock.unmask()
        clock.advance(10)
        assert [t - (clock.step_index - 18) for t in ticks] == expected
    clock.add_interrupt(0.006, tick)       # stopped with nothing pending: nothing kept
    clock.advance(1)
    assert clock.remove_interrupt(tick, latch=True) == 1 and clock.unpend_interrupt(tick) == 0


def test_is_pending_tells_a_call_held_by_the_mask_kept_by_a_latched_stop_or_due_after_the_handler():
    """``LockstepClock.is_pending`` (a kit's NVIC_GetPendingIRQ): False while nothing fell due since the
    mask; True once a call is held, also after a latched stop; False once it ran or was unpended; in a
    handler, True for another handler due at the same step after it (not for one that ran)."""
    sim = FakeSim()
    clock = LockstepClock(sim, dt_s=0.002, frame_period_s=0.02)
    seen = []

    def tick():
        pass

    def first():
        seen.append((clock.is_pending(tick), clock.is_pending(first)))

    clock.add_interrupt(0.006, tick)
    clock.advance(1)
    clock.mask()
    assert not clock.is_pending(tick)
    clock.advance(2)                       # due at step 3: held
    assert clock.is_pending(tick)
    clock.unmask()
    assert not clock.is_pending(tick)
    clock.mask()
    clock.advance(3)                       # step 6: held again
    clock.remove_interrupt(tick, latch=True)
    assert clock.is_pending(tick)
    clock.unpend_interrupt(tick)
    assert not clock.is_pending(tick)
    clock.unmask()
    clock.add_interrupt(0.004, first)      # both due at steps 8 and 10: first, set up first, runs first
    clock.add_interrupt(0.004, tick)
    clock.advance(4)
    assert seen == [(True, False), (True, False)] and not clock.is_pending(tick)


def test_the_clock_removes_an_interrupt_and_steps_on_without_one():
    """``LockstepClock.remove_interrupt``: the handler runs no more; with none left the clock
    steps to the next frame in one chunk again; the count says how many were removed."""
    sim = FakeSim()
    clock = LockstepClock(sim, dt_s=0.002, frame_period_s=0.02)
    ticks = []

    def tick():
        ticks.append(clock.step_index)

    clock.add_interrupt(0.006, tick)
    clock.advance(10)
    assert ticks == [3, 6, 9]
    assert clock.remove_interrupt(tick) == 1 and clock.remove_interrupt(tick) == 0
    sim.step_calls.clear()
    clock.advance_to_next_frame()
    clock.advance(10)
    assert ticks == [3, 6, 9] and sim.step_calls == [10, 10]  # no chunk cut at an interrupt's step
