"""The mbed flavour of the FRDM-TFC kit library (simrunner drive main.cpp --kit tfc-mbed): a
team's mbed program (mbed.h + the FRDM-TFC library's TFC.h) builds unchanged and drives."""
from __future__ import annotations

import dataclasses
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from simrunner.errors import ControllerFileError
from simrunner.run.native import build_program
from simrunner.run.runner import drive

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "firmware" / "mbed" / "main.cpp"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"


def program(tmp_path, text, name="main.cpp"):
    src = tmp_path / name
    src.write_text(textwrap.dedent(text))
    return build_program([str(src)], kit="tfc-mbed")


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
@pytest.mark.parametrize("frame_us", [19500, 10000])
def test_one_image_a_servo_frame_as_the_free_running_tpm1_gives_them(tmp_path, capfd, frame_us, isolate):
    """TFC.cpp's TPM1 overflow raises SI and starts the read-out every servo frame, free-running:
    one image a servo frame (2 s / frame), not a servo frame plus the read-out (it gave 2.5 %
    fewer at 19.5 ms, 5 % at 10 ms). Images counted over 2 s, in process and isolated."""
    prog = program(tmp_path, f"""\
        #include <stdio.h>
        #include "mbed.h"
        #include "TFC.h"
        int main() {{
            TFC_Init();
            TFC_SetLineScanExposureTime({frame_us});
            Timer t;
            t.start();
            int images = 0;
            while (t.read_ms() < 2000) {{
                if (TFC_LineScanImageReady) {{ TFC_LineScanImageReady = 0; images++; }}
            }}
            printf("images %d\\n", images);
            fflush(stdout);
            return 0;
        }}
        """)
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, track="floor", time_limit_s=3.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    images = int(out.split("images ")[1].split()[0])
    assert abs(images - 2.0 / (frame_us * 1e-6)) <= 1, images


