"""``simrunner excite``, ``simrunner calibrate`` and ``simrunner calibrate-camera``: thin click
commands (registered by ``simrunner.cli``) over :mod:`simrunner.workflows.excite`,
:mod:`simrunner.workflows.calibration.calibrate` and :mod:`simrunner.workflows.calibration.camera_fit`.

Exit codes: 0 done; 2 bad input (one line on stderr, no traceback).
"""
from __future__ import annotations

import math
import sys

import click

from simrunner.cli import input_errors
from simrunner.cli.names import HELP


def _fail(exc: BaseException) -> None:
    click.echo(f"simrunner: {exc}", err=True)
    sys.exit(2)


@click.command("excite", context_settings=HELP)
@click.option("-o", "--output", "output", required=True, metavar="PLAN.csv",
              help="Where to write the plan (t, speed_cmd, steer_cmd, coast, segment, and the turns' "
                   "ref_x, ref_y, ref_yaw at 50 Hz).")
@click.option("--duration", "duration_s", default=None, type=float, metavar="SECONDS",
              help="Total duration: the core plan (~90 s) plus random-steer blocks "
                   "(default: the core plan).")
@click.option("--car", default=None, metavar="CAR.toml", help="Car description (default: built-in car).")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
              help="Seed of the random-steer steps (and of --pose-noise).")
@click.option("--simulate", default=None, metavar="OUT.csv",
              help="Also play the plan in the simulator (car effects apply) and write its "
                   "run log (CSV, docs/telemetry.md).")
@click.option("--closed-loop", "closed_loop", is_flag=True,
              help="With --simulate: drive the turns closed loop, following their reference path "
                   "from the (noisy) pose, as docs/calibration.md tells the car's code to.")
@click.option("--pose-noise", "pose_noise_m", default=0.0, show_default=True,
              type=click.FloatRange(min=0.0, max=1.0), metavar="METRES",
              help="With --simulate: Gaussian noise on the logged x and y (and /0.2 m per rad on yaw), "
                   "like a real pose measurement; closed loop, the car steers from it too.")
@click.option("--dt", "dt_s", default=0.002, show_default=True, type=float, metavar="SECONDS",
              help="Physics time step of --simulate (must divide the 20 ms row period).")
@click.option("--dead-reckoning", "gyro_bias_dps", default=None, type=click.FloatRange(min=-10.0, max=10.0),
              metavar="DEG_PER_S", help="With --closed-loop: steer the turns from a pose the car integrates from its "
                                        "wheel speed and gyro, whose bias after zeroing is this (deg/s), as a team "
                                        "without a camera does; the log holds where the car really went.")
@click.option("--area", "area_m", default=None, type=float, metavar="METRES",
              help="Side of the square area to plan for (6 .. 15 m; default: the smallest from 6 m up, "
                   "in 0.5 m steps, that the car's turns fit).")
def excite_cmd(output, duration_s, car, seed, simulate, closed_loop, pose_noise_m, dt_s, gyro_bias_dps,
               area_m) -> None:
    """Write an excitation plan to drive on the real car (docs/calibration.md)."""
    from simrunner.telemetry.log import write_log
    from simrunner.workflows.excite import AREA_M, DeadReckoning, make_plan, predict_path, run_plan
    from vehicle.description import load_car

    if simulate is None and (closed_loop or pose_noise_m > 0.0):
        _fail(click.UsageError("--closed-loop and --pose-noise apply to --simulate, which is not given"))
    if gyro_bias_dps is not None and not math.isfinite(gyro_bias_dps):
        _fail(click.UsageError(f"--dead-reckoning {gyro_bias_dps}: expected a finite gyro bias in deg/s"))
    if gyro_bias_dps is not None and not closed_loop:
        _fail(click.UsageError("--dead-reckoning applies to --closed-loop (the turns steer from the pose)"))
    try:
        car_desc = load_car(car)
        plan = make_plan(car_desc, seed=seed, duration_s=duration_s, area_m=area_m)
        xy = predict_path(plan, car_desc)
        extent = (xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max())
        log = None
        if simulate:
            dr = None if gyro_bias_dps is None else DeadReckoning(gyro_bias_radps=math.radians(gyro_bias_dps))
            log = run_plan(plan, car_desc, dt_s=dt_s, seed=seed, pose_noise_m=pose_noise_m, closed_loop=closed_loop,
                           dead_reckoning=dr)
        plan.to_csv(output, extent=extent)
        if log is not None:
            write_log(log, simulate)
    except input_errors() as exc:
        _fail(exc)
    click.echo(f"plan: {output} ({len(plan)} rows, {plan.duration_s:.1f} s; predicted path "
               f"{extent[1] - extent[0]:.1f} x {extent[3] - extent[2]:.1f} m; area {plan.area_m:g} x {plan.area_m:g} m "
               f"+ {plan.margin_m:g} m margin"
               + (f"; this car's turns need more than {AREA_M:g} m" if area_m is None and plan.area_m > AREA_M
                  else "") + ")")
    if log is not None:
        out = plan.outside_area_m(log.x_m, log.y_m)
        where = "inside the area" if out == 0.0 else f"up to {out:.2f} m outside the area" + (
            " (within the margin)" if out <= plan.margin_m else " (beyond the margin)")
        if out > 0.0 and not closed_loop:
            where += ("; a real car drifts like this unless the turns close the loop on its pose: "
                      "--closed-loop (docs/calibration.md)")
        click.echo(f"simulated log: {simulate} ({'closed' if closed_loop else 'open'} loop"
                   f"{'' if gyro_bias_dps is None else f' from dead reckoning, gyro bias {gyro_bias_dps:g} deg/s'}, "
                   f"{log.duration_s:.1f} s, "
                   f"path {log.x_m.max() - log.x_m.min():.1f} x {log.y_m.max() - log.y_m.min():.1f} m, {where})")


