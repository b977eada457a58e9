"""Wheel encoders and the IMU (issue 50 item 2): the car file's [encoders] and [imu], their
models (simrunner.sensors.imu) and the Spinner's get_encoder / get_gyro / get_accel in Python
and C."""
from __future__ import annotations

import dataclasses
import math
import textwrap
import tomllib

import numpy as np
import pytest

from simrunner.errors import CommandError
from simrunner.run.runner import drive
from simrunner.car.physics import CarSim
from simrunner.sensors.imu import Encoders, Imu, ImuNoise
from vehicle.description import CarDescription, CarDescriptionError, car_from_dict

SENSORS = car_from_dict(tomllib.loads("[encoders]\n[imu]\n"))
R = CarDescription().wheels.radius_m


def test_the_car_file_declares_encoders_and_an_imu():
    assert CarDescription().encoders is None and CarDescription().imu is None  # the default car has none
    assert SENSORS.encoders.lines_per_rev == 512 and SENSORS.encoders.counting == "x4"
    assert SENSORS.imu.gyro_noise_density_radps_rthz == pytest.approx(math.radians(0.025), rel=1e-3)
    assert car_from_dict(tomllib.loads(SENSORS.to_toml())) == SENSORS
    assert car_from_dict(SENSORS.to_dict()) == SENSORS
    assert "[encoders]" not in CarDescription().to_toml()
    text = "[encoders]\ncounting = \"x3\"\n"
    with pytest.raises(CarDescriptionError, match=r"car.toml:2: encoders.counting = 'x3': expected one of"):
        car_from_dict(tomllib.loads(text), "car.toml", text)
    text = "[imu]\nrate_hz = 0\n"
    with pytest.raises(CarDescriptionError, match=r"car.toml:2: imu.rate_hz = 0: expected a value in"):
        car_from_dict(tomllib.loads(text), "car.toml", text)


@pytest.mark.parametrize("counting, per_line", [("x4", 4), ("x2", 2), ("x1", 1)])
def test_quadrature_counts_are_signed_whole_counts(counting, per_line):
    enc = Encoders(dataclasses.replace(SENSORS.encoders, counting=counting))
    turn = 2 * math.pi
    assert enc.count("RL", [0, 0, turn, -turn]) == 512 * per_line
    assert enc.count("RR", [0, 0, turn, -turn]) == -512 * per_line
    assert enc.count(2, [0, 0, 0.5 * turn / (512 * per_line), 0]) == 0  # half a count: not yet one


def test_a_single_channel_counts_up_whichever_way_the_wheel_turns():
    enc = Encoders(dataclasses.replace(SENSORS.encoders, counting="single", lines_per_rev=10))
    turn = 2 * math.pi
    assert enc.count("RL", [0, 0, turn, 0]) == 10
    assert enc.count("RL", [0, 0, 0.0, 0]) == 20  # back again: still counting up


def test_encoder_misuse_is_the_controllers_error():
    enc = Encoders(SENSORS.encoders)
    with pytest.raises(CommandError, match=r"get_encoder\('FL'\): the car's encoders are on its rear wheels"):
        enc.count("FL", [0] * 4)
    with pytest.raises(CommandError, match=r"expected a wheel, one of FL, FR, RL, RR"):
        enc.count("left", [0] * 4)
    with pytest.raises(CommandError, match=r"the car has no encoders \(add \[encoders\]"):
        Encoders(None).count("RL", [0] * 4)
    with pytest.raises(CommandError, match=r"get_gyro\(\): the car has no IMU"):
        Imu(None, 0).sample("get_gyro", 0.0, lambda: None)
    for wheel in (True, 2.0, 3.0, [2], "fl", 0, "FR"):  # not wheels, or wheels without an encoder
        with pytest.raises(CommandError, match=r"get_encoder\("):
            enc.count(wheel, [0] * 4)


