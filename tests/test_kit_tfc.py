"""The FRDM-TFC kit library on the simulated car (issue 50 item 1, simrunner drive --kit tfc):
a team's firmware builds unchanged against the simulator's TFC library and drives."""
from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
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


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
@pytest.mark.parametrize("exposure_us", [19500, 10000])
def test_the_kit_reads_one_image_an_exposure_as_the_pit_gives_them(tmp_path, capfd, exposure_us, isolate):
    """The library's PIT0 pulses SI every exposure, free-running, and reads each integration out
    while the next integrates: one image an exposure (2 s / exposure), not one an exposure plus
    the read-out (it gave 2.5 % fewer at 19.5 ms, 5 % at 10 ms; it once took every other one).
    Images counted over 2 s of ticks from the first image of the new exposure (the frame in
    progress at TFC_SetLineScanExposureTime ends on TFC_Init's 50 ms, the next is the first of
    the new period), in process and isolated."""
    src = tmp_path / "count.c"
    src.write_text(textwrap.dedent(f"""\
        #include <stdio.h>
        #include "derivative.h"
        #include "TFC/TFC.h"
        int main(void) {{
            TFC_Init();
            TFC_SetLineScanExposureTime({exposure_us});
            for (int frames = 0; frames < 2; frames++) {{   /* TFC_Init's frame, then the first new one */
                while (!LineScanImageReady) TFC_Task();
                LineScanImageReady = 0;
            }}
            int images = 0;
            uint32_t start = TFC_Ticker[0];
            while (TFC_Ticker[0] - start < 2000) {{
                TFC_Task();
                if (LineScanImageReady) {{ LineScanImageReady = 0; images++; }}
            }}
            printf("images %d\\n", images);
            fflush(stdout);
            return 0;
        }}
    """))
    prog = firmware([src])
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, time_limit_s=3.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned" and r.message == "main() returned", (r.message, out)
    images = int(out.split("images ")[1].split()[0])
    assert abs(images - 2.0 / (exposure_us * 1e-6)) <= 1, images


def test_a_plain_c_programs_frames_are_an_exposure_plus_the_read_out(tmp_path, capfd):
    """Without a kit's spinner_camera_free_running the frames stay exposure + read-out apart
    (a driver that starts the next integration after the read-out): 2 s at 9.5 ms = 200 frames."""
    src = tmp_path / "plain.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include "spinner.h"
        int main(void) {
            uint8_t row[4096];
            spinner_set_exposure(0.0095);
            spinner_get_image(spinner_line_row(), 0, row, sizeof row);
            double t0 = spinner_get_time();
            int frames = 0;
            while (spinner_get_time() - t0 < 2.0 - 1e-9) {
                spinner_get_image(spinner_line_row(), 0, row, sizeof row);
                frames++;
            }
            printf("frames %d period %.6f\\n", frames, (spinner_get_time() - t0) / frames);
            fflush(stdout);
            return 0;
        }
    """))
    r = drive(build_program([str(src)]), time_limit_s=3.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    frames, period = out.split()[1], float(out.split()[3])
    assert frames == "200" and period == pytest.approx(0.010, abs=2e-5), out  # (210 frames one an exposure)


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
            TFC_Delay_mS(60);   /* the ADC's first conversion: the PIT's first period (50 ms) */
            /* --param pot0, pot1 as the library reads them: 12-bit counts 1 - pot x 2047.5 */
            if (TFC_ReadPot(0) != (float)(1024.0f / -2047.5 + 1.0) || TFC_ReadPot(1) != -1.0f) return 1;
            if (TFC_GetDIP_Switch() != 5) return 2;
            /* the library's sense voltage, battery_v x 10k / (47k + 10k), counted by the 3.3-V ADC and
             * scaled by the library's 3.0 (it returned battery_v, then the sense voltage itself) */
            if (fabsf(TFC_ReadBatteryVoltage() - 7.2f * 10.0f / 57.0f * 3.0f / 3.3f) > 1e-3f) return 9;
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


def test_a_loop_that_polls_the_image_flag_sees_every_image(tmp_path):
    """`while (!LineScanImageReady); LineScanImageReady = 0;` takes each image as it comes: 40
    images at a 50 ms exposure in 40 frames' time (clearing the flag is a read of the board too,
    and once fetched the next image before the program read this one: every second image)."""
    src = tmp_path / "poll_images.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\\\TFC.h"
        #include "spinner.h"
        int main(void) {
            TFC_Init();
            TFC_SetLineScanExposureTime(50000);
            double t0 = spinner_get_time();
            for (int i = 0; i < 40; i++) {
                while (!LineScanImageReady);
                LineScanImageReady = 0;
            }
            spinner_add_textf("took %.3f", spinner_get_time() - t0);
            return 0;
        }
    """))
    csv = tmp_path / "poll.csv"
    r = drive(firmware([src]), track="floor", time_limit_s=10.0, csv=csv)
    assert r.outcome == "controller_returned", r.message
    took = float(csv.read_text().rsplit("took ", 1)[1].split('"')[0].split(",")[0].strip())
    assert 39 * 0.05 <= took < 41 * 0.05, took  # a frame is the exposure (the PIT's period)


