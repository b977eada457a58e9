"""Merged topic logs (simrunner.telemetry.sparse, read_log(merged=True)): each sensor fills its own
cells at its own rate; the log is read as one row per sample of the leading sensor."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from simrunner.telemetry.columns import column_map_from
from simrunner.telemetry.log import LogError, read_log
from simrunner.telemetry.sparse import GAP_FACTOR, command_steps, gap_limit_s, merge_rows


def _stamps(draw, n_min, n_max, t_end):
    n = draw(st.integers(n_min, n_max))
    gaps = draw(st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n))
    t = np.cumsum(gaps)
    return t / t[-1] * t_end


@st.composite
def merged_tables(draw):
    """A pose at its stamps, a speed sensor sampling a straight line v = a + b t at its own,
    commands sent at theirs: merged in time order, each row one message."""
    t_end = 10.0
    t_pose = _stamps(draw, 20, 60, t_end)
    t_speed = _stamps(draw, 20, 60, t_end) - draw(st.floats(0.0, 0.1))
    t_cmd = np.sort(draw(st.lists(st.floats(-0.5, t_end), min_size=2, max_size=10, unique=True)))
    cmds = draw(st.lists(st.floats(-2.0, 2.0), min_size=len(t_cmd), max_size=len(t_cmd)))
    a, b = draw(st.floats(-1.0, 1.0)), draw(st.floats(-0.2, 0.2))
    events = ([(t, 0, i) for i, t in enumerate(t_pose)] + [(t, 1, i) for i, t in enumerate(t_speed)]
              + [(t, 2, i) for i, t in enumerate(t_cmd)])
    events.sort(key=lambda e: (e[0], e[1]))
    n = len(events)
    cols = {k: np.full(n, np.nan) for k in ("x_m", "y_m", "yaw_rad", "speed_mps", "speed_cmd_mps", "steer_cmd_rad")}
    t = np.array([e[0] for e in events])
    for row, (tt, kind, _) in enumerate(events):
        if kind == 0:
            cols["x_m"][row], cols["y_m"][row], cols["yaw_rad"][row] = tt, 2 * tt, 0.1
        elif kind == 1:
            cols["speed_mps"][row] = a + b * tt
        else:
            cols["speed_cmd_mps"][row], cols["steer_cmd_rad"][row] = cmds[list(t_cmd).index(tt)], 0.0
    return {"t_s": t, **cols}, (t_pose, t_speed, t_cmd, cmds, a, b)


@settings(max_examples=60, deadline=None)
@given(merged_tables())
def test_merge_gives_one_row_per_pose_sample_with_held_commands_and_interpolated_sensors(table):
    values, (t_pose, t_speed, t_cmd, cmds, a, b) = table
    out, kept, notes = merge_rows(values)
    t = out["t_s"]
    assert np.all(np.diff(t) >= 0) and np.isin(t, t_pose).all()
    assert np.array_equal(values["t_s"][kept], t)
    for k, v in out.items():
        assert np.isfinite(v).all(), k
    # the speed sensor sampled a line: interpolated exactly, inside its own coverage only
    assert np.allclose(out["speed_mps"], a + b * t, atol=1e-9)
    assert (t >= t_speed[0] - 1e-12).all() and (t <= t_speed[-1] + 1e-12).all()
    assert notes == []  # the speed sensor covers the log: never dropped
    # the command in force is the last one sent at or before the row
    last = np.searchsorted(t_cmd, t, side="right") - 1
    assert (last >= 0).all() and np.array_equal(out["speed_cmd_mps"], np.asarray(cmds)[last])
    # every pose sample inside both coverages is kept (when the speed sensor has no hole; it
    # covers nearly all of the log)
    steps = np.diff(t_speed)
    if steps.max() <= gap_limit_s(steps) and not notes:
        inside = (t_pose >= max(t_speed[0], t_cmd[0])) & (t_pose <= t_speed[-1])
        assert len(t) == np.count_nonzero(inside)


@settings(max_examples=60, deadline=None)
@given(merged_tables())
def test_every_command_is_kept_at_its_own_stamp(table):
    """The commands sent between two leading rows are not lost: ``command_steps`` gives each
    at its stamp, and at every row the last one at or before it is the row's command."""
    values, (t_pose, t_speed, t_cmd, cmds, a, b) = table
    steps = command_steps(values)
    assert np.array_equal(steps["t_s"], t_cmd) and np.array_equal(steps["speed_cmd_mps"], cmds)
    assert (steps["steer_cmd_rad"] == 0.0).all() and "coast" not in steps
    out, _, _ = merge_rows(values)
    last = np.searchsorted(steps["t_s"], out["t_s"], side="right") - 1
    assert np.array_equal(steps["speed_cmd_mps"][last], out["speed_cmd_mps"])


