"""Timer interrupts (issue 50 item 1: "the team's own main() with its super-loop or its timer
interrupts, a periodic ISR the simulator calls at its rate"): ``Spinner.every``, C
``spinner_every`` and ``simrunner drive --isr NAME@HZ`` (simrunner.run.clock, Interrupts)."""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.errors import ControllerFileError
from simrunner.run.native import build_program
from simrunner.run.native.build import with_isrs
from simrunner.run.runner import drive

REPO = Path(__file__).resolve().parents[1]
ISR_FIRMWARE = REPO / "examples" / "firmware" / "isr" / "main.c"
FIRMWARE_DIR = REPO / "examples" / "firmware"
SHARED_TRACKS = REPO.parent / "shared" / "tracks"


def test_a_handler_runs_at_its_rate_and_its_commands_drive():
    """Every 10 ms exactly (simulated), from the call on; reads inside give the state then and
    no time passes in it; the speed it commands is what moves the car."""
    seen = []

    def main(s):
        def tick():
            t0 = s.get_time()
            seen.append((t0, s.get_speed(), s.get_time()))
            s.set_speed(0.8)

        s.sleep(0.1)
        s.every(0.01, tick)
        for _ in range(45):
            s.get_image(s.line_row)

    r = drive(main, track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_returned", r.message
    times = [t for t, _, _ in seen]
    assert times == pytest.approx([0.1 + 0.01 * k for k in range(1, len(seen) + 1)], abs=1e-12)
    assert times[-1] == pytest.approx(r.sim_time_s, abs=0.0101)
    assert all(t == again for t, _, again in seen)  # no time passes inside
    assert seen[0][1] == pytest.approx(0.0, abs=1e-3) and seen[-1][1] > 0.5  # its command moved the car


def test_a_handler_faster_than_the_physics_step_runs_as_often_as_it_fell_due():
    """1 kHz at the default 2 ms step: two calls a step, 500 in 0.5 s."""
    count = []

    def main(s):
        s.every(0.001, lambda: count.append(s.get_time()))
        s.sleep(0.5)

    drive(main, track="floor", time_limit_s=5.0)
    assert len(count) == 500 and count[0] == count[1] == pytest.approx(0.002)


def test_handlers_due_together_run_in_the_order_set_up():
    order = []

    def main(s):
        s.every(0.02, lambda: order.append(("b", s.get_time())))
        s.every(0.01, lambda: order.append(("a", s.get_time())))
        s.sleep(0.04)

    drive(main, track="floor", time_limit_s=5.0)
    assert [(n, round(t, 6)) for n, t in order] == [("a", 0.01), ("b", 0.02), ("a", 0.02), ("a", 0.03),
                                                    ("b", 0.04), ("a", 0.04)]


def test_waiting_inside_a_handler_is_the_controllers_error_at_its_line(tmp_path):
    ctl = tmp_path / "waits.py"
    ctl.write_text(textwrap.dedent("""\
        def main(s):
            def tick():
                s.get_image()
            s.every(0.05, tick)
            s.sleep(1.0)
        """))
    r = drive(ctl, track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_error" and "inside an interrupt handler" in r.message, r.message
    assert "waits.py:3" in r.message


C_EVERY = """\
#include <stdio.h>
#include "spinner.h"
static int ticks;
static void tick(void) {
    ticks++;
    spinner_set_speed(ticks < 50 ? 0.5 : 0.0);
    spinner_add_textf("tick %d at %.3f", ticks, spinner_get_time());
}
int main(void) {
    spinner_every(0.02, tick);
    unsigned char row[256];
    for (int i = 0; i < 75; i++) spinner_get_image(spinner_line_row(), 1, row, sizeof row);
    return ticks == 75 ? 0 : 3;
}
"""


def test_c_handlers_run_alike_in_process_and_isolated(tmp_path):
    """``spinner_every`` in C: the handler runs inside main's waiting calls (75 frames, 75
    ticks at 50 Hz), the same run log in the simulator's process and in a child process."""
    src = tmp_path / "every.c"
    src.write_text(C_EVERY)
    program = build_program([src])
    logs = []
    for isolate in (False, True):
        csv = tmp_path / f"run{isolate}.csv"
        r = drive(program if not isolate else __import__("dataclasses").replace(program, isolate=True),
                  track="floor", time_limit_s=5.0, csv=csv)
        assert r.outcome == "controller_returned", r.message
        logs.append(csv.read_bytes())
    assert logs[0] == logs[1] and b"tick 75 at 1.500" in logs[0]


def test_a_c_handler_that_waits_points_at_its_line(tmp_path):
    src = tmp_path / "isr_waits.c"
    src.write_text(textwrap.dedent("""\
        #include "spinner.h"
        static void tick(void) {
            spinner_sleep(0.01);
        }
        int main(void) {
            spinner_every(0.05, tick);
            spinner_sleep(1.0);
            return 0;
        }
        """))
    r = drive(build_program([src]), track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_error" and "isr_waits.c:3" in r.message, r.message
    assert "inside an interrupt handler" in r.message


def test_firmware_with_its_control_in_a_timer_interrupt_laps(tmp_path):
    """examples/firmware/isr/main.c: main() idles in __WFI(), LPTimer_IRQHandler steers at the
    100 Hz its LPTMR set-up gives (no --isr); it laps the default track as the super-loop firmware
    does (7.737 s both) and as with --isr LPTimer_IRQHandler@100 (7.741 s: the handler's phase is
    --isr's, from the start), with the same run log in a child process."""
    import dataclasses

    program = build_program([str(ISR_FIRMWARE)], include_dirs=[str(FIRMWARE_DIR)], kit="tfc")
    csv = tmp_path / "isr.csv"
    r = drive(program, csv=csv)
    assert r.outcome == "finished" and r.laps_completed == 1, r.message
    loop = drive(build_program([str(FIRMWARE_DIR / "main.c")], kit="tfc"))
    assert r.lap_times_s[0] == pytest.approx(loop.lap_times_s[0], rel=0.003)
    isr = drive(with_isrs(program, [("LPTimer_IRQHandler", 0.01)]))
    assert isr.laps_completed == 1 and r.lap_times_s[0] == pytest.approx(isr.lap_times_s[0], rel=0.003)
    alone = tmp_path / "isolated.csv"
    drive(dataclasses.replace(program, isolate=True), csv=alone)
    assert alone.read_bytes() == csv.read_bytes()


@pytest.mark.skipif(not SHARED_TRACKS.is_dir(), reason="../shared/tracks absent")
@pytest.mark.parametrize("track", ["nxp_raceway", "nxp_raceway_octagon"])
def test_the_interrupt_firmware_laps_both_nxp_tracks(track):
    program = build_program([str(ISR_FIRMWARE)], include_dirs=[str(FIRMWARE_DIR)], kit="tfc")  # its LPTMR's rate
    r = drive(program, track=SHARED_TRACKS / track)
    assert r.outcome == "finished" and r.laps_completed == 1, r.message


def test_measured_mcu_time_charges_a_handlers_own_time_only():
    """--mcu-time measured with --isr: the simulator's start-up is not the program's time (the
    firmware still laps at 20 x this machine's time)."""
    program = with_isrs(build_program([str(ISR_FIRMWARE)], include_dirs=[str(FIRMWARE_DIR)], kit="tfc"),
                        [("LPTimer_IRQHandler", 0.01)])
    r = drive(program, mcu_time="measured", mcu_scale=20.0)
    assert r.outcome == "finished" and r.laps_completed == 1, r.message


def test_the_cli_names_what_is_wrong_with_an_isr(tmp_path):
    args = ["drive", str(ISR_FIRMWARE), "-I", str(FIRMWARE_DIR), "--kit", "tfc", "--track", "floor",
            "--time-limit", "0.5"]
    res = CliRunner().invoke(cli, [*args, "--isr", "LPT_Handler@100"])
    assert res.exit_code == 2 and "defines no function LPT_Handler" in res.output, res.output
    res = CliRunner().invoke(cli, [*args, "--isr", "LPTimer_IRQHandler"])
    assert res.exit_code == 2 and "expected NAME@HZ" in res.output, res.output
    res = CliRunner().invoke(cli, ["drive", str(REPO / "examples" / "line_follower.py"), "--isr", "f@10"])
    assert res.exit_code == 2 and "spinner.every" in res.output, res.output
    res = CliRunner().invoke(cli, [*args, "--isr", "LPTimer_IRQHandler@100"])
    assert res.exit_code == 1 and "timeout" in res.output, res.output  # runs (0.5 s: no lap)


def test_with_isrs_refuses_a_missing_function(tmp_path):
    src = tmp_path / "plain.c"
    src.write_text("int main(void) { return 0; }\n")
    with pytest.raises(ControllerFileError, match="defines no function tick"):
        with_isrs(build_program([src]), [("tick", 0.01)])


S32K_GPT = """\
#include "Gpt.h"
#include "OsIf.h"
static volatile uint32 ticks;
void Gpt_Notification_0(void) { ticks++; }   /* named in the generated configuration */
int main(void) {
    Gpt_StartTimer(0U, 8000U);               /* 1 ms at the kit's 8 MHz Gpt clock */
    Gpt_EnableNotification(0U);
    while (ticks < 200U) OsIf_TimeDelay(1U);
    return OsIf_GetMilliseconds() >= 200U ? 0 : 3;
}
"""


def test_an_s32k144_gpt_notification_runs_as_an_isr(tmp_path):
    """With --kit s32k144 a Gpt notification is called with --isr NAME@HZ (enabling it does
    nothing more); without --isr, enabling it ends the run saying how."""
    src = tmp_path / "gpt.c"
    src.write_text(S32K_GPT)
    program = build_program([src], kit="s32k144")
    r = drive(with_isrs(program, [("Gpt_Notification_0", 0.001)]), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned" and r.sim_time_s == pytest.approx(0.2, abs=0.005), r.message
    r = drive(program, track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error" and "--isr NAME@HZ" in r.message and "gpt.c:7" in r.message, r.message


LPTMR_FIRMWARE = """\
#include "derivative.h"
#include "TFC\\\\TFC.h"
volatile uint32_t ticks;
void LPTimer_IRQHandler(void) {
    LPTMR0_CSR |= LPTMR_CSR_TCF_MASK;        /* clear the compare flag */
    ticks++;
}
static void timer_init(void) {               /* 100 Hz from the 1 kHz LPO, as on the board */
    SIM_SCGC5 |= SIM_SCGC5_LPTMR_MASK;
    LPTMR0_CSR = 0;
    LPTMR0_PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK;
    LPTMR0_CMR = LPTMR_CMR_COMPARE(10 - 1);
    LPTMR0->CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK;
    NVIC_ICPR |= 1u << (INT_LPTimer - 16);
    NVIC_ISER |= 1u << (INT_LPTimer - 16);
    NVIC_EnableIRQ(LPTimer_IRQn);
}
int main(void) {
    TFC_Init();
    timer_init();
    EnableInterrupts;
    while (ticks < 100) __WFI();
    return 0;
}
"""


def test_a_tfc_firmwares_own_timer_set_up_builds_and_its_handler_runs(tmp_path):
    """A KL25Z timer interrupt as firmware writes it (the LPTMR's clock gate, prescaler, compare
    value and interrupt enable, the NVIC, the flag cleared in the handler) builds unchanged with
    --kit tfc; --isr LPTimer_IRQHandler@100 calls the handler: 100 ticks in 1 s."""
    src = tmp_path / "lptmr.c"
    src.write_text(LPTMR_FIRMWARE)
    program = with_isrs(build_program([src], kit="tfc"), [("LPTimer_IRQHandler", 0.01)])
    r = drive(program, track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    assert r.sim_time_s == pytest.approx(1.0, abs=0.06)  # the last __WFI() pass may read an image


def test_check_builds_firmware_as_drive_does():
    """``simrunner check`` takes the firmware's sources, -I, --kit, --isr and --param as drive
    does: the interrupt firmware passes with --isr and without (its LPTMR's registers then give
    the rate)."""
    args = ["check", str(ISR_FIRMWARE), "-I", str(FIRMWARE_DIR), "--kit", "tfc", "--seconds", "1.5"]
    res = CliRunner().invoke(cli, [*args, "--isr", "LPTimer_IRQHandler@100", "--param", "dip=1"])
    assert res.exit_code == 0 and "isr/main.c: OK" in res.output and "warning" not in res.output, res.output
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0 and "isr/main.c: OK" in res.output and "warning" not in res.output, res.output


def test_batch_runs_firmware_built_once_with_its_kit_and_isr(tmp_path):
    """``simrunner batch`` takes the firmware's build as drive does (built once for every run):
    the interrupt firmware over 2 DIP settings x 2 seeds laps each run, the same rows on 1 and 2
    workers; a build that fails says the compiler's line."""
    from simrunner.workflows.batch import deterministic, run_batch

    build = dict(include_dirs=[str(FIRMWARE_DIR)], kit="tfc", isrs=(("LPTimer_IRQHandler", 0.01),))
    rows = []
    for workers in (1, 2):
        res = run_batch(ISR_FIRMWARE, out_dir=tmp_path / f"w{workers}", seeds=2, params=["dip=0,1"],
                        workers=workers, plot=False, build=build)
        assert [r["outcome"] for r in res.rows] == ["finished"] * 4
        rows.append([deterministic(r) for r in res.rows])
    assert rows[0] == rows[1]
    res = CliRunner().invoke(cli, ["batch", str(ISR_FIRMWARE), "--kit", "tfc", "-o", str(tmp_path / "bad")])
    assert res.exit_code == 2 and "lane.h: No such file" in res.output, res.output


def test_cpp_every_takes_a_lambda(tmp_path):
    src = tmp_path / "every.cpp"
    src.write_text(textwrap.dedent("""\
        #include "spinner.hpp"
        static int ticks;
        int main() {
            Spinner s;
            s.every(0.01, [] { ticks++; });
            s.sleep(0.5);
            return ticks == 50 ? 0 : 3;
        }
        """))
    r = drive(build_program([src]), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message


C_QUEUED = """\
#include "spinner.h"
static int ticks;
static void tick(void) { ticks++; spinner_set_servo(0.01 * (ticks % 3)); }
int main(void) {
    spinner_every(0.004, tick);
    unsigned char row[256];
    for (int i = 0; i < 50; i++) {
        spinner_add_textf("frame %d ticks %d", i, ticks);
        spinner_set_speed(0.5);
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
    }
    return ticks >= 200 ? 0 : 3;
}
"""


def test_an_interrupt_due_in_a_queued_call_runs_before_the_waiting_call_it_came_with(tmp_path):
    """--mcu-time lets time pass in calls that do not wait (set_speed, add_text): a handler due
    then runs inside the waiting call that follows them, and the main loop's requests queued
    with it are still its own (in process and isolated alike)."""
    src = tmp_path / "queued.c"
    src.write_text(C_QUEUED)
    program = build_program([src])
    import dataclasses

    logs = []
    for isolate in (False, True):
        csv = tmp_path / f"queued{isolate}.csv"
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=5.0,
                  mcu_time=0.003, csv=csv)
        assert r.outcome == "controller_returned", r.message
        logs.append(csv.read_bytes())
    assert logs[0] == logs[1]


def test_a_handler_that_changes_the_exposure_still_gets_get_image_a_frame(tmp_path):
    """A line camera's exposure set in a handler while main() waits for a frame moves that frame
    (set_exposure): get_image returns at the frame's boundary, one image a frame, as the run log's
    rows record them."""
    images = []

    def main(s):
        exposures = iter([0.0295, 0.0095, 0.0195] * 20)
        count = [0]

        def tick():
            count[0] += 1
            if count[0] % 4 == 0:
                s.set_exposure(next(exposures))

        s.every(0.007, tick)
        for _ in range(25):
            s.get_image(s.line_row)
            images.append(round(s.get_time() - 0.002, 6))  # get_time: one 2-ms step on

    csv = tmp_path / "exposure.csv"
    r = drive(main, track="floor", time_limit_s=2.0, csv=csv)
    assert r.outcome == "controller_returned", r.message
    import csv as csvmod

    with csv.open() as f:
        frame_times = {round(float(row["t_s"]), 6) for row in csvmod.DictReader(line for line in f
                                                                                 if not line.startswith("#"))}
    assert images and all(t in frame_times for t in images), (images, sorted(frame_times)[:20])
    assert len(set(images)) == len(images)


def test_a_handler_that_raises_leaves_the_clock_in_order():
    """A handler's exception reaches main() in the waiting call it ran in; main() may go on: the
    clock and the car move on together (the same position as when the handler does not raise)
    and the handler keeps its rate."""
    def run(raises):
        ticks = []

        def main(s):
            def tick():
                ticks.append(s.get_time())
                if raises and len(ticks) == 1:
                    raise ValueError("once")

            s.set_speed(1.0)
            s.every(0.01, tick)
            try:
                s.sleep(0.05 if raises else 0.01)  # (the exception ends the wait at 0.01 s)
            except ValueError:
                pass
            for _ in range(10):
                s.get_time()
            s.sleep(0.05)
            ticks.append(s.get_position())

        r = drive(main, track="floor", time_limit_s=2.0)
        assert r.outcome == "controller_returned", r.message
        return ticks

    plain, caught = run(False), run(True)
    assert caught == plain  # the same ticks; where the car is after the same simulated time
    assert caught[:-1] == pytest.approx([0.01 * k for k in range(1, len(caught))], abs=1e-9)


def test_a_handler_polls_the_pixy2_without_waiting():
    """getMainFeatures(wait=False) in a handler is a read, not a wait: a new frame's features
    when main() waited past one, else PIXY_RESULT_BUSY; the run once ended there ("cannot
    wait")."""
    from simrunner.sensors.pixy2 import PIXY_RESULT_BUSY

    results = []

    def main(s):
        pixy = s.pixy2()
        pixy.init()

        def tick():
            results.append(pixy.line.getMainFeatures(wait=False))

        s.every(0.005, tick)
        s.sleep(0.5)

    r = drive(main, car=REPO / "examples" / "pixy2_car.toml", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    frames = [x for x in results if x != PIXY_RESULT_BUSY]
    assert len(results) == 100 and 25 <= len(frames) <= 31  # 60 frames a second, 0.5 s


def test_a_handler_that_waits_for_time_is_named_as_such(tmp_path):
    """A loop inside a handler waiting for simulated time never ends (none passes there): the
    stall names the handler's line and says why, in Python, in C in-process and isolated; the TFC
    kit's TFC_Delay_mS in a handler is refused at its line."""
    ctl = tmp_path / "spin.py"
    ctl.write_text(textwrap.dedent("""\
        def main(s):
            def tick():
                t0 = s.get_time()
                while s.get_time() < t0 + 0.01:
                    pass
            s.every(0.05, tick)
            s.sleep(1.0)
        """))
    r = drive(ctl, track="floor", time_limit_s=5.0, wall_limit_s=1.0)
    assert r.outcome == "stalled" and "spin.py:4" in r.message, r.message
    assert "inside an interrupt handler no simulated time passes" in r.message
    src = tmp_path / "spin_isr.c"
    src.write_text(textwrap.dedent("""\
        #include "spinner.h"
        static void tick(void) {
            double t0 = spinner_get_time();
            while (spinner_get_time() < t0 + 0.01) { }
        }
        int main(void) {
            spinner_every(0.05, tick);
            spinner_sleep(1.0);
            return 0;
        }
        """))
    import dataclasses

    program = build_program([src])
    for prog in (program, dataclasses.replace(program, isolate=True)):
        r = drive(prog, track="floor", time_limit_s=5.0, wall_limit_s=1.0)
        assert r.outcome == "stalled" and "spin_isr.c:4" in r.message, r.message
        assert "inside an interrupt handler no simulated time passes" in r.message
    fw = tmp_path / "delay_isr.c"
    fw.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC\\\\TFC.h"
        void LPTimer_IRQHandler(void) {
            TFC_Delay_mS(5);
        }
        int main(void) {
            TFC_Init();
            for (;;) __WFI();
        }
        """))
    r = drive(with_isrs(build_program([fw], kit="tfc"), [("LPTimer_IRQHandler", 0.01)]), track="floor",
              time_limit_s=5.0, wall_limit_s=2.0)
    assert r.outcome == "controller_error" and "delay_isr.c:4: TFC_Delay_mS(5) inside an interrupt handler" \
        in r.message, r.message


def test_more_handlers_than_the_table_holds_is_bad_input(tmp_path):
    src = tmp_path / "many.c"
    src.write_text("void tick(void) {}\nint main(void) { return 0; }\n")
    with pytest.raises(ControllerFileError, match="33 handlers, at most 32"):
        with_isrs(build_program([src]), [("tick", 0.1)] * 33)