def test_a_loop_that_only_polls_the_board_lets_time_pass(tmp_path):
    """Firmware written for the board waits on what its interrupts change, calling nothing:
    `while (!TFC_PUSH_BUTTON_0_PRESSED);`, `while (!LineScanImageReady);`, a delay on a ticker.
    Those polls let simulated time pass (the run once stalled), and the library's own extern
    declarations of the flag and the tickers still compile against the kit's."""
    src = tmp_path / "polls.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\\\TFC.h"
        #include "spinner.h"
        extern volatile uint8_t LineScanImageReady;               /* as TFC_LineScanCamera.h */
        extern volatile uint32_t TFC_Ticker[NUM_TFC_TICKERS];     /* as TFC_ARM_SysTick.h */
        static void wait_ms(uint32_t ms) { TFC_Ticker[3] = 0; while (TFC_Ticker[3] < ms); }
        int main(void) {
            TFC_Init();
            TFC_SetLineScanExposureTime(10000);
            while (!TFC_PUSH_BUTTON_0_PRESSED);                   /* pressed at 0.1 s */
            double pressed = spinner_get_time();
            if (pressed < 0.1 || pressed > 0.11) return 1;
            LineScanImageReady = 0;
            while (!LineScanImageReady);                          /* the next image */
            if (LineScanImage0 != LineScanImage0Buffer[1]) return 2;
            double t0 = spinner_get_time();
            wait_ms(200);
            double waited = spinner_get_time() - t0;
            if (TFC_Ticker[7] < 300) return 4;     /* a project's NUM_TFC_TICKERS 8: counts too */
            return waited >= 0.2 && waited < 0.23 ? 0 : 3;   /* + a camera read's wait */
        }
    """))
    r = drive(firmware([src]), time_limit_s=5.0, wall_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message


def test_a_windows_project_builds_with_its_own_library_headers_on_the_path(tmp_path):
    """A CodeWarrior project as teams publish it: -I Project_Headers holds its own copy of the
    library's headers (register macros included), which the kit's headers win over; its
    includes use Windows spellings (a backslash, another case, "Math.h"), found the Windows way."""
    headers = tmp_path / "Project_Headers"
    (headers / "TFC").mkdir(parents=True)
    (headers / "TFC" / "TFC.h").write_text('#include "MKL25Z4.h"\n#define TAOS_SI_HIGH GPIOD_PSOR = (1<<7)\n')
    (headers / "derivative.h").write_text('#include <MKL25Z4.h>\n')
    (headers / "Control").mkdir()
    (headers / "Control" / "Steering.h").write_text('#include "math.h"\n#define GAIN_PER_PIXEL (2.0f / 128)\n')
    src = tmp_path / "Sources" / "main.c"
    src.parent.mkdir()
    src.write_text('#include "derivative.h"\n#include "TFC\\\\TFC.h"\n#include "control\\\\steering.h"\n'
                   '#include "Math.h"\n'
                   'int main(void) { TFC_Init(); TFC_SetServo(0, sqrtf(GAIN_PER_PIXEL * 32)); '
                   'TFC_Delay_mS(50); return 0; }\n')
    r = drive(firmware([src], include_dirs=[headers]), time_limit_s=2.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    assert r.log.steer_cmd_rad[-1] == pytest.approx(0.40 * 0.5 ** 0.5, rel=1e-6)  # sqrt(2/128 * 32) x 0.40 rad


def test_the_librarys_own_sources_and_register_writes_are_named(tmp_path):
    """Passing the project's Sources/TFC/*.c (the kit replaces them) names the file; writing an
    MCU register says it is not emulated, after the compiler's file:line."""
    lib = tmp_path / "TFC" / "TFC_Servo.c"
    lib.parent.mkdir()
    lib.write_text("void TFC_InitServos(void) {}\n")
    with pytest.raises(ControllerFileError, match=r"TFC_Servo.c: the kit's own driver source: --kit tfc"):
        firmware([FIRMWARE, lib])
    regs = tmp_path / "regs.c"
    regs.write_text('#include "derivative.h"\n#include "TFC/TFC.h"\n'
                    'int main(void) { GPIOB_PSOR = 1 << 8; TPM0_C0V = 3; return 0; }\n')
    with pytest.raises(ControllerFileError, match=r"(?s)regs.c:3:.*GPIOB_PSOR, TPM0_C0V: the MCU's "
                                                  r"registers, not emulated by the simulator's --kit tfc "
                                                  r"\(it has a timer interrupt's only: LPTMR0, the PIT"):
        firmware([regs])  # (it said "it has no registers", though a timer's set-up compiles and runs)


