"""Gap workflow end to end on synthetic logs with a hidden effect (real physics).

Logs are parts of the excitation plan (~20 s instead of 67 s) to keep the file within its
time budget; the first part (straights, step steers, circles) hides lateral effects, the
part from 44 s (speed steps, brake, straight at 2 m/s, coast) longitudinal ones.

The runs fit in this process (``jobs=1``): a fit's result does not depend on ``jobs``
(:mod:`simrunner.workflows.gap.fit`), and under ``pytest -n 2`` a pool of two more processes
only adds CPU (5-10 % measured).
The worker pool is tested where it is the point: ``short_run`` and the --screen test (jobs 2
against the CLI's --jobs 1), and test_gap_live's runs of ``simrunner gap --jobs 2``.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli.gap import gap
from simrunner.workflows.gap.fit import CANDIDATES
from simrunner.telemetry.log import read_log, write_log
from simrunner.workflows.gap.report import GapError, summary_text, write_outputs
from simrunner.workflows.gap.workflow import run_gap
from simrunner.workflows.gap.synth import make_measured_log
from vehicle.description import load_car

LONGITUDINAL = ["motor_lag", "command_latency", "throttle_deadband", "rolling_resistance", "drag"]
PART_LATERAL = dict(start_s=0.0, duration_s=20.0)
PART_LONGITUDINAL = dict(start_s=44.0, duration_s=16.0)


@pytest.fixture(scope="module")
def offset_run():
    log, truth = make_measured_log("steering_offset", rng=np.random.default_rng(11), value=-0.03, **PART_LATERAL)
    return log, truth, run_gap(log, jobs=1)


def test_a_held_out_signal_the_kept_effects_make_worse_is_said_so(offset_run):
    """The chain keeps what shrinks the held-out gap over all signals; when a signal's own
    RMSE grows beyond the held-out test's noise level (its mean square by more than
    settings.held_improvement_min) the effects trade it for the others and the report says so (a
    sloped floor's coasting fitted as drag: docs/gap.md). Within that level, or with nothing
    kept, it says nothing."""
    import dataclasses

    from simrunner.workflows.gap.settings import SETTINGS
    from simrunner.workflows.gap.report import summary_text, worse_signals

    _, _, result = offset_run
    assert result.signals_worse == {} and "trade these signals" not in summary_text(result)
    before = result.rmse_before
    edge = math.sqrt(1.0 + SETTINGS.held_improvement_min)
    traded = dataclasses.replace(result, rmse_after={**result.rmse_after, "speed_mps": 1.10 * before["speed_mps"],
                                                     "yaw_rate_radps": 0.999 * edge * before["yaw_rate_radps"]})
    assert traded.signals_worse == {"speed_mps": pytest.approx(1.10)}
    assert traded.to_json()["signals_worse"] == {"speed_mps": pytest.approx(1.10)}
    text = summary_text(traded)
    assert "WARNING: the kept effects make the held-out speed_mps RMSE 10% larger" in text
    assert ("left unexplained: nothing well above the sensor noise in any regime, but the kept effects trade "
            "signals" in text) == (not traded.leftovers)
    assert dataclasses.replace(traded, effects=[]).signals_worse == {}
    assert worse_signals({"a": 1.0, "b": 0.0, "c": 1.0}, {"a": float("nan"), "b": 1.0, "c": 1.001 * edge}) \
        == {"c": pytest.approx(1.001 * edge)}


def test_hidden_steering_offset_is_named_and_fitted(offset_run):
    _, truth, result = offset_run
    assert result.effect == "steering_offset"
    assert result.parameters["steering_offset_rad"] == pytest.approx(truth.value, rel=0.10)
    assert result.rmse_after["position_m"] < 0.5 * result.rmse_before["position_m"]
    assert result.rmse_after["yaw_rad"] < 0.5 * result.rmse_before["yaw_rad"]
    # every catalogue effect the car can have is in the ranking, best first; the others are said
    assert [r.effect for r in result.ranking][0] == "steering_offset"
    assert sorted(r.effect for r in result.ranking) == sorted(set(CANDIDATES) - set(result.not_applicable))
    assert list(result.not_applicable) == ["tyre_stiffness", "tyre_balance", "tyre_relaxation"]


def test_effect_free_log_gives_none():
    log, _ = make_measured_log(None, rng=np.random.default_rng(12), **PART_LATERAL)
    result = run_gap(log, jobs=1)
    assert result.effect == "none" and result.parameters == {}
    assert result.rmse_after == result.rmse_before


@pytest.mark.parametrize("effect, value, field", [("motor_lag", 0.3, "motor_lag_s"),
                                                  ("drag", 0.3, "drag_coeff_kgpm")])
def test_hidden_longitudinal_effect_is_named(effect, value, field):
    log, truth = make_measured_log(effect, rng=np.random.default_rng(13), value=value, **PART_LONGITUDINAL)
    # this part of the plan coasts from one speed only, which cannot tell drag from rolling
    # resistance (the whole plan coasts from two speeds): offer one of the two
    candidates = [n for n in LONGITUDINAL if n != ("rolling_resistance" if effect == "drag" else "drag")]
    result = run_gap(log, jobs=1, effects=candidates)
    assert result.effect == effect
    # one 16-s part: which 2-s windows are fitted moves the value (drag 0.300 -> 0.335 with
    # the windows on the log's time grid, within 10 % before); the bench's median is the target
    assert result.parameters[field] == pytest.approx(value, rel=0.15)
    assert result.rmse_after["speed_mps"] < result.rmse_before["speed_mps"]


def test_summary_says_which_effects_the_logs_cannot_tell_apart(offset_run):
    """A step that recorded a look-alike (``Step.alike``): the answer names both, and the
    step's line gives the figures."""
    import dataclasses

    from simrunner.workflows.gap.chain import Alike

    _, _, result = offset_run
    assert "cannot tell them apart" not in summary_text(result)
    step = dataclasses.replace(result.chain.steps[0], alike=(Alike("steering_gain", {"steering_gain": 0.9}, 0.73, 10),))
    chain = dataclasses.replace(result.chain, steps=(step,) + result.chain.steps[1:])
    text = summary_text(dataclasses.replace(result, chain=chain))
    answer = text.split("held-out gap")[0]
    assert "steering_offset or steering_gain: these logs cannot tell them apart (step 1" in answer
    assert "as good on these windows: steering_gain" in text and "z = +0.73 over 10 windows" in text
    # a look-alike the chain kept as well is no alternative to the kept one
    both = dataclasses.replace(result, effects=list(result.effects) + ["steering_gain"])
    assert "cannot tell them apart" not in summary_text(dataclasses.replace(both, chain=chain))


def test_report_folder_that_cannot_be_written_is_one_line_and_leaves_nothing(offset_run, tmp_path, monkeypatch):
    """A disk that fills while the folder is written: a GapError naming the folder, no
    half-written folder and no temporary one beside it."""
    import errno

    import simrunner.workflows.gap.plots as plots

    _, _, result = offset_run

    def full(*_a, **_k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(plots, "plot_regimes", full)
    with pytest.raises(GapError, match=r"gap: cannot write the output folder \(No space left on device\)") as info:
        write_outputs(result, tmp_path / "gap")
    assert "\n" not in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_a_log_faster_than_the_car_file_allows_is_warned_of(offset_run):
    """A log of another car run without its car file (an F1/10 log at 5 m/s on the default
    car's 3.1 m/s): the answer asks whether the car file is the car's."""
    _, _, result = offset_run
    assert "beyond the car file's top speed" not in summary_text(result)
    fastest = max(float(np.nanmax(np.abs(p.derived.speed_mps))) for p in result.parts)
    slow = dataclasses.replace(result.car, drive=dataclasses.replace(result.car.drive, max_speed_mps=fastest / 1.5))
    text = summary_text(dataclasses.replace(result, car=slow))
    answer = text.split("held-out gap")[0]
    assert f"WARNING: the logs reach {fastest:.3g} m/s, beyond the car file's top speed" in answer
    assert "(--car CAR.toml)" in answer


def test_report_folder(offset_run, tmp_path):
    _, truth, result = offset_run
    out = write_outputs(result, tmp_path / "gap")
    names = {p.name for p in out.iterdir()}
    assert {"report.json", "car.toml", "gap_before_after.png", "residuals_by_regime.png"} <= names
    rep = json.loads((out / "report.json").read_text())
    assert rep["effect"] == "steering_offset"
    assert set(rep["parameters"]) == {"steering_offset_rad"}
    for key in ("rmse_before", "rmse_after", "rmse_smoothed_before", "rmse_smoothed_after", "noise_rms"):
        assert set(rep[key]) == {"position_m", "yaw_rad", "speed_mps", "yaw_rate_radps"}
    # against the smoothed states the sensor noise no longer adds to the residuals
    for key in ("position_m", "yaw_rad"):
        assert rep["rmse_smoothed_after"][key] < rep["rmse_after"][key]
        assert rep["rmse_smoothed_after"][key] < 0.5 * rep["rmse_smoothed_before"][key]
    assert rep["noise_rms"]["position_m"] == pytest.approx(5e-3 * math.sqrt(2), rel=0.3)
    assert len(rep["ranking"]) == len(CANDIDATES) - len(rep["not_applicable"]) == 24
    assert rep["held_out_worse"] is False and rep["gap_after"] < rep["gap_before"]
    assert rep["signals_worse"] == {}  # the offset leaves the speed as it was and mends the rest
    assert rep["conventions_unchecked"] == {}  # pose, speed and gyro: every convention checked
    assert {"effect", "parameters", "bic", "delta_bic", "improvement"} <= set(rep["ranking"][0])
    car = load_car(out / "car.toml")
    assert car.effects.steering_offset_rad == pytest.approx(rep["parameters"]["steering_offset_rad"])
    # the fitted number says where it came from, not the default's "neutral"
    text = (out / "car.toml").read_text().splitlines()
    above = text[text.index(next(x for x in text if x.startswith("steering_offset_rad ="))) - 1]
    assert "Source: fitted by simrunner gap (steering_offset) on " in above and "held-out gap" in above
    assert f"standard error {rep['parameter_sigma']['steering_offset_rad']:.2g}" in above
    assert "neutral" not in above
    assert not list(tmp_path.glob(".gap.*"))  # no temporary folder left behind


def test_an_exchange_is_reported_in_text_and_json(offset_run):
    """The chain's exchanges (tables test in test_gap_units) reach the summary and report.json."""
    import dataclasses

    from simrunner.workflows.gap.chain import Swap
    from simrunner.workflows.gap.report import summary_text

    _, _, result = offset_run
    sw = Swap(1, "steering_offset", "steering_asymmetry", {"steering_asymmetry": 0.1}, 10.0, 8.0, 0.5, 0.4)
    chain = dataclasses.replace(result.chain, swaps=(sw,))
    assert chain.effects == ["steering_asymmetry"]
    swapped = dataclasses.replace(result, chain=chain)
    assert ("after step 1: steering_offset -> steering_asymmetry (exchanged, all refitted): fit cost 10 -> 8, "
            "held-out gap 0.5 -> 0.4") in summary_text(swapped)
    assert swapped.to_json()["swaps"] == [{"step": 1, "out": "steering_offset", "into": "steering_asymmetry",
                                           "parameters": {"steering_asymmetry": 0.1}, "cost_before": 10.0,
                                           "cost_after": 8.0, "held_gap_before": 0.5, "held_gap_after": 0.4,
                                           "spans": {}}]
    assert result.to_json()["swaps"] == []


def test_glitch_times_of_a_log_with_epoch_stamps_also_say_how_far_into_the_log(offset_run):
    """A log stamped in epoch (ROS) time lists its glitches as logged and as seconds into it."""
    import dataclasses

    from simrunner.workflows.gap.glitches import Glitch, GlitchKind
    from simrunner.workflows.gap.report import summary_text

    _, _, result = offset_run
    part = result.parts[0]
    t0 = 1650776487.0
    epoch = part.log.with_columns(t_s=part.log.t_s + t0)
    gap = Glitch(GlitchKind.TIME_GAP, t0 + 12.25, t0 + 12.6, "t_s", "no sample for 0.35 s")
    shifted = dataclasses.replace(result, parts=[dataclasses.replace(part, log=epoch, glitches=(gap,))])
    assert "t = 1650776499.250..1650776499.600 s (12.2 s into the log): time_gap (t_s)" in summary_text(shifted)
    # stamps from 0 (the log's own clock) need no second time
    plain = dataclasses.replace(result, parts=[dataclasses.replace(
        part, glitches=(Glitch(GlitchKind.TIME_GAP, 12.25, 12.6, "t_s", "no sample for 0.35 s"),))])
    assert "t = 12.250..12.600 s: time_gap (t_s)" in summary_text(plain)


def test_a_log_with_many_glitches_lists_twelve_and_says_how_many_more(offset_run):
    import dataclasses

    from simrunner.workflows.gap.glitches import Glitch, GlitchKind
    from simrunner.workflows.gap.report import summary_text

    _, _, result = offset_run
    part = result.parts[0]
    many = tuple(Glitch(GlitchKind.DUPLICATE, 1.0 + k, 1.0 + k, "t_s", "repeats the row before it")
                 for k in range(20))
    text = summary_text(dataclasses.replace(result, parts=[dataclasses.replace(part, glitches=many)]))
    assert "glitches kept out of the windows (20):" in text
    assert text.count("duplicate (t_s) repeats") == 12
    assert '... and 8 more (all of them: report.json, "glitches")' in text


# -- command line ------------------------------------------------------------------------
@pytest.mark.parametrize("text, line, what", [
    ("t,x,y,yaw,speed,speed_cmd\n0,0,0,0,0,0\n", 1, "missing: steer_cmd_rad"),
    ("t,x,y,yaw,speed,speed_cmd,steer_cmd\n0,0,0,0,0,0,zero\n", 2, "expected a number"),
    ("t,x,y,yaw,speed,speed_cmd,steer_cmd\n" + "".join(f"{i * 0.1},0,0,0,0,0,0\n" for i in range(100))
     + "5.0,0,0,0,0,0,0\n", 102, "strictly increasing"),
    ("t,x,y,yaw,speed,speed_cmd,steer_cmd\n0,0,0,0,0,0,0\n", 2, "expected at least"),
    ("t,x,y,yaw,speed,speed_cmd,steer_cmd\n", 1, "expected rows of data after the header (got none)"),
])
def test_cli_bad_input_exit_2_and_nothing_written(tmp_path, text, line, what):
    p = tmp_path / "m.csv"
    p.write_text(text)
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2
    err = res.stderr.strip()
    assert "\n" not in err and f"{p}:{line}: " in err and what in err
    assert "Traceback" not in res.output
    assert sorted(x.name for x in tmp_path.iterdir()) == ["m.csv"]


def test_a_log_of_a_car_at_rest_is_refused_in_one_line(tmp_path):
    """20 s of a car standing still (noisy sensors, zero commands): nothing can show, so the
    workflow says so instead of reporting 'effects found: none'."""
    rng = np.random.default_rng(0)
    rows = "".join(f"{i * 0.02:.2f},{rng.normal(0, 0.005):.4f},{rng.normal(0, 0.005):.4f},{rng.normal(0, 0.005):.4f},"
                   f"{rng.normal(0, 0.02):.4f},0,0\n" for i in range(1000))
    p = tmp_path / "m.csv"
    p.write_text("t,x,y,yaw,speed,speed_cmd,steer_cmd\n" + rows)
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2 and "Traceback" not in res.output
    err = res.stderr.strip()
    assert "\n" not in err and "expected the car to move" in err and "(got 0 of " in err and "simrunner excite" in err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["m.csv"]


def test_cli_reads_a_log_with_a_row_written_twice(tmp_path, offset_run):
    """The same row twice (a logger's repeat): the run goes on, the repeat is listed."""
    log, _, _ = offset_run
    p = tmp_path / "m.csv"
    write_log(log.subset(int(np.searchsorted(log.t_s, 12.0))), p)
    lines = p.read_text().splitlines(keepends=True)
    p.write_text("".join(lines[:300] + [lines[299]] + lines[300:]))
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out"), "--max-effects", "0", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert "duplicate (t_s) line 301 repeats the row before it (same stamp, same values): left out" in res.stdout
    assert "the chain stopped: max effects 0: nothing tried" in res.stdout
    assert "left unexplained by the catalogue" not in res.stdout  # no effect was tried
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert any("line 301" in g["detail"] for g in rep["glitches"])


def test_cli_reads_a_log_in_the_car_s_units_through_the_controller_s_norms(tmp_path, offset_run):
    """The commands logged as the car's code sends them (examples/real_car_units.py: servo
    -512..512, + = right; duty in percent) read through that controller's own norm
    functions (--norms): the same gap as the log in m/s and radians."""
    import csv as csvmod

    log, _, _ = offset_run
    native = tmp_path / "native.csv"
    write_log(log, native, float_format="%.17g")
    with native.open() as f:
        rows = [r for r in csvmod.reader(f) if r and not r[0].startswith("#")]
    head = rows[0]
    i_v, i_s = head.index("speed_cmd_mps"), head.index("steer_cmd_rad")
    head[i_v], head[i_s] = "duty", "servo"
    for r in rows[1:]:
        r[i_v], r[i_s] = repr(float(r[i_v]) / 3.1 * 100), repr(-float(r[i_s]) * 512 / 0.40)
    units = tmp_path / "car_units.csv"
    units.write_text("\n".join(",".join(r) for r in rows) + "\n")
    ctl = Path(__file__).resolve().parents[1] / "examples" / "real_car_units.py"
    res = CliRunner().invoke(gap, [str(units), "-o", str(tmp_path / "a"), "--max-effects", "0", "--no-progress",
                                   "--column", "speed_cmd_mps=speed_norm(duty, servo)",
                                   "--column", "steer_cmd_rad=turn_norm(duty, servo)", "--norms", str(ctl)])
    assert res.exit_code == 0, res.output
    ref = CliRunner().invoke(gap, [str(native), "-o", str(tmp_path / "b"), "--max-effects", "0", "--no-progress"])
    assert ref.exit_code == 0, ref.output
    a, b = (json.loads((tmp_path / d / "report.json").read_text()) for d in "ab")
    assert a["gap_before"] == pytest.approx(b["gap_before"], rel=1e-9)
    # --norms that no rule calls is refused before anything runs
    res = CliRunner().invoke(gap, [str(native), "-o", str(tmp_path / "c"), "--norms", str(ctl)])
    assert res.exit_code == 2 and "no column rule calls speed_norm or turn_norm" in res.stderr


def test_cli_one_mapping_reads_logs_of_one_car_with_other_sensors(tmp_path):
    """A camera log (pose only) and an encoder + gyro log, each with the team's own column
    names, under one mapping: each log is read with the sensors it has and the two form one
    data set (the signals both have); a rule that no log can follow is still refused."""
    import csv as csvmod

    names = {"t_s": "stamp", "x_m": "cam_x", "y_m": "cam_y", "yaw_rad": "cam_yaw", "speed_mps": "enc_v",
             "yaw_rate_radps": "gyro_z", "speed_cmd_mps": "v_cmd", "steer_cmd_rad": "d_cmd"}
    paths = []
    for k, sensors in enumerate(("pose", "speed_gyro")):
        log, _ = make_measured_log("speed_scale", value=1.1, rng=np.random.default_rng(40 + k), sensors=sensors,
                                   duration_s=14.0)
        p = tmp_path / f"{sensors}.csv"
        write_log(log, p, float_format="%.17g")
        with p.open() as f:
            rows = [r for r in csvmod.reader(f) if r and not r[0].startswith("#")]
        rows[0] = [names.get(h, h) for h in rows[0]]
        p.write_text("\n".join(",".join(r) for r in rows) + "\n")
        paths.append(str(p))
    cmap = tmp_path / "map.toml"
    cmap.write_text("".join(f'{k} = "{v}"\n' for k, v in names.items()))
    res = CliRunner().invoke(gap, paths + ["-o", str(tmp_path / "out"), "--columns", str(cmap), "--max-effects", "0",
                                           "--no-progress"])
    assert res.exit_code == 0, res.output
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["logs"] == paths and set(rep["rmse_before"]) == {"speed_mps", "yaw_rate_radps"}
    cmap.write_text(cmap.read_text() + 'coast = "motor_off"\n')
    res = CliRunner().invoke(gap, paths + ["-o", str(tmp_path / "out2"), "--columns", str(cmap)])
    assert res.exit_code == 2 and res.stderr.startswith(
        f"simrunner gap: {cmap}:9: coast asks for column 'motor_off', which none of the 2 logs has")


def test_cli_bad_options_exit_2(tmp_path, offset_run):
    log, _, _ = offset_run
    p = tmp_path / "m.csv"
    write_log(log, p, float_format="%.17g")
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out"), "--effects", "warp_drive"])
    assert res.exit_code == 2 and "warp_drive" in res.stderr
    (tmp_path / "exists").mkdir()
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "exists")])
    assert res.exit_code == 2 and "exists" in res.stderr
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out"), "--car", str(tmp_path / "nope.toml")])
    assert res.exit_code == 2
    assert not (tmp_path / "out").exists()
    # a folder that cannot be made is told before the run, not after its minutes
    (tmp_path / "afile").write_text("")
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "afile" / "out")])
    assert res.exit_code == 2 and res.stdout == ""
    assert res.stderr.startswith(f"simrunner gap: {tmp_path / 'afile' / 'out'}: cannot write the output folder there")