def servo_frames(tmp_path, capfd, period_s, seconds, position=0.0):
    """TFC_ServoTicker's count over `seconds` after TFC_InitServos(0.5 ms, 2 ms, period_s) and
    TFC_SetServo(0, position); the run's log."""
    prog = program(tmp_path, f"""\
        #include <stdio.h>
        #include "mbed.h"
        #include "TFC.h"
        int main() {{
            TFC_Init();
            TFC_InitServos(0.0005f, 0.002f, {period_s}f);
            TFC_SetServo(0, {position}f);
            TFC_ServoTicker = 0;
            wait({seconds});
            printf("frames %u\\n", (unsigned)TFC_ServoTicker);
            fflush(stdout);
            return 0;
        }}
        """)
    r = drive(prog, track="floor", time_limit_s=seconds + 1.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    return int(out.split("frames ")[1].split()[0]), r.log


def test_a_servo_frame_is_mod_plus_one_counts(tmp_path, capfd):
    """TFC_InitServos' MOD = 750 kHz x 2.5 ms = 1875, and TPM1 counts 0 .. MOD: a frame of 1876 counts,
    2.50133 ms (KL25 RM 31.4.3.1: "(MOD + 0x0001) x period of the TPM counter clock"), so 20 s hold
    7995.7 frames; before, the kit's frames were the period given, 8000."""
    frames, _ = servo_frames(tmp_path, capfd, 0.0025, 20.0)
    assert abs(frames - 20.0 / (1876 / 750e3)) <= 1.5, frames


def test_a_servo_period_over_87_ms_wraps_the_16_bit_mod(tmp_path, capfd):
    """TFC_InitServos(..., 0.1 s): MOD = 75000 written to a 16-bit field keeps 75000 - 65536 = 9464
    (KL25 RM 31.3.3), a frame of 9465 counts, 12.62 ms: 2 s hold 158 frames (before: 100-ms frames, 20);
    and the library's duty, MOD x pulse / 0.1 s, gives a neutral pulse of 118 counts, 0.157 ms, under the
    0.5 ms end: the servo goes to its end (before: straight ahead)."""
    frames, log = servo_frames(tmp_path, capfd, 0.1, 2.0)
    assert abs(frames - 2.0 / (9465 / 750e3)) <= 1.5, frames
    late = log.t_s > 1.0
    assert np.allclose(log.steer_cmd_rad[late], -0.4), log.steer_cmd_rad[late][:5]


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_new_servo_frame_loads_as_the_frame_in_progress_ends(tmp_path, capfd, isolate):
    """TFC_SetLineScanExposureTime writes TPM1's MOD while it counts, and the KL25 updates MOD as the
    counter turns from MOD to zero (RM 31.4.8.1): the image after the call still comes one old frame
    (10 ms) after the one before and is as bright, the next one 20 ms later and brighter; of the two
    writes in that frame (5 ms, then 20 ms) the last loads; TFC_ServoTicker counts on, one a frame.
    (It used to re-time the frame in progress, 20 ms and brighter, and start the ticker from 0.)"""
    prog = program(tmp_path, """\
        #include <stdio.h>
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        static long sum() { long s = 0; for (int i = 0; i < 128; i++) s += TFC_LineScanImage0[i]; return s; }
        int main() {
            TFC_Init();
            for (int n = 0; n < 10; n++) {
                while (!TFC_LineScanImageReady) {}
                TFC_LineScanImageReady = 0;
                printf("image %d %.6f %u %ld\\n", n, spinner_now(), (unsigned)TFC_ServoTicker, sum());
                if (n == 5) {                       // mid-frame: two writes, the last one counts
                    wait_ms(4);
                    TFC_SetLineScanExposureTime(5000);
                    TFC_SetLineScanExposureTime(20000);
                }
            }
            fflush(stdout);
            return 0;
        }
        """)
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, track="floor", time_limit_s=2.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    images = [line.split()[1:] for line in out.splitlines() if line.startswith("image ")]
    t = {int(n): float(ts) for n, ts, _, _ in images}
    ticker = {int(n): int(k) for n, _, k, _ in images}
    light = {int(n): int(s) for n, _, _, s in images}
    assert [round(t[n + 1] - t[n], 6) for n in range(2, 9)] == [0.01, 0.01, 0.01, 0.01, 0.02, 0.02, 0.02], t
    assert [ticker[n + 1] - ticker[n] for n in range(2, 9)] == [1] * 7, ticker
    assert abs(light[6] - light[5]) < 0.02 * light[5], light   # the frame in progress: its own exposure
    assert light[7] > 1.4 * light[6], light                      # the next: 20 ms of light


def test_the_example_builds_unchanged_and_laps():
    """examples/firmware/mbed/main.cpp (Serial, a Ticker counting TFC_Ticker[], a main loop on
    TFC_LineScanImageReady) laps the default track about as the Python line follower does."""
    r = drive(build_program([str(EXAMPLE)], kit="tfc-mbed"), laps=2)
    follower = drive(REPO / "examples" / "line_follower.py", laps=2)
    assert r.outcome == "finished" and r.laps_completed == 2, r.message
    assert r.lap_times_s[1] == pytest.approx(follower.lap_times_s[1], rel=0.05)


@pytest.mark.skipif(not SHARED_TRACKS.is_dir(), reason="../shared/tracks not present")
@pytest.mark.parametrize("name", ["nxp_raceway", "nxp_raceway_octagon"])
def test_the_example_laps_both_nxp_tracks(name):
    r = drive(build_program([str(EXAMPLE)], kit="tfc-mbed"), track=SHARED_TRACKS / name)
    assert r.outcome == "finished", (name, r.message)


def test_a_ticker_driven_control_loop_laps(tmp_path):
    """The control in a Ticker's handler (an object's method, the older attach form), main()
    only waiting: the handler steers from the images main()'s waits fetch."""
    lane = REPO / "examples" / "firmware" / "lane.h"
    prog = program(tmp_path, f"""\
        #include "mbed.h"
        #include "TFC.h"
        #include "{lane}"
        class Driver {{
        public:
            int passes = 0;
            void control() {{
                passes++;
                if (!TFC_LineScanImageReady) return;
                TFC_LineScanImageReady = 0;
                float steer, speed;
                lane_control(TFC_LineScanImage0, V_MAX_MPS, &steer, &speed);
                TFC_SetServo(0, steer / STEER_LIMIT_RAD);
                TFC_SetMotorPWM(speed / MAX_SPEED_MPS, speed / MAX_SPEED_MPS);
            }}
        }};
        Driver driver;
        Ticker control_ticker;
        int main() {{
            TFC_Init();
            TFC_InitServos(SERVO_MIN_PULSE_WIDTH_DEFAULT, SERVO_MAX_PULSE_WIDTH_DEFAULT, EXPOSURE_US * 1e-6f);
            TFC_HBRIDGE_ENABLE;
            control_ticker.attach(&driver, &Driver::control, 0.01f);   // 100 Hz
            while (1) {{
                wait(0.5);
                if (driver.passes < 45) return 1;                        // ~50 a half second
                driver.passes = 0;
            }}
        }}
        """)
    r = drive(prog, laps=1)
    assert r.outcome == "finished", r.message


def test_the_library_maps_the_board_onto_the_car(tmp_path):
    """Pots, DIP switch, battery, buttons and AnalogIn read --param; Timer and wait count simulated
    time; a Timeout fires once; images are 12-bit counts in ping-pong buffers; servo 0 steers,
    the motors drive only with the H-bridge enabled (here through its pin, PTE21)."""
    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        volatile int fired = 0;
        void once() { fired++; }
        int main() {
            TFC_Init();
            wait_ms(12);   /* the ADC's first conversion: TPM1's first overflow (10 ms) */
            if (TFC_ReadPot(0) != (float)(1024.0f / -2047.5 + 1.0) || TFC_ReadPot(1) != -1.0f) return 1;
            if (TFC_GetDIP_Switch() != 5 || !TFC_DIP_SWITCH_2_ON || TFC_DIP_SWITCH_1_ON) return 2;
            if (fabsf(TFC_ReadBatteryVoltage() - 7.2f * 10.0f / 57.0f * 3.0f / 3.3f) > 1e-3f) return 3;
            AnalogIn sensor(PTB0), pot0(PTB3);
            if (fabsf(sensor.read() - 0.25f) > 1e-6f || fabsf(pot0.read() - 0.25f) > 1e-6f) return 4;
            DigitalIn button(PTC17);
            if (!button.read() || !TFC_PUSH_BUTTON_1_PRESSED || TFC_ReadPushButton(1) == 0) return 5;
            Timer t;
            t.start();
            Timeout timeout;
            timeout.attach(&once, 0.05f);
            wait_ms(100);
            if (t.read_ms() < 100 || t.read_ms() > 104 || fired != 1) return 6;
            TFC_LineScanImageReady = 0;
            volatile uint16_t *before = TFC_LineScanImage0;
            while (!TFC_LineScanImageReady) {}
            if (TFC_LineScanImage0 == before) return 7;
            for (int i = 0; i < 128; i++) if (TFC_LineScanImage0[i] % 16 || TFC_LineScanImage0[i] > 4080) return 8;
            TFC_SetServo(0, 0.5f);
            TFC_SetMotorPWM(0.5f, 0.5f);       // H-bridge still disabled: no speed
            wait(0.1);
            DigitalOut enable(PTE21);
            enable = 1;
            wait(0.1);
            return 0;
        }
        """)
    r = drive(prog, params={"pot0": 0.5, "pot1": -3, "dip": 5, "analog_PTB0": 0.25, "button1": 1},
              time_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message
    log = r.log
    late = log.t_s > log.t_s[-1] - 0.05
    # TFC_SetServo(0, 0.5): CnV = trunc(MOD 7500 x duty 0.1625) = 1218 counts of 750 kHz, a 1.624 ms pulse of
    # TFC_InitServos' 0.5 .. 2 ms: position 0.49867, not 0.5 (TFC.cpp's QueuedServo0Val = TPM1->MOD * DutyCycle)
    steer = 0.4 * (2 * (1218 / 750e3 - 0.5e-3) / 1.5e-3 - 1)
    assert np.allclose(log.speed_cmd_mps[late], 0.5 * 3.1) and np.allclose(log.steer_cmd_rad[late], steer, atol=1e-6)
    before = (log.t_s > 0.15) & (log.t_s < log.t_s[-1] - 0.12)
    assert np.all(log.speed_cmd_mps[before] == 0.0)


def test_pots_and_battery_read_zero_counts_until_tpm1s_first_overflow(tmp_path):
    """TFC.cpp's TPM1 interrupt starts the pots' and the battery's conversions at each servo frame:
    before the first after TFC_Init (10 ms) - or without TFC_Init - TFC_ReadPot returns 1.0 (a count
    of 0) and the battery 0 V, on the board too, and the first such read is a warning at its line;
    an AnalogIn on a pot's pin converts at once."""
    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        int main() {
            float before_init = TFC_ReadPot(0);
            TFC_Init();
            float at_init = TFC_ReadPot(0), battery = TFC_ReadBatteryVoltage();
            AnalogIn pot0(PTB3);
            float direct = pot0.read();
            wait_ms(12);
            float pot = TFC_ReadPot(0);
            spinner_add_textf("%g %g %g %.4f %.6f %u", before_init, at_init, battery, direct, pot, PotADC_Value[0]);
            return 0;
        }
        """, name="early.cpp")
    r = drive(prog, params={"pot0": -0.25}, time_limit_s=1.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    assert [s for s in r.log.data_text if s][-1] == f"1 1 0 0.6250 {1 - 2559 / 2047.5:.6f} 2559"
    early = [w for w in r.warnings if "ADC" in w]
    assert len(early) == 2, r.warnings
    src = tmp_path / "early.cpp"
    assert early[0].startswith(f"{src}:5: TFC_ReadPot(0) before TFC_Init(): ") and "returns 1.0" in early[0]
    assert early[1].startswith(f"{src}:7: TFC_ReadBatteryVoltage() at t = 0.002 s, before the ADC's first "
                               "conversion (TPM1's first overflow") and "returns 0 V" in early[1], early[1]


def test_a_loop_waiting_on_the_programs_own_tickers_lets_time_pass(tmp_path):
    """mbed programs define TFC_Ticker[] themselves and count it with a Ticker; a loop waiting on
    it (`while (TFC_Ticker[3] < 100) {}`) lets time pass for the Ticker to count."""
    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #define NUM_TFC_TICKERS 4
        Ticker TFC_TickerObj;
        volatile uint32_t TFC_Ticker[NUM_TFC_TICKERS];
        void TFC_TickerUpdate() {
            for (int i = 0; i < NUM_TFC_TICKERS; i++) if (TFC_Ticker[i] < 0xFFFFFFFF) TFC_Ticker[i]++;
        }
        int main() {
            TFC_TickerObj.attach_us(&TFC_TickerUpdate, 2000);
            TFC_Init();
            Timer t;
            t.start();
            TFC_Ticker[3] = 0;
            while (TFC_Ticker[3] < 100) {}
            int ms = t.read_ms();   // 100 ticks of 2 ms, + a camera read-out under way (< a frame)
            return ms >= 198 && ms <= 230 ? 0 : 1;
        }
        """)
    r = drive(prog, time_limit_s=3.0, wall_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message


def test_misuse_is_one_clear_line(tmp_path):
    """A wait inside a handler ends the run naming its line; the serial port's input is not
    emulated; register writes and left-out mbed drivers are named after the compiler's error; the
    library's own TFC.cpp is named."""
    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        Ticker tick;
        void handler() {
            wait_ms(5);
        }
        int main() {
            tick.attach(&handler, 0.01f);
            while (1) wait(0.1);
        }
        """, name="isr_wait.cpp")
    r = drive(prog, time_limit_s=1.0)
    assert r.outcome == "controller_error"
    assert "wait_ms: not emulated by the simulator's mbed FRDM-TFC kit" in r.message
    assert "isr_wait.cpp:5" in r.message
    assert r.message.endswith("(in handler())"), r.message  # (C++'s demangled name: it said handler()())
    prog = program(tmp_path, """\
        #include "mbed.h"
        Serial pc(USBTX, USBRX);
        int main() {
            int c = pc.getc();
            return c;
        }
        """, name="getc.cpp")
    r = drive(prog, time_limit_s=1.0)
    assert r.outcome == "controller_error" and "Serial::getc: not emulated" in r.message
    assert "getc.cpp:4" in r.message
    regs = tmp_path / "regs.cpp"
    regs.write_text('#include "mbed.h"\n#include "TFC.h"\nSPI flash(PTD2, PTD3, PTD1);\n'
                    'int main() { TAOS_SI_HIGH; return 0; }\n')
    with pytest.raises(ControllerFileError, match=r"(?s)regs.cpp:3:.*PTD, SPI: the MCU's registers "
                                                  r"or mbed drivers, not emulated by the simulator's --kit tfc-mbed"):
        build_program([str(regs)], kit="tfc-mbed")
    lib = tmp_path / "FRDM-TFC" / "TFC.cpp"
    lib.parent.mkdir()
    lib.write_text("void TFC_Init() {}\n")
    with pytest.raises(ControllerFileError, match=r"TFC.cpp: the kit's own driver source: --kit tfc-mbed"):
        build_program([str(EXAMPLE), str(lib)], kit="tfc-mbed")


def test_an_isr_handler_reads_the_board_while_main_polls_the_image_flag(tmp_path):
    """A handler of the program's own (--isr) that reads the board (the servo ticker, a pot) while
    main() waits on `while (!TFC_LineScanImageReady) {}`: its reads are the board's state at its
    time; they once waited for the camera inside the interrupt (the run ended at its line)."""
    from simrunner.run.native.build import with_isrs

    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        static volatile int reads;
        extern "C" void PIT_IRQHandler(void) {
            for (int i = 0; i < 100; i++) reads += TFC_ServoTicker >= 0 && TFC_ReadPot(0) > -2.0f;
        }
        int main() {
            TFC_Init();
            for (int images = 0; images < 20; images++) {
                while (!TFC_LineScanImageReady) {}
                TFC_LineScanImageReady = 0;
            }
            return reads > 0 ? 0 : 3;
        }
        """)
    r = drive(with_isrs(prog, [("PIT_IRQHandler", 0.001)]), track="floor", time_limit_s=3.0, wall_limit_s=5.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message


SENSOR_CAR = "[encoders]\n[imu]\n"  # rear encoders, 512 lines, x4; the default IMU


def sensor_drive(tmp_path, text, car=SENSOR_CAR, params=None, name="main.cpp"):
    """Drive `text` (an mbed program) on the floor with a car file holding `car`."""
    car_file = tmp_path / "car.toml"
    car_file.write_text(car)
    return drive(program(tmp_path, text, name), track="floor", car=car_file, params=params or {},
                 time_limit_s=8.0, csv=tmp_path / "log.csv")  # a CSV keeps the program's text


def texts(r):
    """The program's spinner_add_textf lines with the time they were added: [(t_s, text), ...]."""
    return [(t, s) for t, s in zip(r.log.t_s, r.log.data_text) if s]


def test_the_boards_accelerometer_reads_the_cars_imu_in_g(tmp_path):
    """MMA8451Q (the FRDM-KL25Z's accelerometer, as the mbed library reads it): ~(0, 0, 1) g at rest;
    in a steady left turn getAccY() is v^2 / r in g, as the car file's [imu] measures it."""
    r = sensor_drive(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "MMA8451Q.h"
        #include "spinner.h"
        #define MMA8451_I2C_ADDRESS (0x1d << 1)
        MMA8451Q acc(PTE25, PTE24, MMA8451_I2C_ADDRESS);
        int main() {
            TFC_Init();
            wait(0.2);
            float rest[3] = {0, 0, 0}, a[3];
            for (int i = 0; i < 50; i++) {
                acc.getAccAllAxis(a);
                for (int j = 0; j < 3; j++) rest[j] += a[j] / 50;
                wait_ms(5);
            }
            spinner_add_textf("rest %x %.4f %.4f %.4f", acc.getWhoAmI(), rest[0], rest[1], rest[2]);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.4f, 0.4f);
            TFC_SetServo(0, 0.6f);
            wait(3.0);
            float lateral = 0;
            for (int i = 0; i < 100; i++) {
                lateral += acc.getAccY() / 100;
                wait_ms(10);
            }
            spinner_add_textf("turn %.4f", lateral);
            return 0;
        }
        """)
    assert r.outcome == "controller_returned", r.message
    (_, rest), (t_turn, turn) = texts(r)
    who, *g = rest.split()[1:]
    assert who == "1a"
    assert [float(v) for v in g] == pytest.approx([0.0, 0.0, 1.0], abs=0.03)
    log = r.log
    steady = (log.t_s > t_turn - 1.0) & (log.t_s <= t_turn)
    v, yaw_rate = log.speed_mps[steady].mean(), log.yaw_rate_radps[steady].mean()
    radius_m = v / yaw_rate
    want_g = v ** 2 / radius_m / 9.80665
    assert want_g > 0.05  # a real turn (left: + y)
    assert float(turn.split()[1]) == pytest.approx(want_g, rel=0.1)


def test_qei_counts_a_rear_wheels_encoder_as_the_library_decodes_it(tmp_path):
    """QEI on the first rear encoder (RL): pulses per metre = lines x encoding / (2 pi r); X4 counts
    twice X2; reset() starts again from 0; --param qei_PTxN puts a QEI on a wheel by its pin."""
    r = sensor_drive(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "QEI.h"
        #include "spinner.h"
        QEI left(PTD4, PTA12, NC, 512, QEI::X4_ENCODING);   // the first QEI: RL
        QEI left_x2(PTA4, PTA5, PTA13, 512);                 // X2, on RL by --param qei_PTA4=2
        int main() {
            TFC_Init();
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(1.5);
            spinner_add_textf("a %d %d %d", left.getPulses(), left_x2.getPulses(), left_x2.getRevolutions());
            left.reset();
            int after_reset = left.getPulses();
            wait(1.0);
            spinner_add_textf("b %d %d %d", after_reset, left.getPulses(), left_x2.getPulses());
            return 0;
        }
        """, params={"qei_PTA4": 2})
    assert r.outcome == "controller_returned", r.message
    (t_a, a), (t_b, b) = texts(r)
    x4, x2, revs = (int(v) for v in a.split()[1:])
    after_reset, x4_since, x2_b = (int(v) for v in b.split()[1:])
    log = r.log
    x_a, x_b = np.interp(t_a, log.t_s, log.x_m), np.interp(t_b, log.t_s, log.x_m)
    per_m = 512 * 4 / (2 * np.pi * 0.034)
    assert x4 == pytest.approx(x_a * per_m, rel=0.02)
    assert abs(x4 - 2 * x2) <= 1 and x2 > 1000
    assert revs == x2 // 1024  # the index channel: one pulse a turn
    assert after_reset == 0
    assert x4_since == pytest.approx((x_b - x_a) * per_m, rel=0.02)
    assert abs(x2_b - x2 - x4_since / 2) <= 2  # the X2 one was not reset