def test_every_spelling_of_a_wheel_reads_its_encoder():
    enc = Encoders(SENSORS.encoders)
    angles = [0.0, 0.0, 1.0, -2.0]
    assert {enc.count(w, angles) for w in ("RL", "rl", "Rl", 2, np.int64(2))} == {math.floor(512 * 4 / (2 * math.pi))}
    assert {enc.count(w, angles) for w in ("RR", "rr", "rR", 3, np.int32(3))} == {math.floor(-2 * 512 * 4 / (2 * math.pi))}


def test_the_imu_adds_noise_bias_and_drift_rounds_and_clips():
    spec = SENSORS.imu
    truth = lambda: (np.zeros(3), np.array([0.0, 0.0, 9.81]))  # noqa: E731  at rest
    imu = Imu(spec, seed=3)
    samples = np.array([imu.sample("get_gyro", k / spec.rate_hz, truth) for k in range(2000)])
    noise = samples.std(axis=0)
    want = spec.gyro_noise_density_radps_rthz * math.sqrt(spec.rate_hz / 2)
    assert noise[:3] == pytest.approx([want] * 3, rel=0.15)
    want_a = spec.accel_noise_density_mps2_rthz * math.sqrt(spec.rate_hz / 2)
    assert noise[3:] == pytest.approx([want_a] * 3, rel=0.25)  # a few counts of 4.8 mm/s^2
    assert np.allclose(np.round(samples[:, 3:] / spec.accel_lsb_mps2) * spec.accel_lsb_mps2, samples[:, 3:])
    bias = samples.mean(axis=0) - [0, 0, 0, 0, 0, 9.81]
    assert 0.001 < abs(bias[2]) < 4 * spec.gyro_bias_std_radps  # this device's offset
    again = Imu(spec, seed=4)  # another run, the same device: the same offsets, other noise
    other = np.array([again.sample("get_gyro", k / spec.rate_hz, truth) for k in range(2000)])
    assert np.allclose(other.mean(axis=0), samples.mean(axis=0), atol=0.01)
    assert not np.array_equal(other, samples)
    # a reading depends on when it is taken, not on what was asked before; held within a sample
    fresh = Imu(spec, seed=3)
    assert np.array_equal(fresh.sample("get_gyro", 1999 / spec.rate_hz, truth), samples[-1])
    calls = []
    held = Imu(spec, seed=3)
    first = held.sample("get_gyro", 0.0, lambda: calls.append(1) or truth())
    assert np.array_equal(held.sample("get_accel", 0.4 / spec.rate_hz, lambda: calls.append(1) or truth()), first)
    assert calls == [1]
    spun = Imu(dataclasses.replace(spec, gyro_range_radps=1.0), seed=3)
    assert spun.sample("get_gyro", 0.0, lambda: (np.array([0, 0, 5.0]), np.zeros(3)))[2] == 1.0


def test_a_run_reads_its_wheels_and_turn():
    got = []

    def main(s):
        s.set_speed_and_servo(1.0, 0.0)
        s.sleep(1.5)
        got.append((s.get_encoder("RL"), s.get_encoder("RR"), s.get_position()[0], s.get_accel()))
        s.set_speed_and_servo(1.0, 0.3)
        s.sleep(1.5)
        got.append((s.get_gyro(), s.get_accel(), s.get_speed()))

    r = drive(main, track="floor", car=SENSORS, time_limit_s=5)
    assert r.outcome in ("finished", "controller_returned", "returned"), r.message
    (rl, rr, x, accel), (gyro, accel_turn, v) = got
    counts_per_m = 2048 / (2 * math.pi * R)
    assert rl == pytest.approx(x * counts_per_m, rel=0.02) and rr == pytest.approx(rl, rel=0.01)
    assert accel[2] == pytest.approx(9.81, abs=0.4) and abs(accel[0]) < 0.4  # steady speed, flat floor
    yaw_rate = v * math.tan(0.3) / CarDescription().chassis.wheelbase_m
    assert gyro[2] == pytest.approx(yaw_rate, rel=0.1)
    assert accel_turn[1] == pytest.approx(v * yaw_rate, rel=0.15)  # to the left, into the turn


