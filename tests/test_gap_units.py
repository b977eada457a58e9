"""Gap workflow parts that need no physics: log checks, regimes, statistics, replay and
fit machinery on a fast kinematic stand-in simulator."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from simrunner.run.log import FORMAT_LINE, LogError, RunLog, log_from_columns, read_log, write_log
from simrunner.workflows.gap import LogError as GapLogError
from simrunner.workflows.gap.fit import CANDIDATES, FitResult, Problem, choose, cost_of, fit_effect, nominal_scales
from simrunner.workflows.gap.logs import MEASURED_COLUMNS, check_measured, derive
from simrunner.workflows.gap.regimes import REGIMES, format_stats, residual_stats, segment
from simrunner.workflows.gap.replay import make_windows, replay, residuals, split_windows
from vehicle.description import CarDescription


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


def simulate(car, noise_rng=None, duration_s=12.0):
    """A 'measured' log from the kinematic sim (truth at 1 ms, logged at 100 Hz)."""
    t, v_cmd, s_cmd = commands(duration_s)
    sim = KinematicSim(car, 0.001)
    sim.set_state(Pose2(), 1.0, 0.0, 0.0)
    rows = []
    for i in range(t.size):
        p = sim.pose
        rows.append((t[i], p.x_m, p.y_m, p.yaw_rad, sim.speed_mps, v_cmd[i], s_cmd[i]))
        sim.set_command(v_cmd[i], s_cmd[i])
        sim.step(10)
    data = np.array(rows)
    if noise_rng is not None:
        sig = np.array([0, 0.005, 0.005, 0.005, 0.02, 0, 0])
        data = data + noise_rng.normal(size=data.shape) * sig
    return log_from_columns({c: data[:, k] for k, c in enumerate(MEASURED_COLUMNS)}, "<kin>")


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
    with pytest.raises(LogError, match="missing: x_m, y_m, yaw_rad, speed_cmd_mps, steer_cmd_rad"):
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


def _problem(true_car, nominal_car, seed=1):
    log = simulate(true_car, np.random.default_rng(seed))
    d = derive(log, nominal_car.chassis.wheelbase_m)
    fit_w, _ = split_windows(make_windows(log))
    res = residuals(log, d, replay(nominal_car, log, d, fit_w, dt_s=0.002, sim_factory=kin_factory))
    return Problem(nominal_car, log, d, tuple(fit_w), nominal_scales(log, res, fit_w), 0.002, kin_factory)


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


def test_choose_applies_thresholds():
    def fr(name, dbic, imp):
        return FitResult(name, {CANDIDATES[name].field: 0.0}, 1.0, -dbic, dbic, imp, 3)
    assert choose([fr("drag", 500.0, 0.5)]).effect == "drag"
    assert choose([fr("drag", 5.0, 0.5)]) is None
    assert choose([fr("drag", 500.0, 0.001)]) is None
    assert choose([]) is None


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