SUBSET = ["steering_offset", "steering_gain"]


@pytest.fixture(scope="module")
def short_run(offset_run, tmp_path_factory):
    """The first 12 s of the offset log (six windows) as a CSV file, and the library's run of
    that file on two effects with 2 jobs (the CLI tests below compare with it)."""
    log, _, _ = offset_run
    p = tmp_path_factory.mktemp("short") / "m.csv"
    write_log(log.subset(int(np.searchsorted(log.t_s, 12.0))), p, float_format="%.17g")
    return p, run_gap(read_log(p), jobs=2, effects=SUBSET)


def test_cli_run_matches_library_and_jobs_do_not_matter(tmp_path, short_run):
    p, lib = short_run
    subset = SUBSET
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out"), "--jobs", "1", "--no-progress",
                                   "--effects", ",".join(subset)])
    assert res.exit_code == 0, res.output
    assert "effects found: steering_offset" in res.stdout
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["effect"] == lib.effect
    assert [r["parameters"] for r in rep["ranking"]] == [r.parameters for r in lib.ranking]
    assert [r["bic"] for r in rep["ranking"]] == [r.criterion for r in lib.ranking]



def test_cli_screen_option_fits_on_a_subset_and_says_so(tmp_path, short_run):
    """``--screen S``: the screening and refits use about S seconds of the fit windows (the
    report says how many of how many); the default uses all of a log this short."""
    p, whole = short_run
    subset = SUBSET
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "out"), "--jobs", "1", "--no-progress",
                                   "--effects", ",".join(subset), "--screen", "3"])
    assert res.exit_code == 0, res.output
    settings = json.loads((tmp_path / "out" / "report.json").read_text())["settings"]
    assert settings["screen_max_s"] == 3.0
    assert 0.0 < settings["screen_windows_s"] < settings["fit_windows_s"]
    assert (f"screened and refitted on {settings['screen_windows_s']:.0f} s of the "
            f"{settings['fit_windows_s']:.0f} s of fit windows") in res.stdout
    assert "effects found: steering_offset" in res.stdout
    lib = run_gap(read_log(p), jobs=2, effects=subset, screen_max_s=3.0)
    assert lib.parameters == json.loads((tmp_path / "out" / "report.json").read_text())["parameters"]
    assert whole.settings["screen_windows_s"] == whole.settings["fit_windows_s"]
    assert "screened and refitted on" not in summary_text(whole)
    res = CliRunner().invoke(gap, [str(p), "-o", str(tmp_path / "neg"), "--screen", "-1"])
    assert res.exit_code == 2 and "--screen" in res.stderr and not (tmp_path / "neg").exists()