def test_c_reads_the_encoders_and_the_imu(tmp_path):
    car = tmp_path / "car.toml"
    car.write_text("[encoders]\n[imu]\n")
    src = tmp_path / "probe.c"
    src.write_text(textwrap.dedent("""\
        #include <math.h>
        #include "spinner.h"
        int main(void) {
            double gx, gy, gz, ax, ay, az;
            spinner_set_speed_and_servo(1.0, 0.0);
            spinner_sleep(1.0);
            long long rl = spinner_get_encoder(SPINNER_WHEEL_RL);
            spinner_get_gyro(&gx, &gy, &gz);
            spinner_get_accel(&ax, &ay, NULL);
            spinner_get_accel(NULL, NULL, &az);
            if (rl < 5000 || fabs(gz) > 0.2 || fabs(az - 9.81) > 0.5) return 1;
            spinner_add_textf("rl %lld", rl);
            spinner_get_encoder(SPINNER_WHEEL_FL);
            return 0;
        }
        """))
    r = drive(str(src), track="floor", car=car, time_limit_s=5.0)
    assert r.outcome == "controller_error" and "on its rear wheels" in r.message, r.message


def test_cpp_reads_an_encoder_by_name_and_a_wrong_name_points_at_the_call(tmp_path):
    """``getEncoder("rl")`` reads what ``getEncoder(SPINNER_WHEEL_RL)`` reads (names as in
    Python); a name that is no wheel throws, and the run's outcome names the controller's line
    that called it, not the header that threw."""
    car = tmp_path / "car.toml"
    car.write_text("[encoders]\n")
    src = tmp_path / "probe.cpp"
    src.write_text(textwrap.dedent("""\
        #include "spinner.hpp"
        int main() {
            Spinner s;
            s.setSpeedAndServo(1.0, 0.0);
            s.sleep(0.5);
            long long by_index = s.getEncoder(SPINNER_WHEEL_RL);
            long long by_name = s.getEncoder("rl");  // one physics step later
            if (by_name < by_index || by_name > by_index + 40 || by_index < 2000) return 1;
            s.getEncoder(std::string("XL"));
            return 0;
        }
        """))
    r = drive(str(src), track="floor", car=car, time_limit_s=5.0)
    assert r.outcome == "controller_error", r.message
    assert "probe.cpp:9: SIGABRT" in r.message and "spinner.hpp" not in r.message, r.message


def test_the_run_log_records_the_encoders_and_the_imu_without_changing_the_readings(tmp_path):
    def run(csv):
        got = []

        def main(s):
            s.set_speed_and_servo(1.0, 0.2)
            for _ in range(30):
                s.get_image(s.line_row)
                got.append((s.get_encoder("RL"), s.get_gyro(), s.get_accel()))

        r = drive(main, track="floor", car=SENSORS, time_limit_s=5, csv=csv)
        return r, got

    logged, read_logged = run(tmp_path / "s.csv")
    plain, read_plain = run(None)
    assert read_logged == read_plain  # the log's copies do not take the controller's samples
    header = (tmp_path / "s.csv").read_text().splitlines()[1].split(",")
    assert header[-9:] == ["enc_rl", "enc_rr", "gyro_x_radps", "gyro_y_radps", "gyro_z_radps",
                           "accel_x_mps2", "accel_y_mps2", "accel_z_mps2", "data_text"]
    log = logged.log
    assert log.enc_fl is None and log.enc_rl[-1] > log.enc_rl[5] > 0
    turning = log.yaw_rate_radps[10:] > 0.5
    assert np.allclose(log.gyro_z_radps[10:][turning], log.yaw_rate_radps[10:][turning], atol=0.15)
    assert np.abs(log.accel_z_mps2 - 9.81).max() < 0.5