def test_missing_car_sections_end_the_run_at_the_programs_line(tmp_path):
    r = sensor_drive(tmp_path, """\
        #include "mbed.h"
        #include "QEI.h"
        QEI wheel(PTD4, PTA12, NC, 512, QEI::X4_ENCODING);
        int main() {
            wait(0.1);
            return wheel.getPulses() > 0;
        }
        """, car="[imu]\n", name="no_encoders.cpp")
    assert r.outcome == "controller_error"
    assert "QEI::getPulses: the car has no wheel encoders: add [encoders] to the car file" in r.message
    assert "no_encoders.cpp:6" in r.message
    r = sensor_drive(tmp_path, """\
        #include "mbed.h"
        #include "MMA8451Q.h"
        MMA8451Q acc(PTE25, PTE24, 0x1d << 1);
        int main() {
            wait(0.1);
            return acc.getAccZ() > 0.5f;
        }
        """, car="[encoders]\n", name="no_imu.cpp")
    assert r.outcome == "controller_error"
    assert "MMA8451Q::getAccZ: the car has no IMU: add [imu] to the car file" in r.message
    assert "no_imu.cpp:6" in r.message
    r = sensor_drive(tmp_path, """\
        #include "mbed.h"
        #include "QEI.h"
        QEI a(PTD4, PTA12, NC, 512), b(PTA4, PTA5, NC, 512), c(PTA1, PTA2, NC, 512);
        int main() {
            wait(0.1);
            return c.getPulses();
        }
        """, name="third.cpp")
    assert r.outcome == "controller_error" and "third.cpp:6" in r.message
    assert "QEI number 3 (channel A PTA1): the car has 2 wheel encoders" in r.message