@click.command("calibrate", context_settings=HELP)
@click.argument("measured", metavar="MEASURED.toml", type=click.Path(dir_okay=False, path_type=str))
@click.option("--car", default=None, metavar="CAR.toml", help="Car description to start from (default: built-in car).")
@click.option("-o", "--output", "output", required=True, metavar="NEW_CAR.toml",
              help="Where to write the calibrated car description (written atomically).")
@click.option("--dt", "dt_s", default=0.002, show_default=True,
              type=click.FloatRange(min=0, max=0.02, min_open=True), metavar="SECONDS",
              help="Physics time step of the simulated tests.")
def calibrate_cmd(measured, car, output, dt_s) -> None:
    """Run the thesis's chapter-5 calibration procedures against MEASURED.toml (numbers
    measured on the real car; docs/calibration.md) and write the updated car description."""
    from pathlib import Path

    from simrunner.workflows.calibration.calibrate import calibrate, load_measurements
    from simrunner.errors import SimError
    from vehicle.description import load_car

    try:
        measurements = load_measurements(measured)
        car_desc = load_car(car)
        result = calibrate(measurements, car_desc, dt_s=dt_s)
        out = Path(output)
        if out.parent and not out.parent.is_dir():
            raise SimError(f"{out}: cannot write the car description (no folder {out.parent})")
        try:
            result.car_after.save(out, result.sources())
        except OSError as exc:
            raise SimError(f"{out}: cannot write the car description ({exc.strerror})") from None
    except input_errors() as exc:
        _fail(exc)
    click.echo(result.report(), nl=False)
    click.echo(f"car description: {output}")


@click.command("calibrate-camera", context_settings=HELP)
@click.argument("lines", nargs=-1, required=True, metavar="LINES.csv [MORE.csv ...]",
                type=click.Path(dir_okay=False, path_type=str))
@click.option("--scene", type=click.Choice(["straight", "track"]), default="straight", show_default=True,
              help="What the car looked at while recording: 'straight' (standing on a straight piece) or "
                   "'track' (driving TRACK; the lines carry the pose: columns x_m, y_m, yaw_rad).")
@click.option("--track", "track", default=None, metavar="LAYOUT|DIR|WORLD",
              help="The track the lines were recorded on (--scene track).")
@click.option("--car", default=None, metavar="CAR.toml", help="Car description whose camera is compared "
              "(default: built-in car).")
@click.option("-o", "--output", "output", required=True, metavar="DIR",
              help="Folder for report.json, car.toml and lines.png (replaced whole).")
def calibrate_camera_cmd(lines, scene, track, car, output) -> None:
    """Compare the car file's camera with lines recorded on the real car (one frame a row,
    128 numbers 0..255; docs/camera.md), name the camera effects the recording shows and
    write the car with the fitted camera."""
    from simrunner.errors import SimError
    from simrunner.workflows.calibration.camera_fit import calibrate_straight, write_outputs
    from simrunner.workflows.calibration.camera_lines import read_recordings
    from vehicle.description import load_car

    try:
        if (scene == "track") != (track is not None):
            raise SimError("--scene track needs --track LAYOUT|DIR|WORLD (the track the lines were recorded on)"
                           if scene == "track" else "--track is for --scene track")
        car_desc = load_car(car)
        recording = read_recordings(lines, car_desc.camera.width_px)
        if scene == "track":
            from simrunner.run.runner import resolve_track
            from simrunner.workflows.calibration.camera_track import calibrate_track

            sim_track, _ = resolve_track(track, car_desc)
            fit = calibrate_track(recording, car_desc, sim_track)
        else:
            fit = calibrate_straight(recording, car_desc)
        write_outputs(fit, output, list(lines))
    except input_errors() as exc:
        _fail(exc)
    click.echo(fit.text(), nl=False)
    click.echo(f"wrote {output}/ (report.json, car.toml, lines.png)")