# -- several effects, several logs, partial sensors -----------------------------------------
def test_two_hidden_effects_are_both_kept_with_a_chain():
    # one car, two logs: the plan's lateral part and its longitudinal part (36 s in all)
    logs = [make_measured_log(["steering_offset", "motor_lag"], value=[-0.03, 0.3],
                              rng=np.random.default_rng(seed), **part)[0]
            for seed, part in ((21, PART_LATERAL), (121, PART_LONGITUDINAL))]
    candidates = ["steering_offset", "steering_gain", "motor_lag", "drag", "command_latency"]
    result = run_gap(logs, jobs=1, effects=candidates)
    assert sorted(result.effects) == ["motor_lag", "steering_offset"]
    assert result.parameters["steering_offset_rad"] == pytest.approx(-0.03, rel=0.15)
    assert result.parameters["motor_lag_s"] == pytest.approx(0.3, rel=0.15)
    steps = result.chain.steps
    assert [s.kept.effect for s in steps if s.kept] == result.effects
    for s in steps:  # every kept step shrinks the held-out gap, on its own and on the report's normalisation
        if s.kept:
            assert s.kept.held_gap < s.held_gap_before and s.gap_after < s.gap_before
    assert steps[0].gap_before == pytest.approx(result.gap_before)
    assert steps[1].gap_before == steps[0].gap_after
    # the second step is normalised to the first model's residuals: the signals the offset
    # explained weigh more than they did under the nominal model
    assert steps[1].scales["cross_m"] < 0.5 * steps[0].scales["cross_m"]
    assert result.gap_after < 0.5 * result.gap_before
    assert steps[-1].kept is None and steps[-1].trials  # the chain stopped on rejections
    rep = result.to_json()
    assert rep["effects"] == result.effects and len(rep["chain"]) == len(steps)
    assert all(r["reason"] for r in rep["rejected"])


