"""The NXP Cup S32K144 kit's drivers on the simulated car (issue 50 item 1, simrunner drive
--kit s32k144): a team's firmware builds unchanged against the simulator's servo.h,
hbridge.h, linear_camera.h, display.h ... and drives."""
from __future__ import annotations

import dataclasses
import re
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
FIRMWARE = REPO / "examples" / "firmware" / "s32k144" / "main.c"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"
MAX_SPEED_MPS = 3.1  # the default car's drive.max_speed_mps: a full duty's speed


def firmware(sources, **kw):
    return build_program([str(s) for s in sources], kit="s32k144", **kw)


def probe(tmp_path, body, name="probe.c"):
    src = tmp_path / name
    src.write_text(textwrap.dedent(body))
    return src


def test_the_example_firmware_builds_unchanged_and_laps():
    """examples/firmware/s32k144/main.c (the NXP sample's structure: DriversInit, ServoInit,
    HbridgeInit, DisplayInit, LinearCameraInit, a blocking LinearCameraGetFrame loop) builds
    without a warning and laps the default track as the Python line follower it mirrors."""
    program = firmware([FIRMWARE])
    assert program.warnings == ""
    r = drive(program, laps=2)
    follower = drive(REPO / "examples" / "line_follower.py", laps=2)
    assert r.outcome == "finished" and r.laps_completed == 2, r.message
    assert r.lap_times_s[1] == pytest.approx(follower.lap_times_s[1], rel=0.05)


@pytest.mark.parametrize("hbridge", ["brake", "coast"])  # coast: the kit's L298N, PWM on its enable
def test_the_example_firmware_laps_a_duty_driven_car(tmp_path, hbridge):
    """With drive.command = "duty" HbridgeSetSpeed's duty drives the two rear motors."""
    car = tmp_path / "duty.toml"
    car.write_text(f'[drive]\ncommand = "duty"\nhbridge = "{hbridge}"\n')
    r = drive(firmware([FIRMWARE]), car=car, laps=2)
    assert r.outcome == "finished" and r.laps_completed == 2, r.message
    assert r.log.duty_left is not None and np.nanmax(r.log.duty_left) > 0.4
    assert np.array_equal(r.log.duty_left, r.log.duty_right)  # HbridgeSetSpeed drives both alike


@pytest.mark.skipif(not SHARED_TRACKS.is_dir(), reason="../shared/tracks not present")
def test_the_example_firmware_laps_both_nxp_tracks():
    for name in ("nxp_raceway", "nxp_raceway_octagon"):
        r = drive(firmware([FIRMWARE]), track=SHARED_TRACKS / name)
        assert r.outcome == "finished", (name, r.message)