def test_a_timer_handler_reads_the_tickers_while_main_polls_the_image_flag(tmp_path):
    """A handler (--isr) that reads TFC_Ticker while main() waits on `while (!LineScanImageReady);`:
    its reads are the board's state at its time, the tickers counted to it (no time passes and no
    image is read in an interrupt; the run once ended with "get_image inside an interrupt handler"
    at its line, and the tickers stood still while main() waited for the camera)."""
    from simrunner.run.native.build import with_isrs

    src = tmp_path / "isr_polls.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\\\TFC.h"
        #include "spinner.h"
        static volatile int periods;
        void PIT_IRQHandler(void) {               /* 1 kHz: 10-ms periods from the SysTick ticker */
            if (TFC_Ticker[1] >= 10) { TFC_Ticker[1] = 0; periods++; }
        }
        int main(void) {
            TFC_Init();
            for (int images = 0; images < 20; images++) {
                while (!LineScanImageReady) { }
                LineScanImageReady = 0;
            }
            double t_ms = 1000.0 * spinner_get_time();  /* the tickers count while main() waits */
            return periods >= 0.95 * t_ms / 10 && periods <= t_ms / 10 ? 0 : 3;
        }
    """))
    r = drive(with_isrs(firmware([src]), [("PIT_IRQHandler", 0.001)]), track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message


def test_firmware_reads_encoders_and_the_imu_through_spinner_h(tmp_path):
    """The TFC library has no encoder or accelerometer API (teams drive their own on the registers,
    which are not emulated): a --kit tfc firmware reads the car file's [encoders] and [imu] with
    spinner.h's calls beside the library's."""
    src = tmp_path / "main.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\\\TFC.h"
        #include "spinner.h"
        int main(void) {
            double gz, ax, ay, az;
            TFC_Init();
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            while (TFC_Ticker[0] < 1500) TFC_Task();
            long long rl = spinner_get_encoder(SPINNER_WHEEL_RL), rr = spinner_get_encoder(SPINNER_WHEEL_RR);
            spinner_get_gyro(NULL, NULL, &gz);
            spinner_get_accel(&ax, &ay, &az);
            if (rl < 5000 || rr < 0.98 * rl || rr > 1.02 * rl) return 1;
            if (az < 9.3 || az > 10.3 || gz > 0.2 || gz < -0.2) return 2;
            return 0;
        }
        """))
    car = tmp_path / "car.toml"
    car.write_text("[encoders]\n[imu]\n")
    r = drive(firmware([src]), track="floor", car=car, time_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message


def test_a_module_that_includes_the_mcus_register_header_builds(tmp_path, capfd):
    """A team's timer module includes MKL25Z4.h itself (the header derivative.h includes on the
    board; Kinetis Design Studio projects include it directly): it builds against the kit's timers
    and runs (was: "fatal error: MKL25Z4.h: No such file or directory")."""
    timer = tmp_path / "timer.c"
    timer.write_text(textwrap.dedent("""\
        #include "MKL25Z4.h"
        volatile unsigned ticks;
        void LPTMR0_IRQHandler(void) { LPTMR0->CSR |= LPTMR_CSR_TCF_MASK; ticks++; }
        void Timer_Init(void) {
            SIM->SCGC5 |= SIM_SCGC5_LPTMR_MASK;
            LPTMR0->PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK;   /* the 1 kHz LPO */
            LPTMR0->CMR = 10 - 1;                                   /* 100 Hz */
            LPTMR0->CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK;
            NVIC_EnableIRQ(LPTMR0_IRQn);
        }
        """))
    main = tmp_path / "main.c"
    main.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\TFC.h"
        extern volatile unsigned ticks;
        void Timer_Init(void);
        int main(void) {
            TFC_Init();
            Timer_Init();
            while (TFC_Ticker[0] < 1000) __WFI();
            printf("ticks %u\\n", ticks);
            return 0;
        }
        """))
    r = drive(firmware([main, timer]), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    assert "ticks 100" in capfd.readouterr().out


def frames_around(log, t_call_s: float) -> list[float]:
    """The run log's frame boundaries (one row a camera frame) b0 <= ``t_call_s`` < b1 < b2 < b3."""
    t = [float(x) for x in log.t_s]
    i = max(j for j, b in enumerate(t) if b <= t_call_s + 1e-9)
    return t[i:i + 4]


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_new_exposure_loads_as_the_frame_in_progress_ends(tmp_path, capfd, isolate):
    """TFC_SetLineScanExposureTime writes PIT_LDVAL0 while PIT0 runs, and the KL25 loads it at the
    timer's next expiry (RM, PIT_LDVALn): the image after the call still comes one old period (10 ms)
    after the one before and is as bright, the next one 20 ms later and brighter; of the two writes
    in that frame (5 ms, then 20 ms) the last loads. (The new exposure used to re-time the frame in
    progress: the image after the call came 20 ms later, brighter.)"""
    src = tmp_path / "expo.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include "derivative.h"
        #include "TFC/TFC.h"
        #include "spinner.h"
        static long sum(void) { long s = 0; for (int i = 0; i < 128; i++) s += LineScanImage0[i]; return s; }
        int main(void) {
            TFC_Init();
            TFC_SetLineScanExposureTime(10000);
            for (int n = 0; n < 10; n++) {
                while (!LineScanImageReady) TFC_Task();
                LineScanImageReady = 0;
                printf("image %d %.6f %ld\\n", n, spinner_now(), sum());
                if (n == 5) {                       /* mid-frame: two writes, the last one counts */
                    TFC_Delay_mS(4);
                    TFC_SetLineScanExposureTime(5000);
                    TFC_SetLineScanExposureTime(20000);
                }
            }
            fflush(stdout);
            return 0;
        }
    """))
    prog = firmware([src])
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, track="floor", time_limit_s=2.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    images = [line.split()[1:] for line in out.splitlines() if line.startswith("image ")]
    t = {int(n): float(ts) for n, ts, _ in images}
    light = {int(n): int(s) for n, _, s in images}
    assert [round(t[n + 1] - t[n], 6) for n in range(2, 9)] == [0.01, 0.01, 0.01, 0.01, 0.02, 0.02, 0.02], t
    assert abs(light[6] - light[5]) < 0.02 * light[5], light   # the frame in progress: its own exposure
    assert light[7] > 1.4 * light[6], light                      # the next: 20 ms of light


@pytest.mark.parametrize("how", ["no-kit-calls", "isr", "mcu-time"])
def test_a_new_exposure_loads_at_the_frames_end_whatever_the_program_does_meanwhile(tmp_path, capfd, how):
    """The write loads at the PIT's expiry, not at the kit's next call: a main loop that calls no
    library function for the rest of the frame (it sleeps through spinner.h), a timer interrupt's
    handler (--isr) that writes it, a run with --mcu-time (each call costs 1 ms): the run log's
    frames go on 10 ms apart up to the end of the frame in progress, then 20 ms apart."""
    from simrunner.run.native.build import with_isrs

    src = tmp_path / "expo.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include "derivative.h"
        #include "TFC/TFC.h"
        #include "spinner.h"
        static volatile double t_call = -1.0;
        static volatile unsigned calls;
        void PIT_IRQHandler(void) {                  /* (--isr only) at 108 ms: mid-frame */
            if (++calls == 107) { TFC_SetLineScanExposureTime(20000); t_call = spinner_now(); }
        }
        int main(void) {
            TFC_Init();
            TFC_SetLineScanExposureTime(10000);
            while (TFC_Ticker[0] < 100) TFC_Task();
            if (ISR == 0) {
                while (!LineScanImageReady) TFC_Task();
                LineScanImageReady = 0;
                TFC_Delay_mS(DELAY_MS);
                TFC_SetLineScanExposureTime(20000);
                t_call = spinner_now();
                spinner_sleep(0.06);                 /* no library call: the PIT runs on */
            }
            while (TFC_Ticker[0] < 300) TFC_Task();
            printf("t_call %.6f\\n", t_call);
            fflush(stdout);
            return 0;
        }
    """))
    # (with --mcu-time the calls' own cost puts the write mid-frame)
    defines = [f"ISR={int(how == 'isr')}", f"DELAY_MS={0 if how == 'mcu-time' else 3}"]
    prog = build_program([str(src)], kit="tfc", defines=defines)
    if how == "isr":
        prog = with_isrs(prog, [("PIT_IRQHandler", 0.001)])
    r = drive(prog, track="floor", time_limit_s=2.0, csv=tmp_path / "log.csv",
              **({"mcu_time": 0.001} if how == "mcu-time" else {}))
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    t_call = float(out.split("t_call ")[1].split()[0])
    b = frames_around(r.log, t_call)
    assert b[0] < t_call - 1e-9, (t_call, b)  # (written mid-frame)
    assert [round(b[i + 1] - b[i], 6) for i in range(3)] == [0.01, 0.02, 0.02], (t_call, b)


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_library_call_from_a_thread_of_the_firmware_names_the_firmwares_line(tmp_path, isolate):
    """A thread of the team's own calling the library: its Spinner calls come from that thread,
    and the run ends at main()'s next call naming the team's line and the library's function it
    called. The library makes several calls: the second one reported from the thread itself - in
    the simulator's process it switched to the simulator's stack from there, and the process hung
    for good (so the run is a child process here, with a time-out); isolated it raced main()'s
    thread for the pipe."""
    src = tmp_path / "kit.c"
    src.write_text(textwrap.dedent("""\
        #include <pthread.h>
        #include "derivative.h"
        #include "TFC\\TFC.h"
        static void *worker(void *arg) { (void)arg; TFC_SetMotorPWM(0.2f, 0.2f); return NULL; }
        int main(void) {
            TFC_Init();
            TFC_Task();
            pthread_t t;
            pthread_create(&t, NULL, worker, NULL);
            pthread_join(t, NULL);
            for (;;)
                TFC_Task();
        }
        """))
    code = textwrap.dedent(f"""\
        import dataclasses
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        program = dataclasses.replace(build_program([{str(src)!r}], kit="tfc"), isolate={isolate})
        r = drive(program, track="floor", time_limit_s=2.0)
        print(r.outcome, r.message, sep="\\n", flush=True)
        """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    outcome, _, message = done.stdout.strip().partition("\n")
    assert outcome == "controller_error", done.stdout + done.stderr
    assert message.startswith(f"{src}:4: a Spinner call, "), message
    assert message.endswith("(in worker(), calling TFC_SetMotorPWM()); noticed by main()'s thread at its next "
                            f"call, {src}:12 (in main())"), message


def test_motor_duties_with_the_h_bridge_disabled_are_a_warning(tmp_path):
    """TFC_Init() disables the H-bridge (the library's TFC.c): a firmware that sets duties and never
    writes TFC_HBRIDGE_ENABLE stands still, on the board too - the run says why (it said nothing);
    duties set before an enable within a second are no warning."""
    src = tmp_path / "still.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\\\TFC.h"
        int main(void) {
            TFC_Init();
            TFC_SetMotorPWM(0.4f, 0.4f);
            if (TFC_GetDIP_Switch() & 1) { TFC_Delay_mS(500); TFC_HBRIDGE_ENABLE; }
            for (;;) TFC_Task();
        }
        """))
    r = drive(firmware([src]), time_limit_s=2.0)
    assert any("still.c:5: TFC_SetMotorPWM(0.40, 0.40) with the H-bridge disabled for 1.0 s: the motors stay off" in w
               and "TFC_HBRIDGE_ENABLE" in w for w in r.warnings), r.warnings
    r = drive(firmware([src]), params={"dip": 1}, time_limit_s=2.0)
    assert not any("H-bridge" in w for w in r.warnings), r.warnings


def test_pots_and_battery_read_zero_counts_until_the_adcs_first_conversion(tmp_path):
    """The library's ADC interrupts fill the pots' and the battery's counts from the first PIT0
    interrupt after TFC_Init (one exposure, 50 ms): before it - or without TFC_Init - TFC_ReadPot
    returns 1.0 (a count of 0) and the battery 0 V, on the board too; the first such read is a
    warning at its line. After it, the counts are the params' (12 bits)."""
    src = tmp_path / "early.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\TFC.h"
        #include "spinner.h"
        int main(void) {
            float before_init = TFC_ReadPot(0);
            TFC_Init();
            float at_init = TFC_ReadPot(1), battery = TFC_ReadBatteryVoltage();
            TFC_Delay_mS(40);
            float still = TFC_ReadPot(0);
            TFC_Delay_mS(20);
            float pot = TFC_ReadPot(0), pot1 = TFC_ReadPot(1), later_battery = TFC_ReadBatteryVoltage();
            spinner_add_textf("%g %g %g %g %.6f %.6f %.4f", before_init, at_init, battery, still, pot, pot1, later_battery);
            return 0;
        }
        """))
    r = drive(firmware([src]), params={"pot0": -0.25, "pot1": 1.0}, time_limit_s=1.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    text = [t for t in r.log.data_text if t][-1]
    # -0.25 -> count lround(1.25 x 2047.5) = 2559 -> 1 - 2559 / 2047.5; 1.0 -> count 0 -> 1.0;
    # the battery: 7.2 V x 10/57 of 3.3 V in 4095 counts (1567), x 3.0 / 4095
    assert text == f"1 1 0 1 {1 - 2559 / 2047.5:.6f} 1.000000 {1567 / 4095 * 3.0:.4f}", text
    early = [w for w in r.warnings if "before" in w and "ADC" in w]
    assert len(early) == 2, r.warnings
    assert early[0].startswith(f"{src}:5: TFC_ReadPot(0) before TFC_Init(): ") and "returns 1.0" in early[0]
    m = re.match(re.escape(str(src)) + r":7: TFC_ReadBatteryVoltage\(\) at t = ([0-9.]+) s, before the ADC's first conversion "
                 r"\(([0-9.]+) s: the first PIT0 interrupt, one exposure after TFC_Init\)", early[1])
    assert m and float(m[2]) - float(m[1]) == pytest.approx(0.050) and "returns 0 V" in early[1], early[1]


MOTORS = ("TFC_HBRIDGE_ENABLE;\n    TFC_SetMotorPWM(0.3f, 0.3f);",
          "6: TFC_SetMotorPWM() before TFC_Init() (or TFC_InitMotorPWM()): on the board the library's write reads "
          "TPM0_MOD while TPM0's clock is still gated off")
SERVO = ("TFC_SetServo(0, 0.2f);",
         "5: TFC_SetServo() before TFC_Init() (or TFC_InitServos()): on the board the library's write reads TPM1_MOD")


@pytest.mark.parametrize("calls, init, said", [
    (MOTORS, "", MOTORS[1]), (MOTORS, "TFC_InitMotorPWM();", None), (MOTORS, "TFC_Init();", None),
    (SERVO, "", SERVO[1]), (SERVO, "TFC_InitServos();", None), (SERVO, "TFC_Init();", None)])
def test_motors_or_servo_before_the_library_clocks_their_timer_end_the_run_at_the_call(tmp_path, calls, init, said):
    """The library's TFC_SetMotorPWM reads TPM0_MOD, whose clock TFC_InitMotorPWM (TFC_Init) opens; its
    TFC_SetServoDutyCycle (TFC_SetServo's) writes TPM1_C0V = TPM1_MOD * DutyCycle, TPM1's clock opened
    by TFC_InitServos (TFC_Init): before them the board stops in a bus fault. The kit drove the car;
    now the run ends at the call, saying why; either init call opens its timer."""
    src = tmp_path / "early.c"
    src.write_text(textwrap.dedent(f"""\
        #include "derivative.h"
        #include "TFC\\TFC.h"
        int main(void) {{
            {init}
            {calls[0]}
            for (;;) TFC_Task();
        }}
        """))
    r = drive(firmware([src]), time_limit_s=0.5)
    assert r.outcome == ("controller_error" if said else "timeout"), r.message
    if said:
        assert r.message.startswith(f"{src}:{said}"), r.message


def test_a_program_that_clocks_the_camera_itself_is_named(tmp_path):
    """The library's TAOS_SI_HIGH, TAOS_CLK_HIGH, ... (its TFC_LineScanCamera.h: GPIO writes) are
    there; a program that reads the camera out with them is not emulated, and its build says so
    after the compiler's line (it said only "TAOS_SI_HIGH undeclared")."""
    src = tmp_path / "cam.c"
    src.write_text('#include "derivative.h"\n#include "TFC/TFC.h"\n'
                   'int main(void) { TFC_Init(); TAOS_SI_HIGH; TAOS_CLK_HIGH; TAOS_SI_LOW; return 0; }\n')
    with pytest.raises(ControllerFileError, match=r"(?s)cam.c:3:.*GPIOD_PCOR, GPIOD_PSOR, GPIOE_PSOR: the MCU's "
                                                  r"registers, not emulated .* - TAOS_CLK_HIGH, TAOS_SI_HIGH, "
                                                  r"TAOS_SI_LOW are the library's camera pins"):
        firmware([src])
