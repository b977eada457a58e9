"""Gap workflow parts that need no physics: log checks, regimes, statistics, replay and
fit machinery on a fast kinematic stand-in simulator."""
from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from simrunner.run.log import FORMAT_LINE, CommandSteps, LogError, RunLog, log_from_columns, read_log, write_log
from simrunner.workflows.gap import LogError as GapLogError
from simrunner.workflows.gap.fit import (Problem, Segment, cost_of, fit_effect,
                                         nominal_scales)
from simrunner.workflows.gap.glitches import GlitchKind, find_glitches, glitch_mask, time_gaps
from simrunner.workflows.gap.logs import MEASURED_COLUMNS, check_measured, derive
from simrunner.workflows.gap.regimes import REGIMES, format_stats, residual_stats, segment
from simrunner.workflows.gap.replay import (FIT_SIGNALS, REPORT_SIGNALS, dead_reckoned_yaw, make_windows, noise_rms,
                                            replay, residuals,
                                            rmse, signals_of, smoothed_log, split_windows, window_mask)
from vehicle.description import CarDescription, Effects


class KinematicSim:
    """Kinematic bicycle with first-order speed tracking; honours steering_offset,
    steering_gain and motor_lag of ``car.effects`` (a CarSim stand-in for fast tests)."""

    def __init__(self, car, dt_s):
        self.car, self.dt = car, dt_s
        self.x = self.y = self.yaw = self.v = self.steer = 0.0
        self.v_cmd = self.s_cmd = self.v_tgt = 0.0

    def set_state(self, pose, speed_mps, steer_rad=0.0, yaw_rate_radps=0.0):
        self.x, self.y, self.yaw = pose.x_m, pose.y_m, pose.yaw_rad
        self.v, self.steer = speed_mps, steer_rad
        self.v_cmd = self.v_tgt = speed_mps
        self.s_cmd = (steer_rad / self.car.effects.steering_gain) - self.car.effects.steering_offset_rad

    def place(self, pose, speed_mps, steer_rad=0.0, yaw_rate_radps=0.0):
        self.x, self.y, self.yaw = pose.x_m, pose.y_m, pose.yaw_rad
        self.v, self.steer = speed_mps, steer_rad

    def set_command(self, speed_mps, steer_rad, yaw_rate_radps=None):
        self.v_cmd, self.s_cmd = speed_mps, steer_rad

    def set_coast(self, coast):
        pass

    def step(self, n=1):
        e, L = self.car.effects, self.car.chassis.wheelbase_m
        a = self.car.drive.max_accel_mps2 * self.dt
        for _ in range(n):
            lag = e.motor_lag_s
            self.v_tgt += (self.v_cmd - self.v_tgt) * (1.0 if lag == 0 else min(1.0, self.dt / lag))
            self.v += float(np.clip(self.v_tgt - self.v, -a, a))
            tgt = np.clip(e.steering_gain * (self.s_cmd + e.steering_offset_rad), -0.4, 0.4)
            r = self.car.steering.rate_radps * self.dt
            self.steer += float(np.clip(tgt - self.steer, -r, r))
            self.yaw += self.v * math.tan(self.steer) / L * self.dt
            self.x += self.v * math.cos(self.yaw) * self.dt
            self.y += self.v * math.sin(self.yaw) * self.dt

    @property
    def pose(self):
        return Pose2(self.x, self.y, self.yaw)

    @property
    def speed_mps(self):
        return self.v

    @property
    def yaw_rate_radps(self):
        return self.v * math.tan(self.steer) / self.car.chassis.wheelbase_m


def kin_factory(car, dt_s):
    return KinematicSim(car, dt_s)


def commands(duration_s=12.0, rate_hz=100.0):
    """Speed steps and left/right step steers; returns t, speed_cmd, steer_cmd."""
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    speed = np.where((t % 4.0) < 2.0, 1.5, 0.8)
    speed[(t > 9.0) & (t < 10.0)] = 0.0
    steer = np.where((t % 3.0) < 1.0, 0.0, np.where((t % 3.0) < 2.0, 0.2, -0.2))
    return t, speed, steer