def test_a_fault_inside_a_kit_headers_function_names_the_programs_call(tmp_path):
    """A fault inside a kit header's function that is not inlined (MMA8451Q::getAccAllAxis given
    NULL): the report names the program's line that called into the kit, as for the kit's sources;
    the backtrace names the header's line (it once named main.cpp at the header's line 49)."""
    r = sensor_drive(tmp_path, """\
        #include "mbed.h"
        #include "MMA8451Q.h"
        MMA8451Q acc(PTE25, PTE24, 0x1d << 1);
        int main() {
            wait(0.1);
            float *axes = NULL;
            acc.getAccAllAxis(axes);
            return 0;
        }
        """, name="null_axes.cpp")
    assert r.outcome == "controller_error"
    assert "null_axes.cpp:7: SIGSEGV: segmentation fault (in main())" in r.message, r.message
    assert "MMA8451Q.h:" in r.error.traceback_text and "null_axes.cpp:49" not in r.error.traceback_text


def test_an_mbed_program_named_dot_c_is_told_to_be_cpp(tmp_path):
    """mbed's API is C++: a .c file that includes mbed.h is one line naming the fix (before, a
    screen of compile errors); a plain C module beside the C++ program still builds."""
    src = tmp_path / "main.c"
    src.write_text('#include "mbed.h"\n#include "TFC.h"\nint main(void) { TFC_Init(); return 0; }\n')
    with pytest.raises(ControllerFileError, match=r"main.c: includes mbed.h, whose API is C\+\+: name the file main.cpp"):
        build_program([src], kit="tfc-mbed")
    cpp = tmp_path / "prog.cpp"
    cpp.write_text('#include "mbed.h"\n#include "TFC.h"\nextern "C" int twice(int);\n'
                   'int main() { TFC_Init(); return twice(2) == 4 ? 0 : 1; }\n')
    helper = tmp_path / "calc.c"
    helper.write_text("int twice(int x) { return 2 * x; }\n")
    r = drive(build_program([cpp, helper], kit="tfc-mbed"), track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message


def test_a_wait_after_other_time_passed_waits_its_whole_time(tmp_path, capfd):
    """Waits add up within a step only while nothing else lets time pass: after sleep() or
    __WFI() a wait counts from then (it used to count from main()'s last wait, up to 10 ms back:
    wait_ms(5) after five __WFI() returned at once)."""
    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        int main() {
            TFC_Init();
            for (int i = 0; i < 5; i++) __WFI();
            Timer t;
            t.start();
            wait_ms(5);
            int a = t.read_us();
            sleep();
            t.reset();
            wait_us(3000);
            int b = t.read_us();
            t.reset();
            for (int i = 0; i < 20; i++) wait_us(100);
            printf("waited %d %d %d\\n", a, b, t.read_us());
            return 0;
        }
        """)
    r = drive(prog, track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    a, b, c = map(int, re.search(r"waited (\d+) (\d+) (\d+)", capfd.readouterr().out).groups())
    assert (a, b) == (6000, 4000) and c <= 2000  # whole 2-ms steps; twenty 0.1-ms waits share one


@pytest.mark.parametrize("isolate", [False, True])
def test_a_global_digitalout_is_set_before_main_and_the_run_starts(tmp_path, isolate):
    """`DigitalOut myled(LED1);` at file scope (mbed's blinky; its constructor writes the pin before
    main(), as the H-bridge enable's `DigitalOut hbridge(PTE21, 1)`): the run starts on both hosts and
    the pin's level holds from the start (in process it crashed the run with SIGSEGV before the first
    frame: the write started the kit from the constructor, before the run's simulator was there)."""
    prog = program(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        DigitalOut myled(LED1);
        DigitalOut hbridge(PTE21, 1);     // the H-bridge enabled from the start
        int main() {
            TFC_Init();
            TFC_SetMotorPWM(0.5f, 0.5f);
            for (int i = 0; i < 10; i++) { myled = !myled; wait_ms(20); }
            return myled.read() == 0 ? 0 : 1;   // toggled ten times
        }
        """)
    r = drive(dataclasses.replace(prog, isolate=isolate), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned" and r.message == "main() returned", r.message
    assert np.allclose(r.log.speed_cmd_mps[r.log.t_s > 0.05], 0.5 * 3.1)


GLOBAL_DRIVERS = """\
    #include "mbed.h"
    #include "TFC.h"
    class Encoder {                      // a team's driver class: its InterruptIn set up in its constructor
    public:
        Encoder(PinName a) : in_(a), n(0) { in_.rise(callback(this, &Encoder::tick)); }
        void tick() { n++; }
        InterruptIn in_;
        volatile int n;
    };
    class Steering {                     // a servo class on a PwmOut: its pulse set in its constructor
    public:
        Steering(PinName p) : pwm_(p) { pwm_.period_ms(20); pwm_.pulsewidth_us(1500); }
        void set(float pos) { pwm_.pulsewidth_us(1500 + (int)(500 * pos)); }
        PwmOut pwm_;
    };
    class Speed {                        // a Ticker attached in its constructor
    public:
        Speed(Encoder &e) : e_(e) { t_.attach(callback(this, &Speed::sample), 0.01f); }
        void sample() { samples++; last = e_.n; }
        Encoder &e_;
        Ticker t_;
        volatile int samples = 0, last = 0;
    };
    Encoder enc(PTA13);
    Steering steering(PTB0);
    Speed speed(enc);
    int main() {
        TFC_Init();
        steering.set(0.5f);
        TFC_HBRIDGE_ENABLE;
        TFC_SetMotorPWM(0.3f, 0.3f);
        wait(1.0);
        printf("edges %d samples %d last %d\\n", enc.n, speed.samples, speed.last);
        return 0;
    }
    """


def test_global_driver_objects_whose_constructors_use_the_kit_run_on_both_hosts(tmp_path, capfd):
    """Global objects of a team's driver classes whose constructors set up an InterruptIn, a PwmOut
    and a Ticker (on the board C++ constructors run in the start-up code, before main): they run as
    --isolate runs them, edge for edge (in the simulator's process the library's constructors ran
    as it was loaded, before the run: the run crashed, SIGSEGV before its first frame; the program
    now runs in a child process)."""
    car = tmp_path / "enc.toml"
    car.write_text('[encoders]\nwheels = "rear"\nlines_per_rev = 100\ncounting = "x1"\n')
    prog = program(tmp_path, GLOBAL_DRIVERS)
    outs = []
    for isolate in (False, True):
        r = drive(dataclasses.replace(prog, isolate=isolate), track="floor", car=car,
                  params={"encoder_PTA13": 2}, time_limit_s=2.0)
        assert r.outcome == "controller_returned" and r.message == "main() returned", r.message
        assert np.allclose(r.log.steer_cmd_rad[r.log.t_s > 0.05], 0.2)   # 0.5 x tfc_servo_rad 0.40
        outs.append(capfd.readouterr().out)
    m = re.search(r"edges (\d+) samples (\d+) last (\d+)", outs[0])
    assert m and int(m[1]) > 100 and int(m[2]) >= 99 and int(m[3]) > 0, outs[0]
    assert outs[0] == outs[1]


def test_tfc_ticker_without_the_programs_definition_says_to_define_it(tmp_path):
    """mbed's library has no TFC_Ticker (the CodeWarrior one's SysTick counts it): a program that
    uses it without defining it is told so after the compiler's error, which names the kit's
    function behind the name (tfc_mbed_tickers was not declared), not TFC_Ticker."""
    src = tmp_path / "ticks.cpp"
    src.write_text('#include "mbed.h"\n#include "TFC.h"\n'
                   'int main() { TFC_Init(); while (TFC_Ticker[0] < 100) {} return 0; }\n')
    with pytest.raises(ControllerFileError) as err:
        build_program([str(src)], kit="tfc-mbed")
    assert "ticks.cpp:3" in str(err.value)
    assert str(err.value).splitlines()[-1].startswith(
        "TFC_Ticker: not declared - mbed's FRDM-TFC library has none (the CodeWarrior library's SysTick "
        "counted it): define it in your program, `volatile uint32_t TFC_Ticker[4];`")


# -- TPM1 as TFC.cpp drives it: TFC_InitServos, TFC_ServoTicker, the servo's CnV ------------------
def image_lines(out):
    """The program's `image N T TICKER` lines: {N: (T_s, ticker)}."""
    rows = [line.split()[1:] for line in out.splitlines() if line.startswith("image ")]
    return {int(n): (float(t), int(k)) for n, t, k in rows}


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_init_servos_keeps_the_ticker_and_the_counter_where_they_are(tmp_path, capfd, isolate):
    """TFC.cpp's TFC_InitServos stops TPM1 (TPM1->SC = 0: the counter keeps its count, KL25 RM
    31.4.1), writes MOD (at once, the counter off: 31.4.8.1) and lets it count on; it writes neither
    CNT nor TFC_ServoTicker (TFC_Init zeroes the ticker, after it). So a 20-ms frame set 4 ms into a
    10-ms frame ends 20 ms after that frame began, and the ticker counts on, one an image; a 4-ms
    frame set 6 ms into a 10-ms one finds the counter past the new MOD: it counts on to 0xFFFF
    (65536 counts of 750 kHz, 87.4 ms) and round, the next image 87.4 + 4 ms after the last. (The
    kit zeroed the ticker and restarted the frame from the call: 6 + 4 ms.)"""
    prog = program(tmp_path, """\
        #include <stdio.h>
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        int main() {
            TFC_Init();
            for (int n = 0; n < 14; n++) {
                while (!TFC_LineScanImageReady) {}
                TFC_LineScanImageReady = 0;
                printf("image %d %.6f %u\\n", n, spinner_now(), (unsigned)TFC_ServoTicker);
                if (n == 5) {
                    wait_ms(4);
                    TFC_InitServos(SERVO_MIN_PULSE_WIDTH_DEFAULT, SERVO_MAX_PULSE_WIDTH_DEFAULT, 0.020f);
                    printf("ticker %u\\n", (unsigned)TFC_ServoTicker);
                }
                if (n == 9) {
                    wait_ms(6);
                    TFC_InitServos(SERVO_MIN_PULSE_WIDTH_DEFAULT, SERVO_MAX_PULSE_WIDTH_DEFAULT, 0.004f);
                }
            }
            fflush(stdout);
            return 0;
        }
        """)
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, track="floor", time_limit_s=2.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    images = image_lines(out)
    t = {n: ts for n, (ts, _) in images.items()}
    gap = {n: round(t[n + 1] - t[n], 6) for n in range(2, 13)}
    assert [gap[n] for n in (2, 3, 4)] == [0.01] * 3, gap
    assert [gap[n] for n in (5, 6, 7, 8)] == [0.02] * 4, gap          # from the frame's start, not the call
    assert gap[9] == pytest.approx(65536 / 750e3 + 0.004, abs=0.0011), gap  # the counter round 0xFFFF
    assert [gap[n] for n in (10, 11, 12)] == [0.004] * 3, gap
    ticker = {n: k for n, (_, k) in images.items()}
    assert int(out.split("ticker ")[1].split()[0]) == ticker[5], out  # the call keeps it
    assert [ticker[n + 1] - ticker[n] for n in range(0, 13)] == [1] * 13, ticker


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_program_that_writes_the_servo_ticker_sees_it_count_on_from_its_value(tmp_path, capfd, isolate):
    """TFC_ServoTicker is the library's variable, which TPM1's interrupt increments (to 0xFFFFFFFF):
    a write sticks, from main() and from a handler. Teams' `if (TFC_ServoTicker >= 10) {
    TFC_ServoTicker = 0; ...}` then runs once every 10 frames (the kit kept the count of frames
    since TFC_Init and took it back at the next tick: every pass after the first 10). The program's
    own TFC_Ticker[] (counted by its Ticker) keeps a write too, from main() and a handler."""
    prog = program(tmp_path, """\
        #include <stdio.h>
        #include "mbed.h"
        #include "TFC.h"
        volatile uint32_t TFC_Ticker[2];
        Ticker ms;
        Timeout later;
        void count() { TFC_Ticker[0]++; TFC_Ticker[1]++; }
        void set() { TFC_ServoTicker = 1000; TFC_Ticker[1] = 5000; }
        int main() {
            TFC_Init();
            ms.attach_us(&count, 1000);
            int passes = 0;
            Timer t;
            t.start();
            while (t.read_ms() < 1000) {                 // 100 frames of 10 ms
                if (TFC_ServoTicker >= 10) {
                    TFC_ServoTicker = 0;
                    passes++;
                }
                wait_ms(1);
            }
            TFC_ServoTicker = 0;
            TFC_Ticker[0] = 0;
            wait_ms(50);
            printf("passes %d after %u %u\\n", passes, (unsigned)TFC_ServoTicker, (unsigned)TFC_Ticker[0]);
            later.attach(&set, 0.0105f);
            wait_ms(40);
            printf("handler %u %u\\n", (unsigned)TFC_ServoTicker, (unsigned)TFC_Ticker[1]);
            fflush(stdout);
            return 0;
        }
        """)
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, track="floor", time_limit_s=3.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    m = re.search(r"passes (\d+) after (\d+) (\d+)\s+handler (\d+) (\d+)", out)
    assert m, out
    passes, after, ticks, from_handler, ticks_1 = (int(v) for v in m.groups())
    assert 9 <= passes <= 10, out                       # once every 10 frames
    assert 4 <= after <= 6 and 49 <= ticks <= 52, out   # 50 ms: 5 frames, 50 ms ticks from 0
    assert 1002 <= from_handler <= 1004, out            # 30 ms after the handler's write: 3 frames on
    assert 5028 <= ticks_1 <= 5031, out


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_servo_position_reaches_the_car_at_the_second_frame_edge_after_it(tmp_path, capfd, isolate):
    """TFC_SetServo queues the position (QueuedServo0Val); TPM1's interrupt writes it to the channel's
    CnV at the next overflow, and in edge-aligned PWM a CnV written while the counter runs loads as it
    next turns from MOD to zero (KL25 RM 31.4.8.2): the pulse from the second frame edge after the
    call carries it. Set 3 ms after an image's edge (10-ms frames; 4 ms at the 2-ms step), twice
    (the last queued wins): the car steers from 20 ms after that edge (it did from the call)."""
    prog = program(tmp_path, """\
        #include <stdio.h>
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        int main() {
            TFC_Init();
            for (int n = 0; n < 6; n++) {
                while (!TFC_LineScanImageReady) {}
                TFC_LineScanImageReady = 0;
            }
            double edge = spinner_now();
            wait_ms(3);
            TFC_SetServo(0, -1.0f);
            TFC_SetServo(0, 1.0f);
            printf("edge %.6f\\n", edge);
            fflush(stdout);
            wait(0.1);
            return 0;
        }
        """)
    if isolate:
        prog = dataclasses.replace(prog, isolate=True)
    r = drive(prog, track="floor", time_limit_s=2.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    edge = float(out.split("edge ")[1].split()[0])
    log = r.log
    steered = log.t_s[log.steer_cmd_rad != 0.0]
    assert np.all(log.steer_cmd_rad[log.steer_cmd_rad != 0.0] == pytest.approx(0.4)), log.steer_cmd_rad
    # a row of the run log holds the command the step after its frame's boundary applied: the one
    # the overflow at edge + 20 ms loads (the call's own row, edge + 10 ms, before)
    assert steered[0] == pytest.approx(edge + 0.020, abs=1e-6), (edge, steered[:3])



INIT_SERVOS_IN_A_CHARGE = """\
    #include <stdio.h>
    #include "mbed.h"
    #include "TFC.h"
    #include "spinner.h"
    int main() {
        TFC_Init();
        for (int k = 0; k < CALLS; k++) spinner_get_exposure();  /* where in a step the charges fall */
        for (int j = 0; j < 16; j++) {
            while (!TFC_LineScanImageReady) {}
            TFC_LineScanImageReady = 0;
            for (int i = 0; i < 10 + j % 8; i++) spinner_get_exposure();  /* 5 to 8.5 ms of code */
            float period = j % 2 ? 0.007f : 0.012f;                 /* 7 ms in a 12-ms frame */
            TFC_InitServos(SERVO_MIN_PULSE_WIDTH_DEFAULT, SERVO_MAX_PULSE_WIDTH_DEFAULT, period);
            printf("call %.6f %.3f\\n", spinner_now(), period);
        }
        fflush(stdout);
        wait(0.12);                                             /* the frame after the last call */
        return 0;
    }
    """


@pytest.mark.parametrize("calls", [0, 1, 2, 3])
def test_init_servos_finds_the_counter_where_mains_code_time_left_it(tmp_path, capfd, calls):
    """--mcu-time 0.5 ms a call: TFC_InitServos 5 to 8.5 ms after each image, 12 ms and 7 ms in turn.
    Its calls to the simulator let main()'s code time pass first, and the kit's tick runs in it: an
    overflow there (an image), or the counter passing the new period, changes where the call finds
    the counter, as on the board, where that code ran before the call. So the frame after each call
    follows TPM1's last overflow (the run log's last frame) by the new period when the counter had
    not passed it at the call's end, else by 87.4 ms more (round 0xFFFF), whichever way the charges
    fell (0 to 3 calls before; in process and isolated)."""
    src = tmp_path / "init_in_charge.cpp"
    src.write_text(textwrap.dedent(INIT_SERVOS_IN_A_CHARGE))
    prog = build_program([str(src)], kit="tfc-mbed", defines=[f"CALLS={calls}"])
    kinds = set()
    for isolate in (False, True):
        r = drive(dataclasses.replace(prog, isolate=isolate), track="floor", time_limit_s=3.0, mcu_time=0.0005)
        out = capfd.readouterr().out
        assert r.outcome == "controller_returned", (isolate, r.message, out)
        frames = r.log.t_s
        calls = [(float(a), float(b)) for a, b in re.findall(r"call ([\d.]+) ([\d.]+)", out)]
        for (call, period), (next_call, _) in zip(calls, calls[1:] + [(np.inf, 0.0)]):
            last = frames[frames <= call + 1e-9].max()
            after = frames[frames > call + 1e-9].min()
            if after > next_call + 1e-9:
                continue  # (the next call set another period before that frame ended)
            past = call - last > period + 1e-9
            expect = last + (65536 / 750e3 if past else 0.0) + period
            assert after == pytest.approx(expect, abs=0.0011), (isolate, call, last, after)
            kinds.add(past)
    assert kinds == {False, True}  # both: the counter short of the new MOD, and past it

# -- a kit's object made in main(), and --mcu-time: the kit's tick inside its set-up ---------------
QEI_IN_MAIN = """\
    #include "mbed.h"
    #include "TFC.h"
    #include "QEI.h"
    #include "spinner.h"
    int main() {
        TFC_Init();
        TFC_HBRIDGE_ENABLE;
        TFC_SetMotorPWM(0.5f, 0.5f);
        wait(1.0);                                            /* the wheels turn: ~5 revolutions */
        for (int k = 0; k < CALLS; k++) spinner_get_exposure();  /* where in a step the charges fall */
        QEI enc(PTD4, PTA12, PTA13, 512, QEI::X4_ENCODING);   /* in main(): counts from now */
        int revs = enc.getRevolutions();
        return revs == 0 ? 12 : 20 + (revs > 50 ? 50 : revs);
    }
    """


@pytest.mark.parametrize("mcu_time, calls", [(None, 0), (0.0005, 0), (0.0005, 1), (0.0005, 2), (0.0005, 3)])
def test_a_qei_made_in_main_counts_its_revolutions_from_then(tmp_path, mcu_time, calls):
    """A QEI constructed in main() counts from then, its index channel's rises too: the kit's tick
    that samples its wheel first (in main()'s wait for it, or, --mcu-time 0.5 ms a call, inside the
    read of its --param, where that charge crosses a step) counted the rises from the wheel's count
    0, the run's start: getRevolutions() gave the 5 turns before the QEI existed. Now 0, without
    --mcu-time and wherever in a step the charges fall (0 to 3 calls before), in process and
    isolated."""
    src = tmp_path / "qei_in_main.cpp"
    src.write_text(textwrap.dedent(QEI_IN_MAIN))
    car = tmp_path / "car.toml"
    car.write_text(SENSOR_CAR)
    prog = build_program([str(src)], kit="tfc-mbed", defines=[f"CALLS={calls}"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(prog, isolate=isolate), track="floor", car=car, time_limit_s=3.0,
                  mcu_time=mcu_time)
        assert r.outcome == "controller_error" and re.search(r"status 12\b", r.message), (isolate, r.message)


def test_motor_duties_before_tfc_init_end_the_run_at_the_call(tmp_path):
    """mbed's TFC_SetMotorPWM writes TPM0's channels from TPM0->MOD, whose clock TFC_InitMotorPWM
    (TFC_Init) opens: before it the board stops in a bus fault; the run ends at the call."""
    src = tmp_path / "early.cpp"
    src.write_text(textwrap.dedent("""\
        #include "mbed.h"
        #include "TFC.h"
        int main() {
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            while (1) wait_ms(10);
        }
        """))
    r = drive(build_program([str(src)], kit="tfc-mbed"), time_limit_s=0.5)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{src}:5: TFC_SetMotorPWM() before TFC_Init() (or TFC_InitMotorPWM())"), r.message


def test_motor_duties_with_the_h_bridge_disabled_are_a_warning(tmp_path):
    """mbed's TFC_Init() disables the H-bridge (TFC.cpp, TFC_GPIO_Init): a program that sets duties
    and never writes TFC_HBRIDGE_ENABLE stands still, on the board too - the run says why."""
    src = tmp_path / "still.cpp"
    src.write_text(textwrap.dedent("""\
        #include "mbed.h"
        #include "TFC.h"
        int main() {
            TFC_Init();
            TFC_SetMotorPWM(0.3f, -0.1f);
            while (1) wait_ms(10);
        }
        """))
    r = drive(build_program([str(src)], kit="tfc-mbed"), time_limit_s=2.0)
    assert any("still.cpp:5: TFC_SetMotorPWM(0.30, -0.10) with the H-bridge disabled for 1.0 s: the motors stay off" in w
               for w in r.warnings), r.warnings
