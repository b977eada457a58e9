"""The FRDM-TFC kit library on the simulated car (issue 50 item 1, simrunner drive --kit tfc):
a team's firmware builds unchanged against the simulator's TFC library and drives."""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.errors import ControllerFileError
from simrunner.run.native import build_program
from simrunner.run.runner import drive

REPO = Path(__file__).resolve().parents[1]
FIRMWARE = REPO / "examples" / "firmware" / "main.c"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"


def firmware(sources, **kw):
    return build_program([str(s) for s in sources], kit="tfc", **kw)


def test_the_example_firmware_builds_unchanged_and_laps():
    """examples/firmware/main.c includes "TFC\\TFC.h" (a Windows path, as CodeWarrior projects
    have it) and laps the default track as the Python line follower it mirrors does."""
    assert '#include "TFC\\TFC.h"' in FIRMWARE.read_text()
    r = drive(firmware([FIRMWARE]), laps=2)
    follower = drive(REPO / "examples" / "line_follower.py", laps=2)
    assert r.outcome == "finished" and r.laps_completed == 2, r.message
    assert r.lap_times_s[1] == pytest.approx(follower.lap_times_s[1], rel=0.05)


@pytest.mark.parametrize("hbridge", ["brake", "coast"])
def test_the_example_firmware_laps_a_duty_driven_car(tmp_path, hbridge):
    """With drive.command = "duty" the firmware's TFC_SetMotorPWM duties drive the two rear
    motors (its speed loop is the duty it sets, as on the car)."""
    car = tmp_path / "duty.toml"
    car.write_text(f'[drive]\ncommand = "duty"\nhbridge = "{hbridge}"\n')
    r = drive(firmware([FIRMWARE]), car=car, laps=2)
    assert r.outcome == "finished" and r.laps_completed == 2, r.message
    assert r.log.duty_left is not None and np.nanmax(np.abs(r.log.duty_left)) > 0.1


@pytest.mark.parametrize("track", [None, "nxp_raceway"])
def test_the_firmwares_run_log_equals_the_same_logic_through_spinner(tmp_path, track):
    """examples/firmware/twin/spinner_twin.c runs the firmware's logic (lane.h) through the
    Spinner API with the library's timing written out: the two run logs are byte for byte the
    same, so the kit adds the library's API and nothing else (no lag, no other rounding)."""
    if track is not None:
        if not SHARED_TRACKS.is_dir():
            pytest.skip("../shared/tracks not present")
        track = SHARED_TRACKS / track
    twin = REPO / "examples" / "firmware" / "twin" / "spinner_twin.c"
    a = drive(firmware([FIRMWARE]), track=track, laps=1, csv=tmp_path / "firmware.csv")
    b = drive(build_program([str(twin)]), track=track, laps=1, csv=tmp_path / "twin.csv")
    assert a.outcome == b.outcome == "finished", (a.message, b.message)
    assert (tmp_path / "firmware.csv").read_bytes() == (tmp_path / "twin.csv").read_bytes()


def test_the_kit_reads_the_camera_at_its_frame_rate(tmp_path, capfd):
    """The PIT read-out takes every frame of a 19.5-ms exposure (about 50 images a second, as the
    kit's camera gives them; it once took every other one): images counted over 1 s of ticks."""
    src = tmp_path / "count.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include "derivative.h"
        #include "TFC/TFC.h"
        int main(void) {
            TFC_Init();
            TFC_SetLineScanExposureTime(19500);
            int images = 0;
            uint32_t start = TFC_Ticker[0];
            while (TFC_Ticker[0] - start < 1000) {
                TFC_Task();
                if (LineScanImageReady) { LineScanImageReady = 0; images++; }
            }
            printf("images %d\\n", images);
            fflush(stdout);
            return images >= 49 && images <= 52 ? 0 : 1;
        }
    """))
    r = drive(firmware([src]), time_limit_s=3.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", (r.message, capfd.readouterr().out)


@pytest.mark.skipif(not SHARED_TRACKS.is_dir(), reason="../shared/tracks not present")
def test_the_example_firmware_laps_both_nxp_tracks():
    for name in ("nxp_raceway", "nxp_raceway_octagon"):
        r = drive(firmware([FIRMWARE]), track=SHARED_TRACKS / name)
        assert r.outcome == "finished", (name, r.message)


def test_the_library_maps_the_board_onto_the_car(tmp_path):
    """Tickers count simulated ms, an image arrives as 12-bit counts with LineScanImageReady,
    pots/DIP/battery read --param, the servo steers, the motors' duty is a speed only with the
    H-bridge enabled."""
    src = tmp_path / "probe.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\TFC.h"
        #include "spinner.h"
        int main(void) {
            TFC_Init();
            if (TFC_ReadPot(0) != 0.5f || TFC_ReadPot(1) != -1.0f) return 1;   /* --param pot0, pot1 */
            if (TFC_GetDIP_Switch() != 5 || TFC_ReadBatteryVoltage() != 7.2f) return 2;
            TFC_Ticker[1] = 0;
            TFC_Delay_mS(100);
            if (TFC_Ticker[1] < 100 || TFC_Ticker[1] > 106) return 3;  /* a camera read may add a step or two */
            TFC_SetLineScanExposureTime(10000);
            LineScanImageReady = 0;
            for (int i = 0; i < 50 && !LineScanImageReady; i++) TFC_Task();
            if (!LineScanImageReady) return 4;
            for (int i = 0; i < 128; i++) if (LineScanImage0[i] % 16 || LineScanImage0[i] > 4080) return 5;
            TFC_SetServo(0, 0.5f);
            TFC_SetMotorPWM(0.5f, 0.5f);       /* H-bridge still disabled: no speed */
            TFC_Delay_mS(100);
            TFC_HBRIDGE_ENABLE;
            TFC_Delay_mS(100);
            spinner_add_textf("done");
            return 0;
        }
        """))
    r = drive(firmware([src]), params={"pot0": 0.5, "pot1": -3, "dip": 5}, time_limit_s=5.0,
              csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    log = r.log
    late = log.t_s > log.t_s[-1] - 0.05
    assert np.allclose(log.speed_cmd_mps[late], 0.5 * 3.1) and np.allclose(log.steer_cmd_rad[late], 0.2)
    before = (log.t_s > 0.15) & (log.t_s < log.t_s[-1] - 0.12)
    assert np.all(log.speed_cmd_mps[before] == 0.0)


def test_kit_misuse_is_one_line(tmp_path):
    with pytest.raises(ControllerFileError, match=r"--kit stm32: expected one of tfc"):
        build_program([str(FIRMWARE)], kit="stm32")
    res = CliRunner().invoke(cli, ["drive", str(REPO / "examples" / "line_follower.py"), "--kit", "tfc"])
    assert res.exit_code == 2 and "--kit is for C/C++ controllers" in res.output
    bad = tmp_path / "regs.c"
    bad.write_text('#include "derivative.h"\n#include "TFC/TFC.h"\nint main(void) { GPIOB_PSOR = 1; return 0; }\n')
    with pytest.raises(ControllerFileError, match=r"regs.c:3"):
        firmware([bad])