def simulate(car, noise_rng=None, duration_s=12.0, rate_hz=100.0, columns=MEASURED_COLUMNS):
    """A 'measured' log from the kinematic sim (truth at 1 ms, logged at ``rate_hz``) with
    ``columns`` (any of MEASURED_COLUMNS and ``yaw_rate_radps``, the gyro)."""
    t, v_cmd, s_cmd = commands(duration_s, rate_hz)
    sim = KinematicSim(car, 0.001)
    sim.set_state(Pose2(), 1.0, 0.0, 0.0)
    per = int(round(1000.0 / rate_hz))
    names = ("t_s", "x_m", "y_m", "yaw_rad", "speed_mps", "speed_cmd_mps", "steer_cmd_rad", "yaw_rate_radps")
    rows = []
    for i in range(t.size):
        p = sim.pose
        rows.append((t[i], p.x_m, p.y_m, p.yaw_rad, sim.speed_mps, v_cmd[i], s_cmd[i], sim.yaw_rate_radps))
        sim.set_command(v_cmd[i], s_cmd[i])
        sim.step(per)
    data = np.array(rows)
    if noise_rng is not None:
        sig = np.array([0, 0.005, 0.005, 0.005, 0.02, 0, 0, 0.01])
        data = data + noise_rng.normal(size=data.shape) * sig
    return log_from_columns({c: data[:, k] for k, c in enumerate(names) if c in columns}, "<kin>")


# -- logs ------------------------------------------------------------------------------
GAP_HEADER = "t,x,y,yaw,speed,speed_cmd,steer_cmd\n"  # format 1 (no units in the names)