def test_speed_and_gyro_only_log_names_a_longitudinal_effect_and_says_what_it_cannot_see():
    log, truth = make_measured_log("motor_lag", value=0.3, rng=np.random.default_rng(22),
                                   sensors="speed_gyro", **PART_LONGITUDINAL)
    assert log.x_m is None and log.yaw_rate_radps is not None
    result = run_gap(log, jobs=1, effects=LONGITUDINAL + ["steering_offset"])
    assert result.effects == ["motor_lag"]
    assert result.parameters["motor_lag_s"] == pytest.approx(0.3, rel=0.15)
    assert result.settings["signals"] == ["speed_mps", "yaw_rate_radps"]
    assert "position_m" not in result.rmse_before
    # no pose: the speed sensor's unit has nothing to be checked against, and the report says so
    assert result.to_json()["conventions_unchecked"] == {log.source: [
        "speed_mps's unit (no pose to compare it with; only its sign, against the command)"]}
    assert (f"not checked in {log.source}" in summary_text(result)
            and "speed_mps's unit (no pose" in summary_text(result))


def test_several_logs_of_one_car_form_one_data_set(tmp_path):
    a, _ = make_measured_log("steering_offset", value=-0.03, rng=np.random.default_rng(23), **PART_LATERAL)
    b, _ = make_measured_log("steering_offset", value=-0.03, rng=np.random.default_rng(24), start_s=20.0,
                             duration_s=14.0)
    pa, pb = tmp_path / "a.csv", tmp_path / "b.csv"
    write_log(a, pa, float_format="%.17g")
    write_log(b, pb, float_format="%.17g")
    res = CliRunner().invoke(gap, [str(pa), str(pb), "-o", str(tmp_path / "out"), "--no-progress", "--jobs", "1",
                                   "--effects", "steering_offset,steering_gain"])
    assert res.exit_code == 0, res.output
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["logs"] == [str(pa), str(pb)] and rep["effects"] == ["steering_offset"]
    assert rep["parameters"]["steering_offset_rad"] == pytest.approx(-0.03, rel=0.10)
    assert rep["windows"]["held_out"] >= 2
    assert [d["log"] for d in rep["per_log"]] == [str(pa), str(pb)] and rep["logs_worse"] == []
    assert all(d["gap_after"] < 0.5 * d["gap_before"] for d in rep["per_log"])
    assert "held-out gap per log before -> after: a.csv " in res.stdout and "WARNING" not in res.stdout