def test_the_drivers_map_onto_the_car(tmp_path):
    """Steer's -100..100 is the servo's calibrated travel (+ = right), HbridgeSetSpeed's
    percentage a duty (its sign from the direction pins, 0 while braking), a frame is 128
    pixels of 0..99, OsIf counts simulated ms, the display's lines reach the run log."""
    src = probe(tmp_path, """\
        #include "servo.h"
        #include "hbridge.h"
        #include "linear_camera.h"
        #include "display.h"
        #include "main_functions.h"
        #include "OsIf.h"
        int main(void) {
            LinearCameraFrame f;
            DriversInit();
            ServoInit(1U, 3300U, 1700U, 2500U);
            HbridgeInit(2U, 3U, 32U, 33U, 6U, 64U);
            DisplayInit(1U);                     /* the sample's first, one-argument version */
            LinearCameraInit(4U, 1U, 0U, 97U);
            uint32 t0 = OsIf_GetMilliseconds();
            OsIf_TimeDelay(100U);
            uint32 dt = OsIf_GetMilliseconds() - t0;
            if (dt < 100U || dt > 104U) return 1;
            LinearCameraGetFrame(&f);
            int bright = 0;
            for (int i = 0; i < 128; i++) { if (f.Values[i] > 99U) return 2; bright += f.Values[i] > 50U; }
            if (bright < 20) return 3;           /* the white lane */
            Steer(50); HbridgeSetSpeed(50);      /* window A: half right, half forward */
            OsIf_TimeDelay(200U);
            SteerLeft(); HbridgeSetSpeed(-30);   /* window B: full left, 30 % backward */
            OsIf_TimeDelay(200U);
            HbridgeSetBrake(1U); HbridgeSetSpeed(80);  /* window C: braking ignores the speed */
            if (HbridgeGetSpeed() != 80 || HbridgeGetBrake() != 1U) return 4;
            OsIf_TimeDelay(200U);
            HbridgeSetBrake(0U); Steer(-250);    /* window D: the 80 % resumes; Steer clamps */
            DisplayText(0U, "probe", 5U, 0U);
            DisplayValue(1U, -42, 4U, 0U);
            DisplayRefresh();
            OsIf_TimeDelay(200U);
            return 0;
        }
        """)
    r = drive(firmware([src]), time_limit_s=5.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    log = r.log
    t_end = log.t_s[-1]

    def window(k):  # the logged frames well inside window k (0 = A) of the four 0.2 s windows
        return (log.t_s > t_end - 0.8 + 0.2 * k + 0.03) & (log.t_s < t_end - 0.6 + 0.2 * k - 0.01)

    def duty(percent):  # the driver's integer duty of 0x8000, as a fraction
        return np.sign(percent) * (abs(percent) * 0x8000 // 100) / 0x8000

    expected = [(-0.2, duty(50)), (0.4, duty(-30)), (0.4, 0.0), (0.4, duty(80))]  # (steer rad, duty)
    for k, (steer, want) in enumerate(expected):
        w = window(k)
        assert w.sum() >= 5
        assert np.allclose(log.steer_cmd_rad[w], steer), (k, log.steer_cmd_rad[w][:3])
        assert np.allclose(log.speed_cmd_mps[w], want * MAX_SPEED_MPS), (k, log.speed_cmd_mps[w][:3])
    assert "probe" in (tmp_path / "log.csv").read_text() and "-42" in (tmp_path / "log.csv").read_text()


def test_the_servo_param_and_the_esc(tmp_path):
    """--param s32k_servo_rad scales (and with a minus flips) the servo; the ESC's pulse is a
    duty of both motors: EscSetSpeed(40) is 40 %."""
    src = probe(tmp_path, """\
        #include "servo.h"
        #include "esc.h"
        #include "OsIf.h"
        int main(void) {
            ServoInit(1U, 3300U, 1700U, 2500U);
            EscInit(0U, 1638U, 2457U, 3276U);
            SteerRight();
            EscSetSpeed(40);
            OsIf_TimeDelay(100U);
            return 0;
        }
        """)
    r = drive(firmware([src]), params={"s32k_servo_rad": -0.3}, time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    late = r.log.t_s > r.log.t_s[-1] - 0.05
    assert np.allclose(r.log.steer_cmd_rad[late], 0.3)  # full right, flipped: + 0.3 rad
    pulse = 40 * (3276 - 2457) // 100  # the driver's integer pulse above the stop pulse
    assert np.allclose(r.log.speed_cmd_mps[late], pulse / (3276 - 2457) * MAX_SPEED_MPS)


def test_kit_misuse_is_one_line(tmp_path, capfd):
    with pytest.raises(ControllerFileError, match=r"--kit stm32: expected one of tfc, s32k144"):
        build_program([str(FIRMWARE)], kit="stm32")
    # the team's copy of a kit driver: the simulator's replaces it
    servo_c = probe(tmp_path, '#include "servo.h"\nvoid Steer(int d) { (void)d; }\n', "servo.c")
    with pytest.raises(ControllerFileError, match=r"servo.c: the kit's own driver source: --kit s32k144 "
                                                  r"provides servo.h's functions"):
        firmware([FIRMWARE, servo_c])
    # an RTD call the simulator has not: a compile error at its line, not a failure at load
    icu = probe(tmp_path, '#include "Icu.h"\n\nint main(void) { Icu_StartSignalMeasurement(0U); return 0; }\n',
                "icu.c")
    with pytest.raises(ControllerFileError, match=r"icu.c:3:.*Icu_StartSignalMeasurement"):
        firmware([icu])
    regs = probe(tmp_path, '#include "Mcal.h"\n#include "S32K144.h"\nint main(void) { return 0; }\n', "regs.c")
    with pytest.raises(ControllerFileError, match=r"regs.c:2:.*S32K144.h"):
        firmware([regs])
    # a driver call the simulator does not emulate: the run stops at the caller's line, saying why
    bench = probe(tmp_path, '#include "main_functions.h"\n\nint main(void) { ServoTest(); return 0; }\n', "bench.c")
    r = drive(firmware([bench]), time_limit_s=1.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{bench}:3: ServoTest: not emulated by the simulator's S32K144 kit: "
                                "the drivers' bench test loops for ever"), r.message
    notify = probe(tmp_path, """\
        #include "Gpt.h"
        int main(void) {
            Gpt_StartTimer(2U, 8000U);
            Gpt_EnableNotification(2U);
            return 0;
        }
        """, "notify.c")
    r = drive(firmware([notify]), time_limit_s=1.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{notify}:4: Gpt_EnableNotification: channel 2 has no notification") and \
        "-D GPT_NOTIFICATION_2=NAME" in r.message, r.message
    typo = probe(tmp_path, """\
        #include "Gpt.h"
        void Gpt_Notifcation(void) {}
        int main(void) {
            Gpt_StartTimer(0U, 8000U);
            Gpt_EnableNotification(0U);
            return 0;
        }
        """, "typo.c")  # channel 0's notification misspelt: the name the program defines is said
    r = drive(firmware([typo]), time_limit_s=1.0)
    assert "notification Gpt_Notification (it defines Gpt_Notifcation: misspelt?)" in r.message, r.message
    res = CliRunner().invoke(cli, ["drive", str(REPO / "examples" / "line_follower.py"), "--kit", "s32k144"])
    assert res.exit_code == 2 and "--kit is for C/C++ controllers" in res.output


PIXY_CAR = REPO / "examples" / "pixy2_car.toml"


def test_the_pixy2_driver_reads_the_simulated_pixy2(tmp_path, capfd):
    """Pixy2GetVectors (the NXP Cup guide's driver) and PixyGetVectors (its earlier version)
    give the vectors the simulator's Pixy2 C API gives for the same frames, one frame a call at
    the Pixy2's 60 Hz, and leave the Pixy2's reply packet in PixyReceivedLinesBuffer: sync
    175 193, type 49, the payload length, its 16-bit sum, a LINE_VECTOR block of 6 bytes a
    vector; the earlier version's 50-byte read holds at most 7 vectors."""
    kit = probe(tmp_path, """\
        #include <stdio.h>
        #include "pixy2.h"
        #include "OsIf.h"
        int main(void) {
            DetectedVectors v;
            Pixy2Init(0x54, 0U);
            Pixy2SetLed(0U, 255U, 0U);
            for (int i = 0; i < 4; i++) {
                Pixy2GetVectors(&v);
                printf("frame %u:", v.NumberOfVectors);
                for (int j = 0; j < v.NumberOfVectors; j++)
                    printf(" %u,%u,%u,%u,%u", v.Vectors[j].x0, v.Vectors[j].y0, v.Vectors[j].x1,
                           v.Vectors[j].y1, v.Vectors[j].VectorIndex);
                printf("\\n");
            }
            printf("packet");
            for (int i = 0; i < 8 + 6 * v.NumberOfVectors; i++) printf(" %u", PixyReceivedLinesBuffer[i]);
            printf("\\n");
            uint32 t0 = OsIf_GetMilliseconds();
            for (int i = 0; i < 6; i++) Pixy2GetVectors(&v);
            printf("six frames %u ms\\n", OsIf_GetMilliseconds() - t0);
            DetectedVectors old = PixyGetVectors();
            printf("earlier %u\\n", old.NumberOfVectors);
            return 0;
        }
        """)
    direct = probe(tmp_path, """\
        #include <stdio.h>
        #include "pixy2_line.h"
        int main(void) {
            pixy2_line_features f;
            pixy2_init();
            for (int i = 0; i < 4; i++) {
                pixy2_line_get_all_features(LINE_VECTOR, true, &f);
                printf("frame %u:", f.numVectors);
                for (int j = 0; j < f.numVectors; j++)
                    printf(" %u,%u,%u,%u,%u", f.vectors[j].m_x0, f.vectors[j].m_y0, f.vectors[j].m_x1,
                           f.vectors[j].m_y1, f.vectors[j].m_index);
                printf("\\n");
            }
            return 0;
        }
        """, "direct.c")
    capfd.readouterr()
    r = drive(firmware([kit]), car=PIXY_CAR, time_limit_s=2.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", r.message
    r = drive(direct, car=PIXY_CAR, time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    frames = [line for line in out.splitlines() if line.startswith("frame")]
    assert frames == [line for line in capfd.readouterr().out.splitlines() if line.startswith("frame")]
    last = frames[-1].split(":")[1].split()
    assert len(last) >= 2  # the lane's two edge lines
    vectors = [tuple(int(x) for x in v.split(",")) for v in last]
    assert all(x0 <= 78 and y0 <= 51 and x1 <= 78 and y1 <= 51 for x0, y0, x1, y1, _ in vectors)
    packet = [int(b) for b in next(line for line in out.splitlines() if line.startswith("packet")).split()[1:]]
    n = len(vectors)
    assert packet[:4] == [175, 193, 49, 2 + 6 * n] and packet[6:8] == [1, 6 * n]
    assert packet[4] + 256 * packet[5] == sum(packet[6:])
    assert [tuple(packet[8 + 6 * i:8 + 6 * i + 5]) for i in range(n)] == vectors
    six_ms = int(out.split("six frames ")[1].split()[0])
    assert 6000 / 60 - 3 <= six_ms <= 6000 / 60 + 3 + 1000 / 60  # a frame a call at 60 Hz
    assert 1 <= int(out.split("earlier ")[1].split()[0]) <= 7


def test_gpt_channels_and_osif_counters_count_simulated_time(tmp_path, capfd):
    """Gpt_StartTimer's channel counts --param s32k_gpt_tick_hz ticks of simulated time,
    continuously (wrapping at its target), the count of its stop once stopped; OsIf's system counter counts
    s32k_osif_hz (48 MHz by default) and a busy-wait on OsIf_GetElapsed ends after its
    simulated microseconds; the dummy counter counts calls. The headers answer to the
    spellings of a Windows-made project (Osif.h, std_types.h)."""
    src = probe(tmp_path, """\
        #include <stdio.h>
        #include "std_types.h"
        #include "Osif.h"
        #include "Gpt.h"
        int main(void) {
            OsIf_Init(NULL_PTR);
            Gpt_StartTimer(1U, 1000000U);
            Gpt_StartTimer(2U, 5000U);
            OsIf_TimeDelay(12U);
            uint32 e1 = Gpt_GetTimeElapsed(1U), e2 = Gpt_GetTimeElapsed(2U), r2 = Gpt_GetTimeRemaining(2U);
            Gpt_StopTimer(1U);
            printf("gpt %u %u %u %u\\n", e1, e2, r2, Gpt_GetTimeElapsed(1U));
            uint32 ticks = OsIf_MicrosToTicks(5000U, OSIF_COUNTER_SYSTEM);
            uint32 ref = OsIf_GetCounter(OSIF_COUNTER_SYSTEM), elapsed = 0U, t0 = OsIf_GetMilliseconds();
            while (elapsed < ticks) elapsed += OsIf_GetElapsed(&ref, OSIF_COUNTER_SYSTEM);
            uint32 waited = OsIf_GetMilliseconds() - t0;
            uint32 d = OsIf_GetCounter(OSIF_COUNTER_DUMMY);
            printf("osif %u %u %u %u\\n", ticks, waited, OsIf_GetCounter(OSIF_COUNTER_DUMMY) - d,
                   OsIf_MicrosToTicks(5000U, OSIF_COUNTER_DUMMY));
            return 0;
        }
        """)
    capfd.readouterr()
    r = drive(firmware([src]), params={"s32k_gpt_tick_hz": 1e6}, time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    out = capfd.readouterr().out
    e1, e2, r2, stopped = (int(x) for x in out.split("gpt ")[1].split()[:4])
    # starts and reads let no time pass: both channels start at 0, the reads come at 12 ms, the
    # stopped channel keeps its count of 12 ms
    assert (e1, e2, r2, stopped) == (12000, 12000 % 5000, 5000 - 12000 % 5000, 12000)
    ticks, waited, dummy_step, dummy_ticks = (int(x) for x in out.split("osif ")[1].split()[:4])
    assert ticks == 5000 * 48 and 5 <= waited <= 5 + 3 * 2 and dummy_step == 1 and dummy_ticks == 5000


def test_firmware_reads_encoders_and_the_imu_through_spinner_h(tmp_path):
    """The sample's drivers have no encoder or IMU driver: a --kit s32k144 firmware reads the car
    file's [encoders] and [imu] with spinner.h's calls beside the drivers."""
    src = probe(tmp_path, """\
        #include "main_functions.h"
        #include "hbridge.h"
        #include "OsIf.h"
        #include "spinner.h"
        int main(void) {
            double gz, az;
            DriversInit();
            HbridgeInit(0U, 1U, 0U, 1U, 2U, 3U);
            HbridgeSetSpeed(30);
            OsIf_TimeDelay(1500U);
            long long rl = spinner_get_encoder(SPINNER_WHEEL_RL), rr = spinner_get_encoder(SPINNER_WHEEL_RR);
            spinner_get_gyro(NULL, NULL, &gz);
            spinner_get_accel(NULL, NULL, &az);
            if (rl < 5000 || rr < 0.98 * rl || rr > 1.02 * rl) return 1;
            if (az < 9.3 || az > 10.3 || gz > 0.2 || gz < -0.2) return 2;
            return 0;
        }
        """, name="main.c")
    car = tmp_path / "car.toml"
    car.write_text("[encoders]\n[imu]\n")
    r = drive(firmware([src]), track="floor", car=car, time_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message


def test_a_cpp_firmware_builds_against_the_kit(tmp_path, capfd):
    """A team's C++ sources (main.cpp) build against the kit's headers without a warning, as in
    the sample's C++-ready headers (extern "C"): the sample's two DisplayInit versions (one
    argument, two), the RTD's Pwm_SetDutyCycle and Dio calls made directly (C linkage: a C++
    call of a mangled name would not link), a Gpt notification defined extern "C"; it runs
    alike in process and isolated."""
    src = probe(tmp_path, """\
        #include <cstdio>
        #include "Mcal.h"
        #include "Pwm.h"
        #include "Dio.h"
        #include "Gpt.h"
        #include "OsIf.h"
        #include "servo.h"
        #include "display.h"
        static volatile int calls;
        extern "C" void Control_Notification(void) { calls++; }
        int main() {
            DisplayInit(0U, STD_ON);             /* the sample's later, two-argument version */
            DisplayInit(STD_ON);                 /* and its first */
            ServoInit(1U, 3300U, 1700U, 2500U);
            Pwm_SetDutyCycle(1U, 3300U);         /* the servo's channel, written directly: full right */
            Dio_WriteChannel(97U, STD_HIGH);
            Gpt_StartTimer(2U, 80000U);          /* 10 ms of 8 MHz */
            Gpt_EnableNotification(2U);
            OsIf_TimeDelay(100U);
            std::printf("cpp %u %d\\n", (unsigned)Dio_ReadChannel(97U), (int)calls);
            return 0;
        }
        """, "main.cpp")
    program = firmware([src], defines=["GPT_NOTIFICATION_2=Control_Notification"])
    assert program.warnings == "", program.warnings
    for isolate in (False, True):
        capfd.readouterr()
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0)
        assert r.outcome == "controller_returned", (isolate, r.message)
        assert capfd.readouterr().out.split("cpp ")[1].split()[:2] == ["1", "10"], isolate
        assert np.allclose(r.log.steer_cmd_rad[r.log.t_s > 0.05], -0.40), isolate  # full right


@pytest.mark.parametrize("mirrored", [False, True])
def test_a_mirrored_servo_calibration_steers_as_servo_init_says(tmp_path, mirrored):
    """ServoInit(ch, Max, Min, Med) names the pulse of full right (Max) and full left (Min),
    whichever is the shorter: a team whose linkage is mirrored passes Max < Med < Min, and the
    sample's Steer() goes from Med towards Max for + and towards Min for - (src/servo.c:
    Med + Direction * (Max - Med) / 100; Med - Direction * (Min - Med) / 100), so Steer(50) is
    half right, SteerLeft() full left either way (was: a mirrored calibration steered 0)."""
    mx, mn = ("1700U", "3300U") if mirrored else ("3300U", "1700U")
    src = probe(tmp_path, f"""\
        #include "servo.h"
        #include "OsIf.h"
        int main(void) {{
            ServoInit(1U, {mx}, {mn}, 2500U);
            Steer(50);
            OsIf_TimeDelay(100U);
            SteerLeft();
            OsIf_TimeDelay(100U);
            Steer(-250);
            OsIf_TimeDelay(100U);
            return 0;
        }}
        """)
    r = drive(firmware([src]), track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    t, steer = r.log.t_s, r.log.steer_cmd_rad
    assert np.allclose(steer[(t > 0.01) & (t < 0.09)], -0.20)   # half right
    assert np.allclose(steer[(t > 0.11) & (t < 0.19)], 0.40)    # full left
    assert np.allclose(steer[(t > 0.21) & (t < 0.29)], 0.40)    # Steer clamps at -100: full left


def test_the_display_writes_values_and_text_as_the_samples_driver(tmp_path):
    """DisplayValue writes the number from TextOffset on, left-aligned, and blanks the rest of
    its TextLength (the sample's src/display.c: the digits first, then ' '); a number longer
    than TextLength shows its first TextLength characters. DisplayText writes TextLength
    characters: those past the string's end are blank (its NUL is the font's blank glyph), not
    what the screen held. Alike in process and isolated."""
    src = probe(tmp_path, """\
        #include "display.h"
        #include "OsIf.h"
        int main(void) {
            DisplayInit(0U, STD_OFF);
            DisplayText(0U, "################", 16U, 0U);
            DisplayValue(0U, 42, 4U, 0U);
            DisplayValue(0U, -42, 5U, 5U);
            DisplayValue(0U, 0, 3U, 11U);
            DisplayValue(1U, 123456, 3U, 0U);
            DisplayText(2U, "speed", 5U, 0U);
            DisplayText(2U, "ok", 5U, 0U);
            DisplayRefresh();
            OsIf_TimeDelay(40U);
            return 0;
        }
        """)
    program = firmware([src])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  csv=tmp_path / f"log{isolate}.csv")
        assert r.outcome == "controller_returned", (isolate, r.message)
        text = [s for s in r.log.data_text if s][-1].split(" | ")
        assert text[:3] == ["42  #-42  #0  ##", "123             ", "ok              "], (isolate, text)


def test_a_cpp_notification_without_extern_c_is_named_so(tmp_path):
    """A C++ team defines its Gpt notification without extern "C": the RTD's generated C
    configuration could not call it (on the board the link fails); the run's error names the
    function as the program spells it and says to declare it extern "C" - not its mangled name
    as a misspelling. Alike in process and isolated."""
    src = probe(tmp_path, """\
        #include "Gpt.h"
        void Control_Notification(void) {}
        int main() {
            Gpt_StartTimer(2U, 80000U);
            Gpt_EnableNotification(2U);
            return 0;
        }
        """, "main.cpp")
    program = firmware([src], defines=["GPT_NOTIFICATION_2=Control_Notification"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0)
        assert r.outcome == "controller_error", (isolate, r.message)
        assert r.message.startswith(f"{src}:5: Gpt_EnableNotification: channel 2's notification "
                                    "Control_Notification (it defines Control_Notification with C++ linkage: "
                                    "declare it extern \"C\")"), (isolate, r.message)
        assert "_Z" not in r.message, (isolate, r.message)


def test_a_loop_polling_a_pin_nothing_drives_ends_at_its_line(tmp_path):
    """A start-button wait (while (Dio_ReadChannel(SW2) == STD_LOW);): the simulator drives no
    pin (a button, a sensor's echo reads what was last written to it), so the loop would never
    end; the run ends at its line at once, naming the channel and why - not as stalled after the
    wall-time limit with Spinner's advice. A loop that writes between its reads (bit-banging) is
    not stopped. Alike in process and isolated."""
    src = probe(tmp_path, """\
        #include "Dio.h"
        #include "OsIf.h"
        int main(void) {
            for (long i = 0; i < 300000; i++) { Dio_WriteChannel(5U, (Dio_LevelType)(i & 1)); (void)Dio_ReadChannel(5U); }
            OsIf_TimeDelay(10U);
            while (Dio_ReadChannel(76U) == STD_LOW) {
            }
            return 0;
        }
        """)
    program = firmware([src])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0, wall_limit_s=30.0)
        assert r.outcome == "controller_error", (isolate, r.message)
        assert r.message.startswith(f"{src}:6: Dio_ReadChannel(76): read "), (isolate, r.message)
        assert "reads what was last written to it" in r.message and r.sim_time_s > 0.009, (isolate, r.message)
    # a pin no --param names is still undriven when others are inputs; the message says how to drive it
    r = drive(program, track="floor", time_limit_s=1.0, wall_limit_s=30.0, params={"s32k_sw2": 77})
    assert r.outcome == "controller_error" and r.message.startswith(f"{src}:6: Dio_ReadChannel(76): read "), r.message
    assert "--param names (s32k_sw2, s32k_sw3" in r.message and "s32k_pin_76=0/1" in r.message, r.message


def button_times(tmp_path, capfd, params, *, pin="76U"):
    """The simulated times (s) a firmware's start-button wait sees the button pressed and then
    released (a loop polling the pin with no library call, writing an LED pin and the button's own
    pin between reads), in process and isolated (alike)."""
    src = probe(tmp_path, f"""\
        #include <stdio.h>
        #include "Dio.h"
        #include "spinner.h"
        int main(void) {{
            Dio_WriteChannel({pin}, STD_HIGH);       /* an input pin: the write is ignored */
            while (Dio_ReadChannel({pin}) == STD_LOW) {{
                Dio_WriteChannel(5U, STD_HIGH);
            }}
            double pressed = spinner_now();
            while (Dio_ReadChannel({pin}) == STD_HIGH);
            printf("button %.6f %.6f\\n", pressed, spinner_now());
            return 0;
        }}
        """)
    program = firmware([src])
    assert program.warnings == "", program.warnings
    times = []
    for isolate in (False, True):
        capfd.readouterr()
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0,
                  wall_limit_s=30.0, params=params)
        assert r.outcome == "controller_returned", (isolate, r.message)
        times.append(tuple(float(x) for x in capfd.readouterr().out.split("button ")[1].split()[:2]))
    assert times[0] == times[1]
    return times[0]


STEP_S = 0.002  # the default physics step


@pytest.mark.parametrize("params, at", [
    ({"s32k_sw2": 76}, 0.1),                           # SW2's start press: 0.2 s from 0.1 s
    ({"s32k_sw2": 76, "s32k_sw2_at": 0.333}, 0.333),
    ({"s32k_sw2": 12, "s32k_sw3": 76, "s32k_sw3_at": 0.5}, 0.5),  # SW3, pressed when asked
])
def test_a_start_button_wait_ends_at_the_press(tmp_path, capfd, params, at):
    """--param s32k_sw2=N says SW2's Dio channel (s32k_sw3 SW3's): it reads STD_HIGH while pressed
    (the S32K144EVB's buttons), 0.2 s from s32k_sw2_at (default 0.1 s, --kit tfc's start press).
    A loop polling it lets simulated time pass, so it ends at the press, within a physics step,
    and a wait for the release 0.2 s later; writes to the pin are ignored (an input)."""
    pressed, released = button_times(tmp_path, capfd, params)
    assert at - 1e-9 <= pressed <= at + STEP_S + 1e-9, (pressed, at)
    assert at + 0.2 - 1e-9 <= released <= at + 0.2 + STEP_S + 1e-9, (released, at)


def level_edges(tmp_path, capfd, params, pin="76U", until_s=1.5):
    """The simulated times (s) at which a firmware polling `pin` sees its level change, and the
    level it read first (a loop of reads, each 64 at one time letting a physics step pass)."""
    src = probe(tmp_path, f"""\
        #include <stdio.h>
        #include "Dio.h"
        #include "spinner.h"
        int main(void) {{
            Dio_LevelType last = Dio_ReadChannel({pin});
            printf("first %u\\n", last);
            while (spinner_now() < {until_s}) {{
                Dio_LevelType now = Dio_ReadChannel({pin});
                if (now != last) printf("edge %.6f %u\\n", spinner_now(), now), last = now;
            }}
            return 0;
        }}
        """, name="edges.c")
    r = drive(firmware([src]), track="floor", time_limit_s=until_s + 0.5, wall_limit_s=60.0, params=params)
    assert r.outcome == "controller_returned", r.message
    out = capfd.readouterr().out
    first = int(out.split("first ")[1].split()[0])
    edges = [(float(t), int(v)) for t, v in re.findall(r"edge ([0-9.]+) (\d)", out)]
    return first, edges


def test_a_button_wired_active_low_reads_low_while_pressed(tmp_path, capfd):
    """--param s32k_sw2_pressed_level=0 (a team board's button to ground with a pull-up): SW2 reads
    STD_HIGH released and STD_LOW while pressed, the 0.2 s from s32k_sw2_at; the EVB's default (1)
    reads the other way. Before: the level was STD_HIGH while pressed whatever the board."""
    first, edges = level_edges(tmp_path, capfd, {"s32k_sw2": 76, "s32k_sw2_at": 0.3, "s32k_sw2_pressed_level": 0})
    assert first == 1 and [v for _, v in edges] == [0, 1], (first, edges)
    assert edges[0][0] == pytest.approx(0.3, abs=STEP_S + 1e-9) and edges[1][0] == pytest.approx(0.5, abs=STEP_S + 1e-9)
    first, edges = level_edges(tmp_path, capfd, {"s32k_sw2": 76, "s32k_sw2_at": 0.3})
    assert first == 0 and [v for _, v in edges] == [1, 0], (first, edges)


def test_a_button_pressed_several_times(tmp_path, capfd):
    """s32k_sw3_at, s32k_sw3_at_2, s32k_sw3_at_3: SW3 pressed three times, 0.2 s each (numbered
    params: a comma list would be batch's sweep). Before: one press only, the later ones unread."""
    params = {"s32k_sw3": 76, "s32k_sw3_at": 0.2, "s32k_sw3_at_2": 0.6, "s32k_sw3_at_3": 1.0}
    first, edges = level_edges(tmp_path, capfd, params)
    assert first == 0 and [v for _, v in edges] == [1, 0] * 3, (first, edges)
    for (t, _), want in zip(edges, (0.2, 0.4, 0.6, 0.8, 1.0, 1.2)):
        assert t == pytest.approx(want, abs=STEP_S + 1e-9), edges


@pytest.mark.parametrize("params, expected", [
    ({"s32k_sw2": 3, "s32k_sw2_pressed_level": 2}, "--param s32k_sw2_pressed_level=2: expected 0 or 1: the level the "
                                                   "pin reads while the button is pressed"),
    ({"s32k_sw2": 3, "s32k_sw2_at": 0.5, "s32k_sw2_at_2": 0.6}, "--param s32k_sw2_at_2=0.6: expected a press after the "
                                                                "one before it is released: 0.7 s or later"),
    ({"s32k_sw3": 3, "s32k_sw3_at_2": 0.6}, "--param s32k_sw3_at_2=0.6: expected the presses before it given too"),
], ids=["level", "overlapping", "second_without_first"])
def test_a_bad_press_param_is_one_line(tmp_path, params, expected):
    src = probe(tmp_path, """\
        #include "Dio.h"
        int main(void) {
            (void)Dio_ReadChannel(7U);
            return 0;
        }
        """)
    r = drive(firmware([src]), track="floor", time_limit_s=1.0, params=params)
    assert r.outcome == "controller_error", (params, r.message)
    assert r.message.startswith(f"{src}:3: {expected}") and "\n" not in r.message, (params, r.message)


def test_a_mode_pin_reads_its_constant_level(tmp_path, capfd):
    """--param s32k_pin_N=0/1: channel N is an input at that level (a mode switch): writes and
    flips leave it (a flip returns its level, as the Dio driver's on an input channel), a poll of
    it lets time pass; the other channels read what was written to them, SW3 not pressed unless
    s32k_sw3_at is given."""
    src = probe(tmp_path, """\
        #include <stdio.h>
        #include "Dio.h"
        #include "spinner.h"
        int main(void) {
            Dio_WriteChannel(40U, STD_LOW);
            Dio_WriteChannel(41U, STD_HIGH);
            Dio_WriteChannel(42U, STD_HIGH);
            unsigned flip40 = Dio_FlipChannel(40U), flip42 = Dio_FlipChannel(42U);
            int polls = 0;
            while (Dio_ReadChannel(40U) == STD_HIGH && polls < 1000) polls++;
            printf("mode %u %u %u %u %u %u %.3f\\n", Dio_ReadChannel(40U), Dio_ReadChannel(41U), Dio_ReadChannel(42U),
                   flip40, flip42, Dio_ReadChannel(43U), spinner_now());
            return 0;
        }
        """)
    program = firmware([src])
    for isolate in (False, True):
        capfd.readouterr()
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=3.0,
                  params={"s32k_pin_40": 1, "s32k_pin_41": 0, "s32k_sw3": 43})
        assert r.outcome == "controller_returned", (isolate, r.message)
        out = capfd.readouterr().out.split("mode ")[1].split()[:7]
        # 40 and 41 keep their levels; 42 is the program's (flipped to low); SW3 released
        assert out[:6] == ["1", "0", "0", "1", "0", "0"], (isolate, out)
        assert float(out[6]) == pytest.approx((1000 - 64) * STEP_S, abs=2 * STEP_S), (isolate, out)


@pytest.mark.parametrize("params, expected", [
    ({"s32k_sw2": 300}, "--param s32k_sw2=300: expected the Dio channel of the board's button SW2 (PTC12): a whole "
                        "number 0..255"),
    ({"s32k_sw3": 2.5}, "--param s32k_sw3=2.5: expected the Dio channel of the board's button SW3 (PTC13)"),
    ({"s32k_sw2": 3, "s32k_sw2_at": -1}, "--param s32k_sw2_at=-1: expected the simulated time of the press"),
    ({"s32k_sw3_at": 0.5}, "--param s32k_sw3_at=0.5: expected the button's Dio channel too: --param s32k_sw3=N"),
    ({"s32k_sw2": 3, "s32k_sw3": 3}, "--param s32k_sw3=3: expected a Dio channel other than SW2's"),
    ({"s32k_pin_7": 2}, "--param s32k_pin_7=2: expected 0 or 1: the level the input pin reads"),
    ({"s32k_sw2": 7, "s32k_pin_7": 1}, "--param s32k_pin_7=1: expected no level for SW2's channel"),
], ids=["sw2_out_of_range", "sw3_not_whole", "sw2_at_negative", "sw3_at_alone", "one_channel_twice",
        "pin_level", "pin_on_a_button"])
def test_a_bad_input_pin_param_is_one_line(tmp_path, params, expected):
    """A button's channel out of range or not whole, a press before 0, a press time without its
    button, two buttons on one channel, a level not 0/1 or on a button's channel: the run ends at
    the first Dio call that reads it, saying what was expected, on one line."""
    src = probe(tmp_path, """\
        #include "Dio.h"
        int main(void) {
            (void)Dio_ReadChannel(7U);
            return 0;
        }
        """)
    r = drive(firmware([src]), track="floor", time_limit_s=1.0, params=params)
    assert r.outcome == "controller_error", (params, r.message)
    assert r.message.startswith(f"{src}:3: {expected}") and "\n" not in r.message, (params, r.message)


def test_a_bad_button_param_ends_the_run_at_the_first_dio_call_not_at_drivers_init(tmp_path):
    """The buttons' --params are read at the first Dio call, as the docs say: a bad one ends the run
    there, not at the DriversInit() or ServoInit() before it (was: at DriversInit's line, where no
    pin is used); a firmware that uses no pin is warned that it never read --param s32k_sw2."""
    src = probe(tmp_path, """\
        #include "main_functions.h"
        #include "servo.h"
        #include "Dio.h"
        int main(void) {
            DriversInit();
            ServoInit(1U, 3000U, 2000U, 2500U);
            (void)Dio_ReadChannel(7U);
            return 0;
        }
        """)
    program = firmware([src])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  params={"s32k_sw2": 300})
        assert r.outcome == "controller_error", (isolate, r.message)
        assert r.message.startswith(f"{src}:7: --param s32k_sw2=300: expected the Dio channel"), (isolate, r.message)
    src.write_text(src.read_text().replace("(void)Dio_ReadChannel(7U);", ""))
    res = CliRunner().invoke(cli, ["drive", str(src), "--kit", "s32k144", "--track", "floor", "--time-limit", "0.5",
                                   "--param", "s32k_sw2=12"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines()[-1] == ("simrunner: warning: the controller never read --param s32k_sw2 (it read "
                                           "s32k_esc_hz, s32k_osif_hz, s32k_servo_offset_rad, s32k_servo_rad)"), res.output
    # (no 'did you mean s32k_esc_hz?': a name 0.63 alike is no typo; the nearest is offered from 0.7)


def test_the_pins_looked_up_are_one_name_in_the_never_read_warning(tmp_path):
    """The kit looks up --param s32k_pin_N for each Dio channel the firmware uses: the warning of
    a --param never read lists them as one name, s32k_pin_{6,32,64} (was: each, s32k_pin_32,
    s32k_pin_6, s32k_pin_64, as if the program had read them), and a pin of a channel the firmware
    does not use is no 'did you mean' of another channel's."""
    src = probe(tmp_path, """\
        #include "Dio.h"
        int main(void) {
            Dio_WriteChannel(6U, STD_HIGH);
            Dio_WriteChannel(64U, STD_LOW);
            (void)Dio_ReadChannel(32U);
            return 0;
        }
        """)
    for given, mean in (("s32k_sw2_att=0.3", "; did you mean s32k_sw2_at?"), ("s32k_pin_7=1", "")):
        res = CliRunner().invoke(cli, ["drive", str(src), "--kit", "s32k144", "--track", "floor", "--time-limit", "0.5",
                                       "--param", given])
        assert res.exit_code == 0, res.output
        assert res.output.splitlines()[-1] == (
            f"simrunner: warning: the controller never read --param {given.split('=')[0]} (it read s32k_esc_hz, "
            "s32k_osif_hz, s32k_pin_{6,32,64}, s32k_servo_offset_rad, s32k_servo_rad, s32k_sw2, s32k_sw2_at, "
            f"s32k_sw3, s32k_sw3_at{mean})"), res.output


def test_a_main_waiting_on_a_flag_its_notification_sets_is_told_what_to_call(tmp_path):
    """while (!Tick) {} waiting for a flag the Gpt notification sets: on the board the interrupt
    ends it; here no time passes in it (documented), so the run stalls at its line - and says
    what to call in C (a kit call that waits, spinner_sleep(0)), not the Python API's
    get_image(). Alike in process and isolated."""
    src = probe(tmp_path, """\
        #include "Gpt.h"
        static volatile int Tick;
        void Gpt_Notification(void) { Tick = 1; }
        int main(void) {
            Gpt_StartTimer(0U, 80000U);
            Gpt_EnableNotification(0U);
            while (!Tick) {
            }
            return 0;
        }
        """)
    program = firmware([src])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0, wall_limit_s=1.0)
        assert r.outcome == "stalled", (isolate, r.message)
        assert "probe.c:7" in r.message and "LinearCameraGetFrame()" in r.message, (isolate, r.message)
        assert "spinner_sleep(0)" in r.message and "get_image()" not in r.message.replace("spinner_get_image()", ""), \
            (isolate, r.message)


@pytest.mark.parametrize("header", ["Mcu.h", "Port.h", "S32K144.h"])
def test_an_rtd_header_the_kit_has_not_is_said_so(tmp_path, header):
    """A team's own set-up (Mcu_Init, Port_Init: what the sample's DriversInit does) or register
    access includes an RTD or register header the kit does not provide: the compiler's 'no such
    file' at its line is followed by a line saying the kit does not emulate it and what stands
    for it (DriversInit), not left unexplained."""
    src = probe(tmp_path, f'#include "Mcal.h"\n#include "{header}"\nint main(void) {{ return 0; }}\n', "init.c")
    with pytest.raises(ControllerFileError) as err:
        firmware([src])
    text = str(err.value)
    assert re.search(rf"init.c:2:.*{re.escape(header)}: No such file", text), text
    assert text.splitlines()[-1].startswith(f"{header}: not a header of the simulator's --kit s32k144"), text
    assert "DriversInit()" in text.splitlines()[-1], text


@pytest.mark.parametrize("name, body, first, named", [
    ("init.c", "Pwm_Init(NULL_PTR); Icu_StartSignalMeasurement(0U);", "Pwm_Init", "Icu_StartSignalMeasurement, Pwm_Init"),
    ("init.cpp", "Pwm_Init(NULL_PTR); Icu_StartSignalMeasurement(0U);", "Pwm_Init", "Icu_StartSignalMeasurement, Pwm_Init"),
    ("hw.c", "Adc_EnableHardwareTrigger(0U);", "Adc_EnableHardwareTrigger", "Adc_EnableHardwareTrigger"),
])
def test_an_rtd_call_the_kit_has_not_is_said_so(tmp_path, name, body, first, named):
    """Pwm_Init(NULL_PTR), Icu_StartSignalMeasurement, an Adc call outside the kit's software-triggered
    subset (a hardware-triggered group's): the compiler's error at the call's line is followed by a
    line naming the calls as not emulated, what the kit has, and DriversInit as their set-up's
    stand-in, in C (implicit declaration) and C++ (not declared)."""
    src = probe(tmp_path, f'#include "Pwm.h"\n#include "Adc.h"\nint main(void) {{ {body} return 0; }}\n', name)
    with pytest.raises(ControllerFileError) as err:
        firmware([src])
    text = str(err.value)
    assert re.search(rf"{re.escape(name)}:3:.*{first}", text), text
    assert text.splitlines()[-1].startswith(f"{named}: of the RTD's calls the simulator's --kit s32k144 has only"), text
    assert "Adc's software-triggered group calls" in text.splitlines()[-1], text
    assert "DriversInit()" in text.splitlines()[-1], text


# ---- esc.h: the sample's driver, its state machine at each period of the ESC's PWM ----

ESC_CAR = '[drive]\ncommand = "duty"\nhbridge = "brake"\n[camera]\nmodel = "ideal"\nfps_hz = 500\n'  # a row a step


def esc_run(tmp_path, calls, *, defines=(), params=None):
    """The rear motors' duty at each physics step (2 ms) while a firmware runs `calls` after
    EscInit(0U, 1638U, 2457U, 3276U) at t = 0 (the sample's 1, 1.5, 2 ms pulses), on a duty car
    whose log has a row a step; alike in process and isolated. Returns (t_s, duty)."""
    src = probe(tmp_path, f"""\
        #include "esc.h"
        #include "OsIf.h"
        int main(void) {{
            EscInit(0U, 1638U, 2457U, 3276U);
            {calls}
            return 0;
        }}
        """)
    car = tmp_path / "esc_car.toml"
    car.write_text(ESC_CAR)
    program = firmware([src], defines=list(defines))
    assert program.warnings == "", program.warnings
    runs = []
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", car=car, time_limit_s=2.0,
                  params=params or {})
        assert r.outcome == "controller_returned", (isolate, r.message)
        assert np.array_equal(r.log.duty_left, r.log.duty_right), isolate
        runs.append((r.log.t_s, r.log.duty_left))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    return runs[0]


def esc_duty(speed):
    """The duty of EscSetSpeed(speed)'s pulse: the driver's integer pulse of 1638, 2457, 3276."""
    span = 3276 - 2457 if speed >= 0 else 2457 - 1638
    return float(np.float32((2457 + int(speed * span / 100) - 2457) / span))


def duty_between(t, duty, t0, t1):
    """The duties of the rows in force from t0 to t1 (a command set at t acts from the next step:
    the row at t + 2 ms)."""
    w = (t > t0 + 0.001) & (t < t1 + 0.001)
    assert w.sum() >= 3, (t0, t1)
    return duty[w]


@pytest.mark.parametrize("name", ["names.c", "names.cpp"])
def test_esc_h_has_the_samples_names(tmp_path, capfd, name):
    """esc.h has the sample's ESC_HAS_BRAKE (STD_ON unless -D ESC_HAS_BRAKE=STD_OFF, as a team
    sets it in its copy), enum EscStates and the Esc struct, in C and C++ (was: undeclared)."""
    src = probe(tmp_path, """\
        #include <stdio.h>
        #include "esc.h"
        int main(void) {
            Esc e = {Braking, 0U, 1638U, 3276U, 2457U, -20, 1U};
            enum EscStates s = Reverse;
        #if ESC_HAS_BRAKE == STD_ON
            const char *brake = "on";
        #else
            const char *brake = "off";
        #endif
            printf("esc %s %d %d %d %d %u\\n", brake, (int)Forward, (int)e.State, (int)Neutral, (int)s,
                   (unsigned)(e.MaxDutyCycle - e.MedDutyCycle + (unsigned)e.Speed + e.Brake + e.Channel + e.MinDutyCycle));
            return 0;
        }
        """, name)
    for defines, want in (((), "on"), (["ESC_HAS_BRAKE=STD_OFF"], "off")):
        program = firmware([src], defines=defines)
        assert program.warnings == "", program.warnings
        capfd.readouterr()
        r = drive(program, track="floor", time_limit_s=1.0)
        assert r.outcome == "controller_returned", r.message
        assert capfd.readouterr().out.split("esc ")[1].split()[:6] == [want, "0", "1", "2", "3", "2438"], defines


@pytest.mark.parametrize("hz", [50, 25])
def test_an_esc_speed_takes_effect_at_the_next_pwm_period(tmp_path, hz):
    """EscSetSpeed only stores the request: the pulse changes at the end of the ESC PWM's next
    period (its falling-edge notification, the sample's Esc_Period_Finished), every 1 / --param
    s32k_esc_hz from EscInit (default 50 Hz, the sample's configuration) (was: at once)."""
    params = {} if hz == 50 else {"s32k_esc_hz": hz}
    t, duty = esc_run(tmp_path, "OsIf_TimeDelay(130U); EscSetSpeed(60); OsIf_TimeDelay(100U);", params=params)
    period = 1.0 / hz
    edge = np.ceil(0.130 / period - 1e-9) * period  # the next edge after the request at 130 ms
    moved = t[np.flatnonzero(duty != 0.0)[0]] - 0.002  # a command acts from the next step's row
    assert moved - 0.130 == pytest.approx(edge - 0.130, abs=1e-6), (hz, moved)  # 10 ms at 50 Hz, 30 at 25
    assert np.all(duty_between(t, duty, edge, edge + 0.05) == esc_duty(60))


def test_a_forward_esc_reverses_through_braking_and_neutral(tmp_path):
    """From forward, EscSetSpeed(-50) goes Forward -> Braking -> Neutral -> Reverse, one period each
    (20 ms). The Braking pulse is full reverse (-100); the car's ESC (with a brake, forward/reverse-
    with-brake mode) takes a pulse below the stop pulse after forward ones as a brake (duty 0: the
    motors shorted) until it has seen a stop pulse; after one it reverses: so a car stopped by
    EscSetSpeed(0) (Forward holds, its pulse the stop pulse) sees the Braking period as full reverse
    (was: -50 % at once; a brake drove full reverse)."""
    t, duty = esc_run(tmp_path, "EscSetSpeed(60); OsIf_TimeDelay(130U); EscSetSpeed(-50); OsIf_TimeDelay(100U);"
                                "EscSetSpeed(60); OsIf_TimeDelay(100U); EscSetSpeed(0); OsIf_TimeDelay(100U);"
                                "EscSetSpeed(-50); OsIf_TimeDelay(100U);")
    assert np.all(duty_between(t, duty, 0.02, 0.14) == esc_duty(60))
    assert np.all(duty_between(t, duty, 0.14, 0.18) == 0.0)           # Braking: the ESC brakes; Neutral
    assert np.all(duty_between(t, duty, 0.18, 0.24) == esc_duty(-50))  # Reverse
    assert np.all(duty_between(t, duty, 0.24, 0.34) == esc_duty(60))   # Reverse -> Forward at once
    assert np.all(duty_between(t, duty, 0.34, 0.44) == 0.0)            # Forward at speed 0: the stop pulse
    assert np.all(duty_between(t, duty, 0.44, 0.46) == -1.0)           # Braking's -100, a stop pulse seen
    assert np.all(duty_between(t, duty, 0.46, 0.48) == 0.0)            # Neutral
    assert np.all(duty_between(t, duty, 0.48, 0.53) == esc_duty(-50))  # Reverse


def test_esc_set_brake_brakes_and_resumes(tmp_path):
    """EscSetBrake(1) brakes at the next period (Braking: the brake-capable ESC's brake, duty 0) for
    as long as it is held; EscSetBrake(0) resumes the speed at the next period (was: at once)."""
    t, duty = esc_run(tmp_path, "EscSetSpeed(60); OsIf_TimeDelay(130U); EscSetBrake(1U); OsIf_TimeDelay(100U);"
                                "EscSetBrake(0U); OsIf_TimeDelay(100U);")
    assert np.all(duty_between(t, duty, 0.02, 0.14) == esc_duty(60))
    assert np.all(duty_between(t, duty, 0.14, 0.24) == 0.0)
    assert np.all(duty_between(t, duty, 0.24, 0.32) == esc_duty(60))


def test_an_esc_without_brake_follows_the_samples_other_table(tmp_path):
    """-D ESC_HAS_BRAKE=STD_OFF (an ESC without a brake, which reverses at any pulse below the stop
    pulse): Forward -> Reverse at once; EscSetBrake(1) alternates Braking (the pulse of -Speed) and
    Neutral each period; EscSetBrake(0) goes back to Reverse."""
    t, duty = esc_run(tmp_path, "EscSetSpeed(60); OsIf_TimeDelay(130U); EscSetSpeed(-50); OsIf_TimeDelay(100U);"
                                "EscSetBrake(1U); OsIf_TimeDelay(100U); EscSetBrake(0U); OsIf_TimeDelay(60U);",
                      defines=["ESC_HAS_BRAKE=STD_OFF"])
    assert np.all(duty_between(t, duty, 0.02, 0.14) == esc_duty(60))
    assert np.all(duty_between(t, duty, 0.14, 0.24) == esc_duty(-50))  # Forward -> Reverse
    for k, edge in enumerate((0.24, 0.26, 0.28, 0.30, 0.32)):          # Braking, Neutral, Braking, ...
        assert np.all(duty_between(t, duty, edge, edge + 0.02) == (esc_duty(50) if k % 2 == 0 else 0.0)), edge
    assert np.all(duty_between(t, duty, 0.34, 0.39) == esc_duty(-50))  # Braking -> Reverse


def test_an_esc_frequency_out_of_range_ends_the_run_at_esc_init(tmp_path):
    """--param s32k_esc_hz of 0 (or above the simulator's 100 kHz timer) ends the run at EscInit's
    line, saying what was expected."""
    src = probe(tmp_path, """\
        #include "esc.h"
        int main(void) {
            EscInit(0U, 1638U, 2457U, 3276U);
            return 0;
        }
        """)
    for hz in (0.0, 2e5):
        r = drive(firmware([src]), track="floor", time_limit_s=1.0, params={"s32k_esc_hz": hz})
        assert r.outcome == "controller_error", (hz, r.message)
        assert r.message.startswith(f"{src}:3: EscInit: --param s32k_esc_hz="), (hz, r.message)
        assert "expected a PWM frequency above 0" in r.message, (hz, r.message)


# ---- Adc.h: a team's own analog inputs (the board's potentiometer, a battery sense) ----

POT_MAIN = """\
    #include <stdio.h>
    #include "Adc.h"
    #include "main_functions.h"
    #include "spinner.h"
    static Adc_ValueGroupType buf[1];
    int main(void) {
        Adc_CalibrationStatusType cal;
        cal.AdcUnitSelfTestStatus = E_NOT_OK;
        DriversInit();
        Adc_Init(&Adc_Config_VS_0);
        Adc_Calibrate(AdcHwUnit_0, &cal);
        Std_ReturnType early = Adc_ReadGroup(AdcGroup_pot, buf);
        unsigned idle = Adc_GetGroupStatus(AdcGroup_pot);
        for (int k = 0; k < 164; k++) {
            Adc_StartGroupConversion(AdcGroup_pot);
            while (Adc_GetGroupStatus(AdcGroup_pot) == ADC_BUSY) {
            }
            (void)Adc_ReadGroup(AdcGroup_pot, buf);
        }
        unsigned after = Adc_GetGroupStatus(AdcGroup_pot);
        Std_ReturnType again = Adc_ReadGroup(AdcGroup_pot, buf);
        printf("pot %u early %u idle %u after %u again %u cal %u t %.3f\\n", (unsigned)buf[0], early, idle, after,
               again, cal.AdcUnitSelfTestStatus, spinner_now());
        return 0;
    }
    """


def pot_run(tmp_path, capfd, params, *, isolate=False, defines=("AdcGroup_pot=1U",)):
    """The run of the team pattern (NXP-Cup-EXPO src/onboard_pot.c's conversion: start, busy-wait
    while ADC_BUSY, Adc_ReadGroup) and what it printed."""
    program = firmware([probe(tmp_path, POT_MAIN)], defines=list(defines))
    assert program.warnings == "", program.warnings
    capfd.readouterr()
    r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, wall_limit_s=30.0,
              params=params)
    out = capfd.readouterr().out
    return r, out.split("pot ")[1].split() if "pot " in out else None


def test_a_pot_read_through_the_rtd_adc_reads_its_param(tmp_path, capfd):
    """A team's pot read as the RTD has it builds unchanged (-D AdcGroup_pot=1U: the configuration's
    group name) and reads --param s32k_adc_1 on both hosts: the busy-wait ends at once (the status is
    ADC_STREAM_COMPLETED, the conversion done), Adc_ReadGroup gives the counts and leaves the group
    ADC_IDLE, a read again the same values; a read before any conversion is E_NOT_OK (ADC_E_IDLE);
    Adc_Calibrate succeeds. 164 conversions at one time let 100 physics steps pass (after 64)."""
    for isolate in (False, True):
        r, out = pot_run(tmp_path, capfd, {"s32k_adc_1": 3000}, isolate=isolate)
        assert r.outcome == "controller_returned", (isolate, r.message)
        assert out[:11] == ["3000", "early", "1", "idle", "0", "after", "0", "again", "0", "cal", "0"], (isolate, out)
        assert float(out[12]) == pytest.approx(100 * STEP_S, abs=STEP_S), (isolate, out)
        assert not any("Adc" in w for w in r.warnings), (isolate, r.warnings)


def test_a_pot_with_no_param_reads_mid_scale_with_one_warning(tmp_path, capfd):
    """No --param for the group: it reads mid-scale (2048 of 12 bits; 512 of 10 with
    s32k_adc_bits=10), and the run lists one warning naming the param to give."""
    r, out = pot_run(tmp_path, capfd, None)
    assert r.outcome == "controller_returned" and out[0] == "2048", (r.message, out)
    adc = [w for w in r.warnings if "Adc group 1" in w]
    assert len(adc) == 1 and "no value given for --param s32k_adc_1: the channel reads mid-scale, 2048 counts" in adc[0], \
        r.warnings
    r, out = pot_run(tmp_path, capfd, {"s32k_adc_bits": 10})
    assert r.outcome == "controller_returned" and out[0] == "512", (r.message, out)


def test_an_adc_group_of_several_channels_and_its_notification(tmp_path, capfd):
    """s32k_adc_<n>_<i> is the group's i-th channel (s32k_adc_<n>_0 its first): Adc_SetupResultBuffer's
    buffer holds the values once the conversion is started, Adc_ReadGroup copies the group's channels
    and no more, Adc_GetStreamLastPointer points at the one sample; the notification -D
    ADC_NOTIFICATION_2=NAME names is called at the conversion's end (before Adc_StartGroupConversion
    returns), where a read gives the values and leaves the group ADC_IDLE (read again later, the same
    values); Adc_DisableGroupNotification stops it. A channel
    below the last given reads mid-scale. Adc_Types.h (the RTD's, which the sample's camera driver
    includes) is found. Both hosts alike."""
    src = probe(tmp_path, """\
        #include <stdio.h>
        #include "Adc_Types.h"
        #include "Adc.h"
        static Adc_ValueGroupType result[3], copy[4] = {7, 7, 7, 7}, in_notification[3];
        static int notified;
        void BatteryDone(void) { notified++; (void)Adc_ReadGroup(2U, in_notification); }
        int main(void) {
            Adc_ValueGroupType *last = NULL;
            Adc_Init(NULL_PTR);
            (void)Adc_SetupResultBuffer(2U, result);
            Adc_EnableGroupNotification(2U);
            Adc_StartGroupConversion(2U);
            unsigned status = Adc_GetGroupStatus(2U);
            Adc_StreamNumSampleType n = Adc_GetStreamLastPointer(2U, &last);
            Std_ReturnType read = Adc_ReadGroup(2U, copy);
            Adc_DisableGroupNotification(2U);
            Adc_StartGroupConversion(2U);
            Adc_StartGroupConversion(3U);
            printf("adc %u %u %u | %u %u %u %u | %u %u %u | %d %u %u %d %u\\n", result[0], result[1], result[2],
                   copy[0], copy[1], copy[2], copy[3], in_notification[0], in_notification[1], in_notification[2],
                   notified, status, (unsigned)n, last == result, read);
            return 0;
        }
        """)
    program = firmware([src], defines=["ADC_NOTIFICATION_2=BatteryDone"])
    assert program.warnings == "", program.warnings
    for isolate in (False, True):
        capfd.readouterr()
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  params={"s32k_adc_2_0": 100, "s32k_adc_2_2": 4095, "s32k_adc_3": 5})
        assert r.outcome == "controller_returned", (isolate, r.message)
        out = capfd.readouterr().out.split("adc ")[1].split()
        assert out == ["100", "2048", "4095", "|", "100", "2048", "4095", "7", "|", "100", "2048", "4095", "|",
                       "1", "0", "1", "1", "0"], (isolate, out)  # ADC_IDLE: the notification's read
        assert any("no value given for --param s32k_adc_2_1" in w for w in r.warnings), (isolate, r.warnings)


@pytest.mark.parametrize("params, expected", [
    ({"s32k_adc_1": 4096}, "--param s32k_adc_1=4096: expected the channel's conversion result: a whole number of "
                           "counts 0..4095 (12 bits"),
    ({"s32k_adc_1_3": 2.5}, "--param s32k_adc_1_3=2.5: expected the channel's conversion result"),
    ({"s32k_adc_1": -1}, "--param s32k_adc_1=-1: expected the channel's conversion result"),
    ({"s32k_adc_1": 1024, "s32k_adc_bits": 10}, "--param s32k_adc_1=1024: expected the channel's conversion result: "
                                                "a whole number of counts 0..1023 (10 bits"),
    ({"s32k_adc_1": 1, "s32k_adc_1_0": 2}, "--param s32k_adc_1_0=2: expected one of s32k_adc_N and s32k_adc_N_0"),
    ({"s32k_adc_bits": 11}, "--param s32k_adc_bits=11: expected 8, 10 or 12"),
], ids=["above_12_bits", "not_whole", "negative", "above_10_bits", "first_channel_twice", "bits"])
def test_a_bad_adc_param_is_one_line(tmp_path, capfd, params, expected):
    """A count out of the resolution's range or not whole, the first channel given twice, a
    resolution the S32K1's ADC has not: the run ends at the Adc call that reads it, on one line."""
    r, _ = pot_run(tmp_path, capfd, params)
    assert r.outcome == "controller_error", (params, r.message)
    line = 10 if "s32k_adc_bits" in params and len(params) == 1 else 15  # Adc_Init, or the first conversion
    assert r.message.startswith(f"{tmp_path / 'probe.c'}:{line}: {expected}") and "\n" not in r.message, \
        (params, r.message)


def test_an_adc_notification_not_configured_ends_the_run_at_its_line(tmp_path):
    """Adc_EnableGroupNotification on a group whose notification the kit's configuration has not
    (the RTD: ADC_E_NOTIF_CAPABILITY): the run ends at the call, saying how to name it; a group
    beyond the kit's 0..255 ends the run at its call."""
    src = probe(tmp_path, """\
        #include "Adc.h"
        int main(void) {
            Adc_StartGroupConversion(AdcGroup_pot);
            Adc_EnableGroupNotification(AdcGroup_pot);
            return 0;
        }
        """)
    r = drive(firmware([src], defines=["AdcGroup_pot=1U"]), track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{src}:4: Adc_EnableGroupNotification: group 1 has no notification") and \
        "-D ADC_NOTIFICATION_1=NAME" in r.message, r.message
    r = drive(firmware([src], defines=["AdcGroup_pot=300U"]), track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{src}:3: Adc_StartGroupConversion(300): the simulator's Adc has groups 0..255"), \
        r.message