def _write(tmp_path, text, name="log.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _good_rows(n=100, dt=0.1):
    return "".join(f"{i * dt},{i * 0.1},0,0,1,1,0\n" for i in range(n))


def read_measured(path):
    """What ``simrunner gap`` does with its input file."""
    return check_measured(read_log(path))


def test_gap_log_error_is_the_run_log_error():
    assert GapLogError is LogError


def test_read_log_round_trip(tmp_path):
    log = simulate(CarDescription())
    write_log(log, tmp_path / "a.csv", float_format="%.17g")
    back = read_log(tmp_path / "a.csv")
    assert back.names == log.names == MEASURED_COLUMNS
    for c in MEASURED_COLUMNS:
        np.testing.assert_array_equal(back.column(c), log.column(c))


def test_read_log_ignores_extra_columns_and_order(tmp_path):
    text = "steer_cmd,t,extra,x,y,yaw,speed,speed_cmd\n" + "".join(
        f"0,{i * 0.1},hello,{i * 0.1},0,0,1,1\n" for i in range(100))
    log = read_measured(_write(tmp_path, text))
    assert len(log) == 100 and log.x_m[10] == pytest.approx(1.0)


@pytest.mark.parametrize("text, line, what", [
    ("t,x,y,yaw,speed,speed_cmd\n" + _good_rows(), 1, "missing: steer_cmd_rad"),
    ("", 1, "header"),
    (GAP_HEADER + _good_rows(5), 6, "expected at least"),
    (GAP_HEADER + _good_rows(20, 0.5), 21, "expected at least"),
    (GAP_HEADER + _good_rows(10) + "1.0,abc,0,0,1,1,0\n" + _good_rows(90), 12, "column 'x_m': expected a number"),
    (GAP_HEADER + _good_rows(10) + "1.0,nan,0,0,1,1,0\n", 12, "finite"),
    (GAP_HEADER + _good_rows(10) + "0.5,0,0,0,1,1,0\n" + _good_rows(90), 12, "strictly increasing"),
    (GAP_HEADER + _good_rows(10) + "\n5.0,0,0\n", 13, "expected 7 cells"),
    (FORMAT_LINE + "\n" + GAP_HEADER + _good_rows(10) + "0.5,0,0,0,1,1,0\n", 13, "strictly increasing"),
])
def test_read_log_errors_name_file_and_line(tmp_path, text, line, what):
    p = _write(tmp_path, text)
    with pytest.raises(LogError, match=what) as info:
        read_measured(p)
    assert str(info.value).startswith(f"{p}:{line}: ")
    assert "\n" not in str(info.value)


def test_read_log_missing_file(tmp_path):
    with pytest.raises(LogError, match="readable"):
        read_log(tmp_path / "nope.csv")


@settings(max_examples=40, deadline=None)
@given(st.lists(st.text(alphabet="0123456789.,-eE abn\n", max_size=30), max_size=8))
def test_measured_log_never_crashes_on_junk(tmp_path_factory, junk):
    p = tmp_path_factory.mktemp("junk") / "j.csv"
    p.write_text(GAP_HEADER + "\n".join(junk))
    with pytest.raises(LogError):
        read_measured(p)


@settings(max_examples=80, deadline=None)
@given(st.lists(st.sampled_from(list("0123456789.,-eE abn\n\r#\"") + ["t_s", "x_m", "t", "coast", "data_text",
                                                                        "# nxpcup-sim run log, format 3"]),
                max_size=80).map("".join))
def test_read_log_never_crashes_on_junk(tmp_path_factory, junk):
    """Any text: a RunLog or one LogError line, nothing else."""
    p = tmp_path_factory.mktemp("junk") / "j.csv"
    p.write_text(junk)
    try:
        log = read_log(p)
    except LogError as err:
        assert str(err).startswith(f"{p}:") and "\n" not in str(err)
    else:
        assert isinstance(log, RunLog) and log.t_s.size == len(log)


def test_run_gap_checks_its_log_first():
    from simrunner.workflows.gap.report import run_gap

    log = simulate(CarDescription())
    with pytest.raises(LogError, match=r"<kin>:41: expected at least 50 rows"):
        run_gap(log.subset(40), sim_factory=kin_factory)
    with pytest.raises(LogError, match=r"missing: steer_cmd_rad"):
        run_gap(log_from_columns({k: v for k, v in log.columns().items() if k != "steer_cmd_rad"}, "<kin>"),
                sim_factory=kin_factory)


# -- the run log's formats (simrunner.run.log; docs/telemetry.md) ----------------------------
def _full_log(n=6) -> RunLog:
    t = 0.02 * np.arange(n)
    cols = {name: np.linspace(-1.0, 1.0, n) + k for k, name in enumerate(
        ("x_m", "y_m", "yaw_rad", "speed_mps", "steer_rad", "yaw_rate_radps", "speed_cmd_mps", "steer_cmd_rad",
         "yaw_rate_cmd_radps"))}
    cols.update(frame=np.arange(n), t_s=t, coast=np.arange(n) % 2, lap=np.arange(n) // 3, off_track=np.arange(n) == 4)
    return log_from_columns(cols, "<full>")


def _assert_same_log(a: RunLog, b: RunLog) -> None:
    assert a.names == b.names
    for name in a.names:
        if name == "data_text":
            assert a.data_text == b.data_text
        else:
            np.testing.assert_array_equal(a.column(name), b.column(name))
            assert a.column(name).dtype == b.column(name).dtype


def test_format_1_file_reads_as_the_format_2_file(tmp_path):
    log = _full_log()
    p2 = write_log(log, tmp_path / "two.csv", float_format="%.17g")
    lines = p2.read_text().splitlines()
    assert lines[0] == FORMAT_LINE
    old_names = {"t_s": "t", "x_m": "x", "y_m": "y", "yaw_rad": "yaw", "speed_mps": "speed", "steer_rad": "steer",
                 "yaw_rate_radps": "yaw_rate", "speed_cmd_mps": "speed_cmd", "steer_cmd_rad": "steer_cmd",
                 "yaw_rate_cmd_radps": "yaw_rate_cmd"}
    header = ",".join(old_names.get(n, n) for n in lines[1].split(","))
    p1 = _write(tmp_path, "\n".join([header] + lines[2:]) + "\n", "one.csv")  # no format line
    one, two = read_log(p1), read_log(p2)
    _assert_same_log(one, two)
    _assert_same_log(two, log)


def test_newer_format_is_refused_in_one_line(tmp_path):
    p = _write(tmp_path, "# nxpcup-sim run log, format 3\nt_s,x_m\n0,0\n0.1,0\n")
    with pytest.raises(LogError, match="format 3 is newer") as info:
        read_log(p)
    assert str(info.value).startswith(f"{p}:1: ") and "\n" not in str(info.value)


def test_data_text_with_commas_and_quotes_round_trips(tmp_path):
    texts = ("", 'say "hi", then go', "a,b,,c", '"', "line | two", "plain")
    log = log_from_columns({"t_s": 0.1 * np.arange(len(texts)), "speed_mps": np.ones(len(texts)),
                            "data_text": texts}, "<text>")
    back = read_log(write_log(log, tmp_path / "text.csv", float_format="%.17g"))
    assert back.data_text == texts
    _assert_same_log(back, log)


def test_log_without_pose_reads_and_require_names_what_is_missing(tmp_path):
    p = _write(tmp_path, "# nxpcup-sim run log, format 2\nt_s,speed_mps,yaw_rate_radps\n"
                         + "".join(f"{0.02 * i:.2f},1.0,0.1\n" for i in range(60)))
    log = read_log(p)
    assert log.names == ("t_s", "speed_mps", "yaw_rate_radps") and len(log) == 60
    assert log.x_m is None and log.coasting().shape == (60,) and not log.coasting().any()
    with pytest.raises(LogError, match=r"missing: x_m\)") as info:
        log.require("x_m")
    assert str(info.value).startswith(f"{p}:1: ")
    with pytest.raises(LogError, match=r"missing: speed_cmd_mps, steer_cmd_rad\)"):
        check_measured(log)


def test_derive_recovers_yaw_rate_and_steer():
    car = CarDescription()
    log = simulate(car, np.random.default_rng(0))
    d = derive(log, car.chassis.wheelbase_m, car.steering.limit_rad)
    sl = slice(30, 85)  # t in [0.3, 0.85): straight
    assert np.max(np.abs(d.yaw_rate_radps[sl])) < 0.1
    turn = slice(150, 190)  # t in [1.5, 1.9): steady left turn at steer 0.2
    np.testing.assert_allclose(d.steer_rad[turn], 0.2, atol=0.02)


# -- regimes and statistics -------------------------------------------------------------
def test_segment_on_constructed_log():
    n = 1000
    t = np.arange(n) * 0.01
    v = np.where(t < 2, 0.5 + 0.5 * t, np.where(t < 4, 1.5, np.where(t < 6, 1.5 - 0.5 * (t - 4), 0.5)))
    yaw = np.zeros(n)
    speed_cmd = np.where(t < 4, 1.5, np.where(t < 6, 0.5, 0.0))
    steer_cmd = np.where(t < 3, 0.0, np.where(t < 5, 0.2, -0.2))
    x = np.cumsum(v) * 0.01
    log = log_from_columns(dict(t_s=t, x_m=x, y_m=np.zeros(n), yaw_rad=yaw, speed_mps=v, speed_cmd_mps=speed_cmd,
                                steer_cmd_rad=steer_cmd))
    d = derive(log, 0.175)
    m = segment(log, d)
    assert set(m) == set(REGIMES)
    inner = lambda a, b: (t > a + 0.1) & (t < b - 0.1)  # noqa: E731 - away from the edges
    assert m["accelerating"][inner(0, 2)].all() and not m["accelerating"][inner(2, 10)].any()
    assert m["steady"][inner(2, 4)].all()
    assert m["braking"][inner(4, 6)].all()
    assert m["coasting"][inner(6, 10)].all()
    assert m["straight"][inner(0, 3)].all() and m["left"][inner(3, 5)].all() and m["right"][inner(5, 10)].all()
    assert (m["cornering"] == (m["left"] | m["right"])).all()
    assert not (m["left"] & m["right"]).any()


def test_residual_stats_values():
    r = {"s": np.array([1.0, -1.0, 3.0, np.nan])}
    masks = {"all": np.array([True, True, True, True]), "one": np.array([False, False, True, False]),
             "none": np.zeros(4, bool)}
    rows = {row["regime"]: row for row in residual_stats(r, masks)}
    assert rows["all"]["count"] == 3
    assert rows["all"]["rmse"] == pytest.approx(math.sqrt(11 / 3))
    assert rows["all"]["bias"] == pytest.approx(1.0)
    assert rows["one"]["bias"] == 3.0
    assert rows["none"]["count"] == 0 and math.isnan(rows["none"]["rmse"])
    assert "rmse" in format_stats(list(rows.values()))


# -- replay and fit on the kinematic stand-in ------------------------------------------------
def test_windows_cover_log_and_split():
    log = simulate(CarDescription())
    w = make_windows(log, 2.0)
    assert w[0].start == 0 and w[-1].stop == len(log)
    assert all(a.stop == b.start for a, b in zip(w[:-1], w[1:]))
    fit, held = split_windows(w)
    assert len(held) == len(w) // 3 and not set(fit) & set(held)


def test_replay_of_exact_model_has_tiny_residuals():
    car = CarDescription()
    log = simulate(car)
    d = derive(log, car.chassis.wheelbase_m)
    res = residuals(log, d, replay(car, log, d, make_windows(log), dt_s=0.001, sim_factory=kin_factory))
    assert np.nanmax(np.abs(res["speed_mps"])) < 0.05  # window starts on a speed ramp: smoothing
    assert np.nanmax(np.abs(res["position_m"])) < 0.02


def test_a_log_far_from_its_origin_replays_as_near_it():
    """A map frame whose origin is a kilometre away: the simulator's ground is finite (400 m),
    so each window is replayed shifted by whole 200 m towards it (a car placed at x = 1234 m
    fell off the ground and drove backwards at 2 m/s)."""
    car = CarDescription()
    near = simulate(car, np.random.default_rng(1), rate_hz=50.0)
    far = log_from_columns({**near.columns(), "x_m": near.x_m + 1234.5, "y_m": near.y_m - 987.25}, "<far>")
    res = []
    for log in (near, far):
        d = derive(log, car.chassis.wheelbase_m)
        res.append(residuals(log, d, replay(car, log, d, make_windows(log))))
    assert np.nanmax(np.abs(res[0]["position_m"])) < 0.1 and np.nanmax(np.abs(res[0]["speed_mps"])) < 0.2
    for k in ("position_m", "yaw_rad", "speed_mps", "yaw_rate_radps"):
        assert np.allclose(res[1][k], res[0][k], atol=1e-6, equal_nan=True), k


def test_a_merged_logs_commands_between_rows_act_at_their_own_stamps():
    """A pose logged at 20 Hz with commands sent at 100 Hz (a merged topic log): each row
    holds the command last sent, so every command change reaches the row-held replay up to
    40 ms late; with the log's command steps it acts when it was sent."""
    car = CarDescription()
    full = simulate(car)  # 100 Hz: the commands' own rate; steps at whole seconds
    thin = full.subset(np.arange(2, len(full), 5))  # the pose at 20 Hz, 20 ms after each step
    merged = dataclasses.replace(thin, command_steps=CommandSteps(full.t_s, full.speed_cmd_mps, full.steer_cmd_rad))
    d = derive(thin, car.chassis.wheelbase_m)
    windows = make_windows(thin)
    mask = window_mask(len(thin), windows)

    def position_rms(log):
        res = residuals(log, d, replay(car, log, d, windows, dt_s=0.001, sim_factory=kin_factory))
        return float(np.sqrt(np.mean(res["position_m"][mask] ** 2)))

    held, stamped = position_rms(thin), position_rms(merged)
    assert stamped < 0.3 * held and held > 0.005
    # steps at the rows' own stamps only change nothing
    on_rows = dataclasses.replace(thin, command_steps=CommandSteps(thin.t_s, thin.speed_cmd_mps, thin.steer_cmd_rad))
    assert position_rms(on_rows) == held


@pytest.mark.parametrize("rate_hz", [10.0, 25.0, 50.0])
def test_a_rate_taken_from_the_pose_is_compared_with_the_prediction_seen_the_same_way(rate_hz):
    """No gyro and no speed sensor: the log's yaw rate and speed are derivatives of its
    smoothed pose, so the prediction goes through the same smoothing. Against the raw
    prediction, the rounded steps of the measured yaw rate would ask for a slower servo."""
    car = CarDescription()
    pose_cols = ("t_s", "x_m", "y_m", "yaw_rad", "speed_cmd_mps", "steer_cmd_rad")
    log = simulate(car, rate_hz=rate_hz, columns=pose_cols)
    with_sensors = simulate(car, rate_hz=rate_hz, columns=pose_cols + ("speed_mps", "yaw_rate_radps"))
    d = derive(log, car.chassis.wheelbase_m)
    windows = make_windows(log)
    pred = replay(car, log, d, windows, dt_s=0.001, sim_factory=kin_factory)
    raw = replay(car, with_sensors, d, windows, dt_s=0.001, sim_factory=kin_factory)
    res = residuals(log, d, pred)
    mask = window_mask(len(log), windows)

    def rms(v):
        return float(np.sqrt(np.mean(v[mask] ** 2)))

    seen, unseen = rms(res["yaw_rate_radps"]), rms(raw.yaw_rate_radps - d.yaw_rate_radps)
    assert seen < 0.01 * unseen and unseen > 0.02
    assert rms(res["speed_mps"]) < 0.5 * rms(raw.speed_mps - d.speed_mps)
    # the pose itself is compared as predicted
    assert np.array_equal(pred.x_m[mask], raw.x_m[mask])


def _problem(true_car, nominal_car, seed=1):
    log = simulate(true_car, np.random.default_rng(seed))
    d = derive(log, nominal_car.chassis.wheelbase_m)
    fit_w, _ = split_windows(make_windows(log))
    res = residuals(log, d, replay(nominal_car, log, d, fit_w, dt_s=0.002, sim_factory=kin_factory))
    segments = (Segment(log, d, tuple(fit_w)),)
    return Problem(nominal_car, segments, nominal_scales(segments, [res]), FIT_SIGNALS, 0.002, kin_factory)


def test_fit_effect_finds_hidden_offset_on_stand_in():
    nominal = CarDescription()
    truth = nominal.replace(effects=nominal.effects.__class__(steering_offset_rad=0.04))
    prob = _problem(truth, nominal)
    c0 = cost_of(prob, nominal)
    r = fit_effect(prob, "steering_offset", c0)
    assert r.parameters["steering_offset_rad"] == pytest.approx(0.04, rel=0.05)
    assert r.improvement > 0.7 and r.delta_bic > 100
    other = fit_effect(prob, "motor_lag", c0)
    assert other.delta_bic < r.delta_bic


def test_rescaled_weighs_every_signal_the_same_under_the_given_car():
    """The normalisation a later chain step judges on: under the nominal car it is the
    problem's own; under the true car the signals the effect bent get much smaller scales,
    and each signal's mean square is 1 again (or below, at the floor)."""
    from simrunner.workflows.gap.fit import SCALE_FLOOR, rescaled, robust_scale_of, segment_residuals, window_costs

    nominal = CarDescription()
    truth = nominal.replace(effects=nominal.effects.__class__(steering_offset_rad=0.04))
    prob = _problem(truth, nominal)
    robust = dataclasses.replace(prob, robust_scale=robust_scale_of(window_costs(prob, segment_residuals(prob, nominal))))
    again = rescaled(robust, nominal)
    assert again.scales == pytest.approx(robust.scales, rel=1e-12)
    assert again.robust_scale == pytest.approx(robust.robust_scale, rel=1e-12)
    assert rescaled(prob, nominal).robust_scale == math.inf  # least squares stays least squares
    judge = rescaled(robust, truth)
    assert judge.segments is robust.segments and judge.signals == robust.signals
    for s in ("cross_m", "yaw_rad", "yaw_rate_radps"):
        assert judge.scales[s] < 0.2 * robust.scales[s]
    res = segment_residuals(judge, truth)[0]
    mask = window_mask(len(prob.segments[0].log), prob.segments[0].windows)
    for s in judge.signals:
        ms = float(np.nanmean((res[s][mask] / judge.scales[s]) ** 2))
        assert ms == pytest.approx(1.0, rel=1e-9) or judge.scales[s] == SCALE_FLOOR[s]


def test_chain_acceptance_needs_bic_fit_and_held_out_improvement():
    from simrunner.workflows.gap.chain import Trial, _reject_reason

    def tr(dbic, imp, held):
        return Trial("drag", {"drag_coeff_kgpm": 0.1}, 1.0, dbic, imp, held, 5)
    assert _reject_reason(tr(500.0, 0.5, 0.5), 1.0, 132.5, 0.068, 0.02) == ""
    assert "delta_BIC 5.0 < 132.5" in _reject_reason(tr(5.0, 0.5, 0.5), 1.0, 132.5, 0.068, 0.02)
    assert "fit improvement 0.1% < 6.8%" in _reject_reason(tr(500.0, 0.001, 0.5), 1.0, 132.5, 0.068, 0.02)
    assert "held-out gap -1.0%: not smaller by 2.0% (the held-out windows do not confirm it)" == \
        _reject_reason(tr(500.0, 0.5, 0.99), 1.0, 132.5, 0.068, 0.02)
    assert "do not confirm" in _reject_reason(tr(500.0, 0.5, float("nan")), 1.0, 132.5, 0.068, 0.02)
    # an effect that acts on none of the held-out windows (an ESC delay, no reversal held out)
    assert "the held-out windows hold nothing it acts on" in _reject_reason(tr(500.0, 0.5, 1.0), 1.0, 132.5,
                                                                           0.068, 0.02)


@pytest.mark.parametrize("effect, field, neutral, near, away", [
    ("drag", "drag_coeff_kgpm", 0.0, 1e-4, 0.05),
    ("steering_offset", "steering_offset_rad", 0.0, 1e-5, 0.01),
    ("steering_gain", "steering_gain", 1.0, 1.0005, 1.1),
])
def test_a_candidate_fitted_at_its_neutral_value_is_not_kept(effect, field, neutral, near, away):
    """Passing every threshold is not enough when the candidate's own parameter stayed
    neutral: the gain then came from refitting the kept ones."""
    from simrunner.workflows.gap.chain import Trial, _reject_reason, neutral_offset

    assert neutral_offset(effect, neutral) == 0.0
    assert neutral_offset(effect, near) < 0.01 <= neutral_offset(effect, away)
    args = (1.0, 132.5, 0.068, 0.02)
    for value, kept in ((neutral, False), (near, False), (away, True)):
        trial = Trial(effect, {"motor_lag_s": 0.2, field: value}, 1.0, 500.0, 0.5, 0.5, 5)
        reason = _reject_reason(trial, *args)
        assert (reason == "") is kept
        if not kept:
            assert "neutral value" in reason


@pytest.mark.parametrize("rate_hz", [20.0, 50.0])
def test_a_reverse_command_is_a_brake_to_reverse_only_while_the_car_rolls_faster_than_one_sample_of_braking(rate_hz):
    """DS2 has a reverse command from rest at a smoothed 0.11 m/s: no braking to see (the
    car is at rest by the next sample), so it must not take the split's brake-to-reverse
    group (with one real event, that event then stays in the fit). At 2 m/s it is one."""
    from simrunner.workflows.gap.report import window_strata

    t = np.arange(0.0, 12.0, 1.0 / rate_hz)
    max_brake = 9.51
    for v_roll in (0.15, 2.0):
        speed = np.full(t.size, v_roll)
        cmd = np.where((t > 5.0) & (t < 5.0 + 2.0 / rate_hz), -5.0, v_roll)
        log = _log({"t_s": t, "x_m": v_roll * t, "y_m": np.zeros_like(t), "yaw_rad": np.zeros_like(t),
                    "speed_mps": speed, "speed_cmd_mps": cmd, "steer_cmd_rad": np.zeros_like(t)})
        derived = derive(log, 0.33)
        windows = make_windows(log)
        masks = segment(log, derived)
        with_car = window_strata(log, derived, masks, windows, max_brake)
        without = window_strata(log, derived, masks, windows)
        assert "brake_to_reverse" in without  # above MOVING_MPS either way
        assert ("brake_to_reverse" in with_car) is (v_roll > max_brake / rate_hz)
        assert with_car.count("brake_to_reverse") <= 1


def test_split_is_stratified_by_label():
    w = [f"w{k}" for k in range(9)]
    labels = ["a", "a", "c", "a", "a", "c", "c", "a", "a"]
    fit, held = split_windows(w, 3, strata=labels)
    # "a": w0 w1 w3 w4 w7 w8 -> last (w8) and third from it (w3); "c": w2 w5 w6 -> last (w6)
    assert held == ["w3", "w6", "w8"]
    assert fit == ["w0", "w1", "w2", "w4", "w5", "w7"]
    fit2, held2 = split_windows(w[:5], 3, strata=["a", "c", "c", "a", "d"])
    assert held2 == ["w2", "w3"] and fit2 == ["w0", "w1", "w4"]  # a lone "d" stays in the fit
    fit3, held3 = split_windows(w[:3], 3, strata=["a", "c", "d"])
    assert held3 == ["w2"]  # nothing held out by group: split without strata


def test_the_plans_two_reverses_go_one_to_the_fits_one_to_the_held_out_windows():
    """An ESC that brakes before it reverses shows only where a reverse command meets a car
    still rolling forward. The plan does that twice and the split keeps the two apart
    (their own stratum), so the effect can be fitted on one and confirmed on the other."""
    from simrunner.workflows.excite import make_plan
    from simrunner.workflows.gap.report import WINDOW_S, prepare
    from simrunner.workflows.gap.synth import make_measured_log

    car = CarDescription()
    plan = make_plan(car)
    rev = np.flatnonzero(plan.kind_mask("reverse"))
    t0 = plan.t_s[rev[0]] - 4.0
    log, _ = make_measured_log("esc_brake_reverse", value=0.5, rng=np.random.default_rng(5), start_s=t0,
                               duration_s=rev.size * 0.02 + 8.0)
    part = prepare(log, car, WINDOW_S)
    speed = np.nan_to_num(part.derived.speed_mps)
    onset = (np.asarray(log.speed_cmd_mps) < -0.05) & (speed > 0.1)

    def with_onset(windows):
        return [w for w in windows if onset[w.start:w.stop].any()]

    assert len(with_onset(part.fit_windows)) >= 1 and len(with_onset(part.held_windows)) >= 1


def test_a_joint_refit_searches_the_new_effect_first(monkeypatch):
    """Powell's first pass line-searches one parameter after the other and a small budget
    ends inside it: the effect just added (``first``) must be searched before the kept ones,
    which start at their last refit. Searched last, it keeps its start value."""
    import simrunner.workflows.gap.chain as chain

    truth = {"steering_offset_rad": 0.01, "mass_scale": 1.2, "steering_gain": 0.9}
    start = {"steering_offset_rad": 0.012, "mass_scale": 1.25, "steering_gain": 1.0}
    u, _ = chain._bounds01(["steering_offset", "mass_scale", "steering_gain"])

    def cost(problem, car):  # a bowl in the fit's scaled coordinates, its floor at the truth
        e = car.effects
        return 1.0 + float(np.sum((u({"steering_offset_rad": e.steering_offset_rad, "mass_scale": e.mass_scale,
                                      "steering_gain": e.steering_gain}) - u(truth)) ** 2))

    monkeypatch.setattr(chain, "cost_of", cost)
    monkeypatch.setattr(chain, "POWELL_EVALS_PER_PARAMETER", 4)  # ends inside the first pass
    names = ["steering_offset", "mass_scale", "steering_gain"]
    new_first, c_first, _, _ = chain.joint_refit(None, CarDescription(), names, start, first="steering_gain")
    old, c_last, _, _ = chain.joint_refit(None, CarDescription(), names, start)
    assert list(new_first) == ["steering_offset_rad", "mass_scale", "steering_gain"]  # the order of names
    assert abs(new_first["steering_gain"] - 0.9) < 0.01 and c_first < c_last
    assert old["steering_gain"] == 1.0  # searched last: never reached


def test_a_refit_keeps_the_middle_of_an_interval_the_fit_windows_cannot_tell_apart(monkeypatch):
    """A deadband the fit windows pin only to (0, 0.3] m/s (no speed command in between in
    them: the cost is the same for every value there, a hair lower at 0.3) is kept at the
    middle of the interval, whose ends are reported (the end towards neutral at twice
    NEUTRAL_TOL of the 0-0.5 range); a parameter whose cost rises towards neutral keeps
    what the search found."""
    from types import SimpleNamespace

    import simrunner.workflows.gap.chain as chain

    def cost(problem, car):
        e = car.effects
        d = e.throttle_deadband_mps
        plateau = 1.0 if d == 0.0 else 0.5 - 1e-7 * d if d <= 0.3 else 0.6  # zero commands coast for any d > 0
        return plateau + (e.steering_gain - 0.9) ** 2

    monkeypatch.setattr(chain, "cost_of", cost)
    problem = SimpleNamespace(n_eff=2000.0)  # a tie: within delta BIC 2, 0.1 % of the cost
    v, c, _, spans = chain.joint_refit(problem, CarDescription(), ["throttle_deadband"],
                                       {"throttle_deadband_mps": 0.25})
    near = 2 * chain.NEUTRAL_TOL * chain.CANDIDATES["throttle_deadband"].hi
    (lo, hi), = spans.values()
    assert lo == pytest.approx(near) and 0.29 < hi <= 0.3  # the bisection's resolution
    assert v["throttle_deadband_mps"] == pytest.approx(0.5 * (lo + hi)) and c < 0.511
    names, start = ["steering_gain", "throttle_deadband"], {"steering_gain": 0.9, "throttle_deadband_mps": 0.25}
    both, _, _, spans2 = chain.joint_refit(problem, CarDescription(), names, start, first="throttle_deadband")
    monkeypatch.setattr(chain, "TIE_DELTA_BIC", 0.0)  # exact ties only: the search's own answer
    searched, _, _, none = chain.joint_refit(problem, CarDescription(), names, start, first="throttle_deadband")
    assert list(spans2) == ["throttle_deadband_mps"] and both["throttle_deadband_mps"] == pytest.approx(0.155, abs=0.01)
    assert searched["throttle_deadband_mps"] > 0.29 and none == {}
    assert both["steering_gain"] == searched["steering_gain"] == pytest.approx(0.9, abs=0.01)  # pinned: not moved


def test_a_plateau_that_ends_short_of_neutral_is_found_to_its_ends(monkeypatch):
    """The cost is flat for deadbands 0.2-0.5 m/s (the bound) and rises below 0.2: the
    interval's ends are found within the bisection's resolution and its middle kept."""
    from types import SimpleNamespace

    import simrunner.workflows.gap.chain as chain

    def cost(problem, car):
        d = car.effects.throttle_deadband_mps
        return 1.0 + max(0.2 - d, 0.0) ** 2 * 100.0 - 1e-7 * d

    monkeypatch.setattr(chain, "cost_of", cost)
    v, _, _, spans = chain.joint_refit(SimpleNamespace(n_eff=2000.0), CarDescription(), ["throttle_deadband"],
                                       {"throttle_deadband_mps": 0.45})
    (lo, hi), = spans.values()
    assert 0.18 < lo < 0.21 and hi == 0.5 and v["throttle_deadband_mps"] == pytest.approx(0.5 * (lo + hi))


def test_a_plateau_found_by_an_earlier_refit_stays_reported_while_the_value_stays_in_it():
    """The earlier refit's interval stays with a parameter a later refit left inside it; a
    value that moved out drops it."""
    from simrunner.workflows.gap.chain import _carried

    old = {"throttle_deadband_mps": (0.01, 0.44)}
    assert _carried(old, {"throttle_deadband_mps": 0.225, "steering_gain": 1.1}, {}) == old
    assert _carried(old, {"throttle_deadband_mps": 0.45}, {}) == {}
    new = {"steering_gain": (1.02, 1.3)}
    assert _carried(old, {"throttle_deadband_mps": 0.225, "steering_gain": 1.02}, new) == {**old, **new}
