"""`simrunner plot LOG`: telemetry and real logs, lap markers and the off-track point drawn."""
from __future__ import annotations

import os
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.telemetry.log import read_log, write_log
from simrunner.reports.plot import lap_rows, off_track_row
from simrunner.run.runner import drive

REPO = Path(__file__).resolve().parents[1]
REAL = Path(os.environ.get("NXPCUP_REAL_LOGS",
                           Path(__file__).resolve().parents[2] / "shared/data/real_logs"))
GOLD = (0, 215, 255)  # BGR of matplotlib's "gold" (the lap markers)
RED = (0, 0, 255)     # BGR of "red" (the off-track cross and line)


def _count(png: Path, bgr, tol: int = 12) -> int:
    img = cv2.imread(str(png))
    return int(np.count_nonzero(np.all(np.abs(img.astype(int) - bgr) <= tol, axis=2)))


@pytest.fixture(scope="module")
def laps_log(tmp_path_factory):
    """Telemetry of two laps of the default track."""
    path = tmp_path_factory.mktemp("plot") / "two_laps.csv"
    drive(REPO / "examples" / "line_follower.py", laps=2, csv=path)
    return path


def test_plot_of_telemetry_marks_every_lap(laps_log, tmp_path):
    log = read_log(laps_log)
    assert lap_rows(log).size == 2 and off_track_row(log) is None
    out = tmp_path / "laps.png"
    r = CliRunner().invoke(cli, ["plot", str(laps_log), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert f"wrote: {out}" in r.output
    gold = _count(out, GOLD)
    # the same log with the lap count removed: no lap marker, no gold
    bare = tmp_path / "bare.csv"
    write_log(log.with_columns(lap=np.zeros(len(log), dtype=np.int64)), bare)
    r = CliRunner().invoke(cli, ["plot", str(bare), "-o", str(tmp_path / "bare.png")])
    assert r.exit_code == 0, r.output
    assert gold > 150 and _count(tmp_path / "bare.png", GOLD) == 0


def test_plot_default_output_name_and_track_background(laps_log, tmp_path):
    log = tmp_path / "run.csv"
    log.write_bytes(laps_log.read_bytes())
    r = CliRunner().invoke(cli, ["plot", str(log), "--track", str(REPO / "examples" / "thesis_figure8.txt")])
    assert r.exit_code == 0, r.output
    png = tmp_path / "run.png"
    img = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    left = img[:, : img.shape[1] // 2]
    assert np.count_nonzero(left < 60) > 20_000  # the track raster's dark floor under the path


def test_plot_marks_the_off_track_point(tmp_path):
    ctrl = tmp_path / "wide.py"
    ctrl.write_text(textwrap.dedent("""
        def main(spinner):
            while True:
                spinner.get_image(60)
                spinner.set_speed_and_servo(1.5, 0.1)
    """))
    csv = tmp_path / "off.csv"
    result = drive(ctrl, csv=csv, off_track_wheels=1)  # the first wheel off ends the run
    assert result.outcome == "off_track"
    log = read_log(csv)
    assert off_track_row(log) == int(np.argmax(log.off_track)) == len(log) - 1
    r = CliRunner().invoke(cli, ["plot", str(csv), "-o", str(tmp_path / "off.png")])
    assert r.exit_code == 0, r.output
    assert _count(tmp_path / "off.png", RED) > 300  # the cross and the vertical lines


@pytest.mark.parametrize("name", ["f1tenth_DS2.csv", "f1tenth_DS3.csv"])
def test_plot_of_a_real_log(name, tmp_path):
    path = REAL / name
    if not path.is_file():
        pytest.skip(f"no real log {path}")
    out = tmp_path / "real.png"
    r = CliRunner().invoke(cli, ["plot", str(path), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert out.stat().st_size > 20_000


def test_plot_reads_other_columns_through_a_mapping(laps_log, tmp_path):
    """A team's log with other names and units, read with --column rules."""
    log = read_log(laps_log)
    own = tmp_path / "team.csv"
    rows = ["time_ms,px_mm,py_mm,v_kmh"] + [f"{t * 1000:.1f},{x * 1000:.1f},{y * 1000:.1f},{v * 3.6:.3f}"
                                            for t, x, y, v in zip(log.t_s, log.x_m, log.y_m, log.speed_mps)]
    own.write_text("\n".join(rows) + "\n")
    args = ["plot", str(own), "-o", str(tmp_path / "team.png"), "--column", "t_s=time_ms/1000",
            "--column", "x_m=px_mm/1000", "--column", "y_m=py_mm/1000", "--column", "speed_mps=v_kmh/3.6"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["plot", str(own), "-o", str(tmp_path / "x.png")])
    assert r.exit_code == 2 and "t_s" in r.output and "Traceback" not in r.output


@pytest.mark.parametrize("text, expected", [
    ("t_s,x_m\n0,1\n0,2\n", r":3: column 't_s': expected strictly increasing time"),
    ("x_m\n1\n", r"expected a time column"),
    ("t_s,x_m\n0,abc\n", r":2:"),
])
def test_bad_logs_are_one_line_exit_2(tmp_path, text, expected):
    import re

    path = tmp_path / "bad.csv"
    path.write_text(text)
    r = CliRunner().invoke(cli, ["plot", str(path), "-o", str(tmp_path / "bad.png")])
    assert r.exit_code == 2 and re.search(expected, r.output), r.output
    assert len(r.output.strip().splitlines()) == 1 and not (tmp_path / "bad.png").exists()


def test_a_drives_lap_labels_are_its_judged_lap_times(laps_log):
    """A drive's plot labels each lap with the judge's time (the gate crossing, as in the title);
    a log read from a file, or lap times that do not match its laps, with the row's time."""
    from simrunner.reports.plot import _lap_label

    log = read_log(laps_log)
    laps = lap_rows(log)
    rows = [float(log.t_s[i]) for i in laps]
    judged = [rows[0] - 0.013, rows[1] - rows[0] + 0.004]
    assert _lap_label(log, laps, 1, judged) == f"lap 1: {judged[0]:.2f} s"
    assert _lap_label(log, laps, 2, judged) == f"lap 2: {judged[1]:.2f} s"
    assert _lap_label(log, laps, 1, None) == f"lap 1 done at {rows[0]:.2f} s"
    assert _lap_label(log, laps, 2, judged[:1]) == f"lap 2 done at {rows[1]:.2f} s"