def test_two_copies_sharing_one_imu_noise_read_what_separate_copies_read():
    """The run log's IMU and the controller's share one ImuNoise (each block drawn once): their
    samples, taken interleaved across blocks (1024 samples each), are those of separate copies."""
    spec = dataclasses.replace(SENSORS.imu, gyro_bias_walk_radps_rts=0.01, accel_bias_walk_mps2_rts=0.05)
    truth = lambda: ((0.01, -0.02, 0.5), (0.3, -0.1, 9.7))  # noqa: E731
    noise = ImuNoise(spec, seed=5)
    log, ctl = Imu(spec, 5, noise), Imu(spec, 5, noise)
    alone_log, alone_ctl = Imu(spec, 5), Imu(spec, 5)
    times = [k * 0.0175 for k in range(700)]  # 3.5 blocks at 200 Hz
    shared = [(log.sample("log", t, truth), ctl.sample("get_gyro", t + 0.006, truth)) for t in times]
    separate = [(alone_log.sample("log", t, truth), alone_ctl.sample("get_gyro", t + 0.006, truth)) for t in times]
    assert shared == separate
    late = Imu(spec, 5)  # a copy whose first read is in block 3: the walk to there is the same
    assert late.sample("get_gyro", times[-1], truth) == shared[-1][0]
    # unrounded, a reading in block 2 is the one of the implementation that drew each copy's
    # blocks itself (commit 6554658), bit for bit
    raw = Imu(dataclasses.replace(spec, gyro_lsb_radps=0.0, accel_lsb_mps2=0.0), 5)
    assert raw.sample("get_gyro", 5.2, truth)[0] == 0.026918908560261683
    assert raw.sample("get_gyro", 12.2475, truth) == (
        -0.0011512342422857237, -0.05579837214758375, 0.5451617310053471, 0.3486569350855944,
        -0.1593934656674018, 9.847697736752059)


def test_the_imu_reader_is_the_engine_s_point_acceleration_in_the_body_frame():
    """CarSim.imu_reader(point)() is bit for bit the chassis's angular velocity, and dart's
    acceleration of the point (getLinearAcceleration(point): world-relative, world axes), less
    gravity, turned into the body frame, to rounding (the reader carries the chassis's
    generalized accelerations to the point itself); wheel_angle_rad(i) is wheel_angles_rad()[i]."""
    sim = CarSim(SENSORS, dt_s=0.002)
    point = (0.1, 0.02, 0.05)
    read = sim.imu_reader(point)
    sim.set_command(1.5, 0.3, 1.0)
    for n in (1, 5, 40, 150):
        sim.step(n)
        assert sim.wheel_angle_rad(2) == sim.wheel_angles_rad()[2] and sim.wheel_angle_rad(0) != 0.0
        gyro, force = read()
        q = sim._skel.getPositions()
        r = dart_rotation(q[:3])
        dq = sim._skel.getVelocities().tolist()
        a = sim._body.chassis.getLinearAcceleration(np.array(point)).tolist()
        a[2] += 9.81
        want_g = tuple(r[0][j] * dq[0] + r[1][j] * dq[1] + r[2][j] * dq[2] for j in range(3))
        want_f = tuple(r[0][j] * a[0] + r[1][j] * a[1] + r[2][j] * a[2] for j in range(3))
        assert gyro == want_g
        assert max(abs(f - w) for f, w in zip(force, want_f)) < 1e-9  # m/s^2; an LSB is ~1e-3
        assert sim.imu_truth(point) == (gyro, force)
    assert abs(force[1]) > 0.1 and abs(gyro[2]) > 0.1  # turning: a yaw rate and a sideways force


def dart_rotation(rotation_vector):
    import dartpy

    return dartpy.math.expMapRot(rotation_vector).tolist()


@pytest.mark.parametrize("counting", ["x4", "single"])
def test_an_encoder_read_from_the_car_is_its_count_of_the_wheel_angles(counting):
    spec = dataclasses.replace(SENSORS.encoders, counting=counting, wheels="all")
    sim = CarSim(SENSORS, dt_s=0.002)
    sim.set_command(1.0, 0.2, 0.0)
    read, counted = Encoders(spec), Encoders(spec)
    got, want = [], []
    for n in (3, 50, 1, 200):
        sim.step(n)
        for wheel in ("RL", "fr", 3):
            got.append(read.read(wheel, sim))
            want.append(counted.count(wheel, sim.wheel_angles_rad()))
    assert got == want and got[-1] > 100