def test_command_steps_hold_each_column_and_start_where_all_are_known():
    nan = np.nan
    values = {"t_s": np.array([0.0, 0.1, 0.2, 0.2, 0.3, 0.4]),
              "x_m": np.array([nan, 0.0, nan, nan, nan, 1.0]), "y_m": np.array([nan, 0.0, nan, nan, nan, 0.0]),
              "yaw_rad": np.array([nan, 0.0, nan, nan, nan, 0.0]),
              "speed_cmd_mps": np.array([1.0, nan, 2.0, 3.0, nan, nan]),
              "steer_cmd_rad": np.array([nan, nan, nan, 0.1, 0.2, nan]),
              "coast": np.array([0.0, nan, nan, nan, 1.0, nan])}
    steps = command_steps(values)
    # 0.0: steering unknown yet; 0.2 twice: the later row counts; 0.3: the steering and coast
    assert list(steps["t_s"]) == [0.2, 0.3]
    assert list(steps["speed_cmd_mps"]) == [3.0, 3.0] and list(steps["steer_cmd_rad"]) == [0.1, 0.2]
    assert steps["coast"].dtype == bool and list(steps["coast"]) == [False, True]
    dense = {"t_s": np.arange(3.0), "speed_cmd_mps": np.ones(3), "steer_cmd_rad": np.zeros(3)}
    assert command_steps(dense) is None


def test_a_dense_log_is_returned_as_it_is():
    values = {"t_s": np.arange(5.0), "speed_mps": np.ones(5), "speed_cmd_mps": np.ones(5),
              "steer_cmd_rad": np.zeros(5), "data_text": ("",) * 5}
    out, kept, notes = merge_rows(values)
    assert out is values and notes == [] and list(kept) == list(range(5))


@settings(max_examples=150, deadline=None)
@given(st.floats(0.001, 0.2), st.floats(1.0, 3.0), st.integers(40, 400), st.floats(0.0, 0.05),
       st.integers(0, 2**31 - 1))