def test_logs_one_model_cannot_fit_are_named():
    """Two logs of 'one car', one of them with a steering offset the other lacks (a trim
    changed between the runs): the pooled offset helps the first and spoils the second, and
    the report says which log got worse; the standard error shows the spread between them."""
    import dataclasses

    from simrunner.workflows.gap.report import summary_text

    a, _ = make_measured_log("steering_offset", value=0.04, rng=np.random.default_rng(11), **PART_LATERAL)
    b, _ = make_measured_log(None, rng=np.random.default_rng(12), **PART_LATERAL)
    r = run_gap([dataclasses.replace(a, source="a.csv"), dataclasses.replace(b, source="b.csv")], jobs=1,
                effects=["steering_offset"])
    assert r.effects == ["steering_offset"] and 0.01 < r.parameters["steering_offset_rad"] < 0.03
    (da, db) = r.per_log
    assert da["gap_after"] < da["gap_before"] and db["gap_after"] > db["gap_before"]
    assert r.logs_worse == ["b.csv"]
    assert "WARNING: the kept effects fit b.csv worse than the nominal car" in summary_text(r)
    assert r.parameter_sigma["steering_offset_rad"] > 0.1 * r.parameters["steering_offset_rad"]


def test_a_deadband_the_log_pins_only_to_an_interval_is_kept_at_its_middle_and_said_so():
    """This part of the plan (40-65 s) holds zero speed commands and one of 0.3 m/s, none in
    between: every deadband in (0, 0.3) fits it as well (a zero command coasts instead of
    braking). The chain keeps the middle of the interval, reports the interval (its lower
    end at twice settings.neutral_tol of the 0-0.5 range) and gives no standard error."""
    from simrunner.workflows.gap.settings import SETTINGS
    from simrunner.workflows.gap.report import summary_text

    log, _ = make_measured_log("throttle_deadband", value=0.03, rng=np.random.default_rng(3), start_s=40.0,
                               duration_s=25.0)
    cmd = np.abs(log.speed_cmd_mps)
    assert set(np.round(cmd[(cmd > 0) & (cmd < 0.5)], 3)) == {0.3}
    result = run_gap(log, jobs=1, effects=["throttle_deadband"])
    assert result.effects == ["throttle_deadband"] and result.gap_after < 0.5 * result.gap_before
    (lo, hi), = result.parameter_spans.values()
    assert lo == pytest.approx(2 * SETTINGS.neutral_tol * CANDIDATES["throttle_deadband"].hi) and 0.2 < hi <= 0.31
    assert result.parameters["throttle_deadband_mps"] == pytest.approx(0.5 * (lo + hi), rel=1e-6)
    assert math.isnan(result.parameter_sigma["throttle_deadband_mps"])
    assert f"any value {lo:.4g}-{hi:.4g} fits the fit windows as well" in summary_text(result)
    assert result.to_json()["parameter_spans"] == {"throttle_deadband_mps": [lo, hi]}