def test_a_hole_is_found_whatever_the_streams_rhythm(step_s, spread, n, hole_share, seed):
    """A stream's steps vary by up to ``spread`` (regular, jittery, irregular stamps); holes
    take under a tenth of its steps. Every hole longer than GAP_FACTOR times its longest
    normal step is beyond the limit; no normal step is."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(step_s, spread * step_s, n)
    holes = rng.choice(n, int(hole_share * n), replace=False)
    steps[holes] = GAP_FACTOR * spread * step_s * rng.uniform(1.01, 20.0, holes.size)
    limit = gap_limit_s(steps)
    normal = np.setdiff1d(np.arange(n), holes)
    assert (steps[holes] > limit).all() and (steps[normal] <= limit).all()


def test_the_hole_limit_follows_the_streams_own_long_interval():
    assert gap_limit_s(np.full(100, 0.02)) == pytest.approx(GAP_FACTOR * 0.02)  # regular: 5 steps
    # a controller that logs when it acts, at a 50-Hz tick with probability 0.6: steps of
    # 1, 2, 3, ... ticks; a 0.12-s step is part of its rhythm (one in a hundred), not a hole
    rng = np.random.default_rng(3)
    ticks = np.flatnonzero(rng.random(20000) < 0.6)
    steps = np.diff(ticks) * 0.02
    assert (steps >= 0.12 - 1e-9).sum() > 50
    assert gap_limit_s(steps) == pytest.approx(GAP_FACTOR * 0.06)
    # a logger writing bursts: four samples 1 ms apart, then 50 ms
    bursts = np.tile([0.001, 0.001, 0.001, 0.001, 0.05], 100)
    assert gap_limit_s(bursts) == pytest.approx(GAP_FACTOR * 0.05)
    assert gap_limit_s(np.zeros(3)) == 0.0 and gap_limit_s(np.zeros(0)) == 0.0


def test_a_gap_of_the_other_sensor_leaves_its_rows_out():
    t = np.arange(0.0, 10.0, 0.1)
    speed = np.where(np.arange(t.size) % 2 == 0, 1.0, np.nan)  # every second row, 0.2 s apart
    speed[(t > 4.0) & (t < 6.05)] = np.nan  # a 2-s hole: 10x its interval
    x = np.where(np.arange(t.size) % 2 == 1, t, np.nan)
    values = {"t_s": t, "x_m": x, "y_m": 0 * x, "yaw_rad": 0 * x, "speed_mps": speed,
              "speed_cmd_mps": np.where(t < 0.15, 1.0, np.nan), "steer_cmd_rad": np.zeros(t.size)}
    out, _, notes = merge_rows(values)
    assert notes == []
    assert not ((out["t_s"] > 4.0) & (out["t_s"] < 6.0)).any()
    assert (out["t_s"] < 4.0).any() and (out["t_s"] > 6.0).any()
    assert (out["speed_cmd_mps"] == 1.0).all()  # a command holds however long


# -- read_log(merged=True) -----------------------------------------------------------------
ROS_EXPORT = """\
time,pose.x,pose.y,pose.qx,pose.qy,pose.qz,pose.qw,odom.vx,imu.wz,cmd.V,cmd.delta
100.00,,,,,,,,,1.5,0.1
100.01,0.00,0.0,0,0,0,1,,,,
100.02,,,,,,,1.00,,,
100.03,,,,,,,,5.7,,
100.05,0.02,0.0,0,0,0,1,,,,
100.06,,,,,,,1.20,nan,,
100.07,,,,,,,,11.4,,
100.08,,,,,,,,,2.0,-0.1
100.09,0.04,0.0,0,0,0,1,,,,
100.10,,,,,,,1.40,,,
100.11,,,,,,,,5.7,,
"""
MAP = ['t_s=time', 'x_m=pose.x', 'y_m=pose.y', 'yaw_rad={quaternion = ["pose.qx", "pose.qy", "pose.qz", "pose.qw"]}',
       'speed_mps=odom.vx', 'yaw_rate_radps={column = "imu.wz", unit = "deg/s"}', 'speed_cmd_mps=cmd.V',
       'steer_cmd_rad=cmd.delta']


def test_read_a_merged_ros_export_through_a_mapping(tmp_path):
    path = tmp_path / "export.csv"
    path.write_text(ROS_EXPORT)
    log = read_log(path, columns=column_map_from(None, MAP), merged=True)
    # pose rows 100.05 and 100.09 (100.01 lies before the first speed sample)
    assert list(log.t_s) == [100.05, 100.09]
    assert np.allclose(log.speed_mps, [1.0 + 0.2 * 3 / 4, 1.2 + 0.2 * 3 / 4])
    assert np.allclose(log.yaw_rate_radps, np.radians([5.7 + 5.7 * 2 / 4, 11.4 - 5.7 * 2 / 4]))
    assert list(log.speed_cmd_mps) == [1.5, 2.0] and list(log.steer_cmd_rad) == [0.1, -0.1]
    # the commands also at their own stamps (a replay applies 100.08's between the rows)
    steps = log.command_steps
    assert list(steps.t_s) == [100.00, 100.08] and list(steps.steer_cmd_rad) == [0.1, -0.1]
    assert log.subset(np.array([1])).command_steps is steps and log.with_columns().command_steps is steps
    assert log.with_columns(steer_cmd_rad=-log.steer_cmd_rad).command_steps is None  # would not match the rows
    # strict reading still refuses the empty cells, naming the first
    with pytest.raises(LogError, match=r"export.csv:2: column 'pose.x': expected a number \(got ''\)"):
        read_log(path, columns=column_map_from(None, MAP))


def test_merged_log_errors_name_the_line(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("t_s,x_m,y_m,yaw_rad,speed_cmd_mps,steer_cmd_rad\n0.0,,,,1,0\n0.1,0,0,0,,\n,0.1,0,0,,\n")
    with pytest.raises(LogError, match=r"m.csv:4: column 't_s': expected a time stamp in every row"):
        read_log(path, merged=True)
    path.write_text("t_s,x_m,y_m,yaw_rad,speed_cmd_mps,steer_cmd_rad\n0.0,,,,1,0\n0.2,0,0,0,,\n0.1,0.1,0,0,,\n")
    with pytest.raises(LogError, match=r"m.csv:4: column 't_s': expected the rows of a merged log in time order"):
        read_log(path, merged=True)
    # empty cells with no pose and no speed sensor to lead
    path.write_text("t_s,x_m,speed_cmd_mps,steer_cmd_rad\n0.0,,1,0\n0.1,0,,\n")
    with pytest.raises(LogError, match=r"m.csv:2: column 'x_m': an empty cell \(a merged log\): expected a pose"):
        read_log(path, merged=True)
    # a computed value that is not finite is still refused where its inputs are present
    path.write_text("t,px,cmd,d\n0.0,,1,0\n0.1,0,,\n0.2,1,0,0\n")
    with pytest.raises(LogError, match=r"m.csv:4: speed_cmd_mps = '1 / cmd'"):
        read_log(path, columns=column_map_from(None, ["t_s=t", "x_m=px", "y_m=0", "yaw_rad=0",
                                                      "speed_cmd_mps=1 / cmd", "steer_cmd_rad=d"]), merged=True)


def test_the_gap_cli_reads_a_merged_log(tmp_path):
    """The CLI reads merged logs as they come (bad input still one line, exit 2)."""
    from click.testing import CliRunner

    from simrunner.cli.gap import gap

    path = tmp_path / "export.csv"
    path.write_text(ROS_EXPORT)
    res = CliRunner().invoke(gap, [str(path), "-o", str(tmp_path / "out"), "--max-effects", "0",
                                   *[a for m in MAP for a in ("--column", m)]])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert "expected at least" in res.output  # read; too short for the workflow
    assert not (tmp_path / "out").exists()


def test_review_cases_of_merged_logs(tmp_path):
    """A pose split over rows, a late gyro, a bad flag held on, other spellings of 'empty'."""
    path = tmp_path / "m.csv"
    head = "t_s,x_m,y_m,yaw_rad,yaw_rate_radps,speed_cmd_mps,steer_cmd_rad,coast\n"
    # position and heading never in one row
    rows = "".join(f"{k * 0.02:.2f},{k * 0.01:.3f},0,,,1,0,0\n{k * 0.02 + 0.01:.2f},,,0,,,,\n" for k in range(100))
    path.write_text(head + rows)
    with pytest.raises(LogError, match=r"m.csv:2: columns x_m, y_m, yaw_rad never share a row"):
        read_log(path, merged=True)
    # a gyro that starts at 15 s of 20: left out with a warning, the 20 s kept
    rows = "".join(f"{k * 0.02:.2f},{k * 0.01:.3f},0,0,{'0.1' if k * 0.02 >= 15 else 'NA'},1,0,-nan\n"
                   for k in range(1000))
    path.write_text(head + rows)
    with pytest.warns(UserWarning, match=r"column 'yaw_rate_radps' covers only t = 15.000..19.980 s"):
        log = read_log(path, merged=True)
    assert len(log) == 1000 and log.yaw_rate_radps is None and log.coast is None
    # a flag is checked on the row that logged it, not the pose row it is held into
    path.write_text(head + "0.00,,,,,1,0,0\n0.01,0,0,0,,,,\n0.02,,,,,1,0,2\n0.03,0.1,0,0,,,,\n")
    with pytest.raises(LogError, match=r"m.csv:4: column 'coast': expected 0 or 1"):
        read_log(path, merged=True)
    # every pose sample before the first command
    path.write_text(head + "0.00,0,0,0,,,,\n0.01,0.1,0,0,,,,\n0.02,,,,,1,0,0\n")
    with pytest.raises(LogError, match=r"no sample of the pose .* comes after the first command"):
        read_log(path, merged=True)
