"""Critical sections (issue 50, the kits' ``__disable_irq()`` / ``__enable_irq()``): masked timer
interrupts are held pending, one bit a handler, and run once at the unmask, at its time, in the
order set up (simrunner.run.clock, Masking; the Cortex-M's PRIMASK and NVIC pending bits)."""
from __future__ import annotations

import dataclasses
import re
import textwrap

import pytest

from simrunner.run.native import build_program
from simrunner.run.native.build import with_isrs
from simrunner.run.runner import drive

MASKED_WARNING = "interrupts disabled at"


def ticks_of(main, **kw):
    r = drive(main, track="floor", time_limit_s=2.0, **kw)
    assert r.outcome == "controller_returned", r.message
    return r


# -- Python: Spinner.disable_interrupts / enable_interrupts ----------------------------------------
def test_a_handler_due_while_masked_runs_once_at_the_unmask_and_keeps_its_schedule():
    """10-ms ticks masked from 0 to 0.036 s (three expiries): one call, at 0.036 s; the next at 0.04."""
    calls = []

    def main(s):
        s.every(0.01, lambda: calls.append(round(s.get_time(), 6)))
        s.disable_interrupts()
        s.sleep(0.035)  # 18 steps: 0.036 s
        assert s.interrupts_disabled() and calls == []
        s.enable_interrupts()
        assert calls == [0.036]  # ran inside the unmask, at its time
        s.sleep(0.01)

    ticks_of(main)
    assert calls == [0.036, 0.04]


def test_masking_is_a_bit_and_pending_handlers_run_in_the_order_set_up():
    """Two disables, one enable: unmasked. Pending b (set up first) runs before a; a handler
    stopped while pending does not run."""
    calls = []

    def main(s):
        def stopped():
            calls.append("stopped")

        s.every(0.02, lambda: calls.append("b"))
        s.every(0.01, lambda: calls.append("a"))
        s.every(0.01, stopped)
        s.disable_interrupts()
        s.disable_interrupts()
        s.sleep(0.05)
        s.stop_every(stopped)
        s.enable_interrupts()
        assert not s.interrupts_disabled() and calls == ["b", "a"]
        s.sleep(0.01)  # unmasked: a runs at 0.06, b at 0.06 too (first b, set up first)

    ticks_of(main)
    assert calls == ["b", "a", "b", "a"]


def test_a_mask_set_in_a_handler_holds_later_ones_and_an_unmask_in_a_handler_runs_them_after_it():
    """PRIMASK is not restored by a handler's return: a masks on its first call, so b (due at the
    same step, set up later) is held until main unmasks. An unmask inside a handler lets the held
    ones run after that handler returns (handlers do not nest)."""
    calls = []

    def main(s):
        def a():
            calls.append(("a", round(s.get_time(), 6)))
            if len(calls) == 1:
                s.disable_interrupts()

        s.every(0.01, a)
        s.every(0.01, lambda: calls.append(("b", round(s.get_time(), 6))))
        s.sleep(0.03)  # a at 0.01 masks: b held; a and b held at 0.02 and 0.03
        assert calls == [("a", 0.01)] and s.interrupts_disabled()
        s.enable_interrupts()
        assert calls == [("a", 0.01), ("a", 0.03), ("b", 0.03)]
        s.stop_every(a)
        calls.clear()

        def d():
            calls.append("d start")
            s.disable_interrupts()
            s.enable_interrupts()  # e, held, runs after d returns, not inside it
            calls.append("d end")

        s.every(0.01, d)
        s.every(0.01, lambda: calls.append("e"))
        s.disable_interrupts()
        s.sleep(0.01)  # b, d, e held
        s.enable_interrupts()
        assert calls == [("b", 0.04), "d start", "d end", "e"]

    ticks_of(main)


def test_interrupts_left_disabled_warn_the_run_once():
    calls = []

    def main(s):
        s.every(0.01, lambda: calls.append(1))
        s.disable_interrupts()
        s.sleep(0.5)

    r = ticks_of(main)
    assert calls == []
    masked = [w for w in r.warnings if MASKED_WARNING in w]
    assert len(masked) == 1 and "__enable_irq" in masked[0], masked
    line = main.__code__.co_firstlineno + 2  # s.disable_interrupts()
    assert masked[0].startswith(f"{__file__}:{line}: interrupts disabled at 0.000 s"), masked

    def short(s):  # critical sections of a camera frame each: no warning
        s.every(0.01, lambda: calls.append(1))
        for _ in range(20):
            s.disable_interrupts()
            s.get_image(s.line_row)
            s.enable_interrupts()

    assert not [w for w in ticks_of(short).warnings if MASKED_WARNING in w]

    def slow(s):  # a 1-Hz timer held at 1 s: the warning 0.1 s later, not at its next expiry
        s.every(1.0, lambda: calls.append(1))
        s.disable_interrupts()
        s.sleep(1.3)

    assert [w for w in ticks_of(slow).warnings if MASKED_WARNING in w]


def test_with_mcu_time_no_handler_runs_inside_a_masked_section():
    """--mcu-time fixed: each call lets 3 ms pass, handlers fall due inside the section (between
    its non-waiting calls) and run at the unmask, never inside; time still passes there."""
    log = []

    def main(s):
        inside = [False]
        s.every(0.002, lambda: log.append(inside[0]))
        for _ in range(10):
            s.disable_interrupts()
            inside[0] = True
            for _ in range(4):
                s.set_servo(0.1)  # no wait: only --mcu-time lets time pass here
            inside[0] = False
            s.enable_interrupts()

    r = ticks_of(main, mcu_time=0.003)
    assert r.sim_time_s > 0.1 and len(log) >= 10 and not any(log)


# -- C: spinner.h, in process and --isolate alike -------------------------------------------------
C_MASKED = """\
#include <stdio.h>
#include "spinner.h"
static int in_cs, bad, ticks;
static void tick(void) {
    ticks++;
    if (in_cs) bad++;
    spinner_add_textf("tick %d at %.3f masked %d", ticks, spinner_get_time(), spinner_interrupts_disabled());
}
int main(void) {
    spinner_every(0.01, tick);
    for (int i = 0; i < 20; i++) {
        spinner_disable_interrupts();
        spinner_disable_interrupts();
        in_cs = 1;
        spinner_sleep(0.025);
        spinner_set_speed(0.3);
        (void)spinner_get_speed();
        in_cs = 0;
        spinner_enable_interrupts();
        spinner_disable_interrupts();   /* a section without a wait: no round trip, nothing held */
        spinner_enable_interrupts();
        spinner_sleep(0.004);
    }
    return bad ? 3 : 0;
}
"""


@pytest.fixture(scope="module")
def c_masked(tmp_path_factory):
    src = tmp_path_factory.mktemp("masked") / "masked.c"
    src.write_text(C_MASKED)
    return build_program([src])


@pytest.mark.parametrize("mcu_time", [None, 0.003])
def test_c_masked_handlers_run_once_at_the_unmask_alike_in_process_and_isolated(c_masked, tmp_path, mcu_time):
    """Masked for 0.028 s a pass: the 10-ms tick (two expiries) runs once at the unmask, never in
    the section (also with --mcu-time fixed, where the calls inside let time pass); the run logs
    of the simulator's process and a child process are the same bytes."""
    logs = []
    for isolate in (False, True):
        csv = tmp_path / f"run{isolate}.csv"
        extra = {} if mcu_time is None else {"mcu_time": mcu_time}
        r = drive(dataclasses.replace(c_masked, isolate=isolate), track="floor", time_limit_s=3.0, csv=csv,
                  **extra)
        assert r.outcome == "controller_returned", r.message  # (status 3: a tick inside a section)
        logs.append(csv.read_bytes())
    assert logs[0] == logs[1]
    ticks = re.findall(rb"tick (\d+) at ([0-9.]+) masked (\d)", logs[0])
    assert ticks and all(masked == b"0" for _, _, masked in ticks)
    if mcu_time is None:  # unmasked at 0.028 (held at 0.01, 0.02: one call), then 0.03 unmasked
        assert [t for _, t, _ in ticks[:4]] == [b"0.028", b"0.030", b"0.060", b"0.092"]


C_MASK_IN_HANDLER = """\
#include "spinner.h"
static int a_calls, b_calls, b_while_masked;
static void a(void) {
    if (++a_calls == 1) spinner_disable_interrupts();   /* left masked on return */
}
static void b(void) {
    b_calls++;
    spinner_add_textf("b at %.3f", spinner_get_time());
}
int main(void) {
    spinner_every(0.01, a);
    spinner_every(0.01, b);
    spinner_sleep(0.03);               /* a at 0.01 masks: b held at 0.01, 0.02, 0.03 */
    if (!spinner_interrupts_disabled() || b_calls) return 3;
    spinner_enable_interrupts();       /* a, then b, now: once each */
    if (a_calls != 2 || b_calls != 1) return 4;
    spinner_disable_interrupts();
    spinner_enable_interrupts();       /* nothing between: nothing held */
    spinner_sleep(0.01);
    return a_calls == 3 && b_calls == 2 ? 0 : 5;
}
"""


def test_c_a_mask_set_in_a_handler_holds_the_later_ones_until_main_unmasks(tmp_path):
    src = tmp_path / "mask_in_handler.c"
    src.write_text(C_MASK_IN_HANDLER)
    program = build_program([src])
    logs = []
    for isolate in (False, True):
        csv = tmp_path / f"run{isolate}.csv"
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0, csv=csv)
        assert r.outcome == "controller_returned", r.message
        logs.append(csv.read_bytes())
    assert logs[0] == logs[1] and re.findall(rb"b at ([0-9.]+)", logs[0]) == [b"0.030", b"0.040"]


# -- the kits ---------------------------------------------------------------------------------------
def test_the_tfc_kits_disable_interrupts_holds_a_timer_handler_across_library_calls(tmp_path):
    """--kit tfc: DisableInterrupts / __disable_irq around TFC_Task() passes (each a physics step):
    the --isr handler runs at EnableInterrupts, never between; __get_PRIMASK reads the bit."""
    src = tmp_path / "tfc_cs.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC/TFC.h"
        volatile int in_cs, bad, ticks, primask_bad;
        void Control_Handler(void) { ticks++; if (in_cs) bad++; }
        int main(void) {
            TFC_Init();
            for (int i = 0; i < 30; i++) {
                DisableInterrupts;
                __disable_irq();
                in_cs = 1;
                if (__get_PRIMASK() != 1) primask_bad++;
                for (int k = 0; k < 8; k++) TFC_Task();
                in_cs = 0;
                EnableInterrupts;
                if (__get_PRIMASK() != 0) primask_bad++;
                TFC_Task();
            }
            return bad || primask_bad ? 3 : ticks;
        }
        """))
    program = with_isrs(build_program([str(src)], kit="tfc"), [("Control_Handler", 0.001)])
    r = drive(program, track="floor", time_limit_s=2.0)
    # 1 kHz at the 2-ms step: two calls in TFC_Init's step; then each pass one at the unmask (16
    # expiries held) and two in its unmasked step: 2 + 30 x 3 (masks ignored: 542, and bad)
    assert r.outcome == "controller_error" and "status 92" in r.message, r.message


def test_the_tfc_kits_systick_and_camera_stop_while_interrupts_are_disabled(tmp_path, capfd):
    """--kit tfc: the SysTick tickers and the camera read-out are interrupts on the board: masked,
    the tickers stand still and no image comes; at the unmask the one pending SysTick counts (20 ms
    masked: +1, not +20). A TFC_Delay_mS or a polling loop with interrupts disabled never ends on
    the board: an error at its line, a warning."""
    src = tmp_path / "systick.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include "derivative.h"
        #include "spinner.h"
        #include "TFC/TFC.h"
        int main(void) {
            TFC_Init();
            TFC_Delay_mS(200);  /* images come */
            LineScanImageReady = 0;
            uint32_t t0 = TFC_Ticker[0];
            __disable_irq();
            for (int i = 0; i < 50; i++) TFC_Task();  /* 100 ms */
            uint32_t masked = TFC_Ticker[0] - t0;
            int image = LineScanImageReady;
            __enable_irq();
            TFC_Task();
            printf("masked %u image %d after %u\\n", masked, image, TFC_Ticker[0] - t0);
            if (spinner_param("delay", 0)) { __disable_irq(); TFC_Delay_mS(5); }
            if (spinner_param("poll", 0)) { __disable_irq(); while (TFC_Ticker[0] < t0 + 1000) {} }
            return 0;
        }
        """))
    program = build_program([str(src)], kit="tfc")
    r = drive(program, track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    # masked: no tick, no image; after: the pending tick and the unmasked step's two
    assert "masked 0 image 0 after 3" in capfd.readouterr().out
    r = drive(program, track="floor", time_limit_s=2.0, params={"delay": 1})
    assert r.outcome == "controller_error" and re.search(
        r"systick\.c:17: TFC_Delay_mS\(5\) with interrupts disabled: .* never returns", r.message), r.message
    r = drive(program, track="floor", time_limit_s=0.6, params={"poll": 1})
    assert r.outcome == "timeout" and any("polls the board" in w and "interrupts disabled" in w
                                             for w in r.warnings), (r.outcome, r.warnings)


def test_interrupts_a_firmware_leaves_disabled_are_named_at_its_line(tmp_path):
    """The warning names the firmware's line (through the kit's DisableInterrupts macro), the
    same in the simulator's process and a child process."""
    src = tmp_path / "forgot.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC/TFC.h"
        void Tick(void) {}
        int main(void) {
            DisableInterrupts;
            for (int i = 0; i < 100; i++) TFC_Task();
            return 0;
        }
        """))
    program = with_isrs(build_program([str(src)], kit="tfc"), [("Tick", 0.01)])
    warnings = []
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0)
        warnings.append([w for w in r.warnings if MASKED_WARNING in w])
    assert warnings[0] == warnings[1] and len(warnings[0]) == 1, warnings
    assert re.match(r".*forgot\.c:5: interrupts disabled at 0\.000 s", warnings[0][0]), warnings


def test_mbed_critical_sections_nest_and_hold_tickers_while_waits_go_on(tmp_path):
    """--kit tfc-mbed: core_util_critical_section_enter/exit count (the inner exit keeps them
    disabled), CriticalSectionLock too; a wait_ms inside one ends (mbed waits on the us ticker's
    counter); the kit's clock interrupt is held, and at the exit mbed's ticker queue runs the
    Ticker as often as it fell due (2 ms in a 20-ms wait: 10), none inside."""
    src = tmp_path / "cs.cpp"
    src.write_text(textwrap.dedent("""\
        #include "mbed.h"
        Ticker ticker;
        Timer timer;
        volatile int in_cs, bad, ticks;
        void tick() { ticks++; if (in_cs) bad++; }
        int main() {
            ticker.attach(&tick, 0.002f);
            timer.start();
            core_util_critical_section_enter();
            core_util_critical_section_enter();
            in_cs = 1;
            wait_ms(20);
            int waited = timer.read_ms();
            core_util_critical_section_exit();
            if (core_util_are_interrupts_enabled() || ticks) return 4;
            in_cs = 0;
            core_util_critical_section_exit();
            if (!core_util_are_interrupts_enabled() || ticks < 9) return 5;  /* mbed's queue catches up */
            {
                CriticalSectionLock lock;
                in_cs = 1;
                wait_ms(10);
                in_cs = 0;
            }
            __disable_irq();
            __disable_irq();
            __enable_irq();
            wait_ms(10);
            if (bad || waited < 19) return 6;  /* (20 ms less rounding) */
            return ticks < 8 ? 7 : 0;
        }
        """))
    r = drive(build_program([str(src)], kit="tfc-mbed"), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message


def test_the_s32k144_kits_osif_suspend_holds_a_gpt_notification(tmp_path):
    """--kit s32k144: OsIf_SuspendAllInterrupts / OsIf_ResumeAllInterrupts (RTD bare-metal:
    __disable_irq / __enable_irq) around OsIf_TimeDelay hold the Gpt notification."""
    src = tmp_path / "osif_cs.c"
    src.write_text(textwrap.dedent("""\
        #include "Gpt.h"
        #include "OsIf.h"
        volatile int in_cs, bad, ticks;
        void Gpt_Notification(void) { ticks++; if (in_cs) bad++; }
        int main(void) {
            Gpt_StartTimer(0U, 40000U);     /* 5 ms at the kit's 8 MHz */
            Gpt_EnableNotification(0U);
            for (int i = 0; i < 10; i++) {
                OsIf_SuspendAllInterrupts();
                in_cs = 1;
                OsIf_TimeDelay(12U);
                in_cs = 0;
                OsIf_ResumeAllInterrupts();
            }
            return bad ? 3 : ticks;
        }
        """))
    r = drive(build_program([str(src)], kit="s32k144"), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error" and "status 10" in r.message, r.message  # one a section
    # nested (a driver's section inside the team's): the inner Resume leaves interrupts disabled;
    # the outer one restores what the first Suspend found (OSEK/VDX OS)
    src.write_text(textwrap.dedent("""\
        #include "Gpt.h"
        #include "OsIf.h"
        volatile int in_cs, bad, ticks;
        void Gpt_Notification(void) { ticks++; if (in_cs) bad++; }
        int main(void) {
            Gpt_StartTimer(0U, 40000U);
            Gpt_EnableNotification(0U);
            for (int i = 0; i < 10; i++) {
                OsIf_SuspendAllInterrupts();
                in_cs = 1;
                OsIf_SuspendAllInterrupts();
                OsIf_TimeDelay(6U);
                OsIf_ResumeAllInterrupts();
                OsIf_TimeDelay(6U);
                in_cs = 0;
                OsIf_ResumeAllInterrupts();
            }
            __disable_irq();
            OsIf_SuspendAllInterrupts();
            OsIf_ResumeAllInterrupts();  /* interrupts were disabled before: they stay so */
            if (!__get_PRIMASK()) bad++;
            __enable_irq();
            return bad ? 3 : ticks;
        }
        """))
    r = drive(build_program([str(src)], kit="s32k144"), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error" and "status 10" in r.message, r.message


PIT_AT_1KHZ = textwrap.dedent("""\
    #include "derivative.h"
    #include "TFC/TFC.h"
    volatile int ticks, tif_at_entry;
    void PIT_IRQHandler(void) {
        tif_at_entry += (PIT_TFLG0 & PIT_TFLG_TIF_MASK) != 0;
        PIT_TFLG0 = PIT_TFLG_TIF_MASK;
        ticks++;
    }
    int main(void) {
        TFC_Init();
        SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
        PIT_MCR = 0;
        PIT_LDVAL0 = 24000 - 1;                                /* 1 kHz of the 24 MHz bus */
        PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
        NVIC_EnableIRQ(PIT_IRQn);
        for (int k = 0; k < 5; k++) TFC_Task();
""")
"""A PIT handler counting its calls (and those that found TIF set), the PIT at 1 kHz, five calls in:
the start of the programs below."""
LATCHED_PIT = PIT_AT_1KHZ + textwrap.dedent("""\
        int before = ticks;
        __disable_irq();
        for (int k = 0; k < 4; k++) TFC_Task();                /* expiries held: one pending bit */
        int held = ticks - before;
        STOP;                                                  /* the timer's source off */
        UNPEND;
        __enable_irq();
        int at_unmask = ticks - before;
        for (int k = 0; k < 5; k++) TFC_Task();
        return 1 + 100 * held + 10 * at_unmask + (ticks - before) + (tif_at_entry == ticks ? 0 : 50);
    }
    """)


@pytest.mark.parametrize("stop, unpend, status", [
    ("PIT_TCTRL0 &= ~PIT_TCTRL_TIE_MASK", "", 12),      # its interrupt enable cleared: the NVIC's bit runs it
    ("PIT_TCTRL0 = 0", "", 12),                         # the timer stopped: the same
    ("NVIC_DisableIRQ(PIT_IRQn)", "", 1),               # its IRQ disabled: not taken (the bit waits)
    # ... for NVIC_EnableIRQ, which takes it, once (ARMv6-M B3.4: the pending bit is independent of the
    # enable bit; before the kit emulated that, the held call was dropped: 1)
    ("NVIC_DisableIRQ(PIT_IRQn)", "__enable_irq(); if (ticks != before) return 99; PIT_TCTRL0 = 0; "
                                  "NVIC_EnableIRQ(PIT_IRQn); __disable_irq()", 12),
    ("PIT_TCTRL0 = 0", "NVIC_ClearPendingIRQ(PIT_IRQn)", 1),  # the pending bit cleared: it does not run
    # still running: its source asserts the IRQ again (TIF && TIE), so the clear does not hold: once at the
    # unmask, then 2 a 2-ms step
    ("PIT_TCTRL0 = PIT_TCTRL_TEN_MASK | PIT_TCTRL_TIE_MASK", "NVIC_ClearPendingIRQ(PIT_IRQn)", 22),
])
def test_a_pit_expiry_held_by_the_mask_keeps_its_nvic_pending_bit_after_its_source_is_off(
        tmp_path, stop, unpend, status):
    """--kit tfc, a raw PIT vector (ARMv6-M: an NVIC pending bit stays until taken or cleared): an
    expiry held by __disable_irq still calls PIT_IRQHandler once at __enable_irq although the
    program turned the PIT's interrupt off in the critical section; NVIC_ClearPendingIRQ of the
    stopped timer drops it. Nothing runs while masked, nothing after the stop; TIF is set at entry."""
    src = tmp_path / "latched.c"
    src.write_text(LATCHED_PIT)
    program = build_program([str(src)], kit="tfc", defines=[f"STOP={stop}", f"UNPEND={unpend or '(void)0'}"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0)
        assert r.outcome == "controller_error" and f"status {status}" in r.message, (isolate, r.message)


C_STOPPED_IN_A_HANDLER = """\
#include "spinner.h"
static int a_calls, b_calls;
static void b(void) { b_calls++; }
static void a(void) { if (++a_calls == 2) STOP(b); }
int main(void) {
    spinner_every(0.01, a);
    spinner_every(0.01, b);
    spinner_sleep(0.025);      /* a, b at 0.01; at 0.02 a stops b, due at that step too */
    int mid = b_calls;
    spinner_sleep(0.03);
    return 10 * mid + b_calls + 1;
}
"""


@pytest.mark.parametrize("stop, status", [("spinner_stop_every", 12), ("spinner_stop_every_latched", 23)])
def test_a_handler_stopping_one_due_at_its_step_drops_it_or_with_the_nvics_bit_runs_it_after(tmp_path, stop, status):
    """spinner_stop_every from a handler: one due at the same step does not run; the kits' NVIC stop
    (spinner_stop_every_latched: the other timer had expired, its pending bit stays) runs it once
    after the running handler, then never again; alike in process and isolated."""
    src = tmp_path / "stop_in_handler.c"
    src.write_text(C_STOPPED_IN_A_HANDLER)
    program = build_program([src], defines=[f"STOP={stop}"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0)
        assert r.outcome == "controller_error" and f"status {status}" in r.message, (isolate, r.message)


RELATCHED_PIT = textwrap.dedent("""\
    #include "derivative.h"
    #include "TFC/TFC.h"
    volatile int ticks;
    void PIT_IRQHandler(void) { PIT_TFLG0 = PIT_TFLG_TIF_MASK; ticks++; }
    int main(void) {
        TFC_Init();
        SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
        PIT_MCR = 0;
        PIT_LDVAL0 = 24000 - 1;
        PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
        NVIC_EnableIRQ(PIT_IRQn);
        for (int k = 0; k < 5; k++) TFC_Task();
        int before = ticks;
        __disable_irq();
        for (int k = 0; k < 4; k++) TFC_Task();      /* held: the pending bit set */
        PIT_TCTRL0 &= ~PIT_TCTRL_TIE_MASK;           /* source off: the bit stays */
        TFC_Task();
        PIT_TCTRL0 |= PIT_TCTRL_TIE_MASK;            /* on again: the same bit */
        for (int k = 0; k < 4; k++) TFC_Task();
        AFTER;
        __enable_irq();
        return 1 + ticks - before;
    }
    """)


@pytest.mark.parametrize("after, status", [
    ("(void)0", 2),                                                           # one bit: one call
    ("PIT_TCTRL0 = 0; NVIC_ClearPendingIRQ(PIT_IRQn); TFC_Task()", 1),        # off and cleared: none
    ("NVIC_DisableIRQ(PIT_IRQn); TFC_Task()", 1),                             # IRQ disabled: not taken
    # ... until NVIC_EnableIRQ, once however many expiries since (before the kit emulated the NVIC's pending
    # bit independent of its enable bit, the held call was dropped and the enable took nothing: 1)
    ("NVIC_DisableIRQ(PIT_IRQn); TFC_Task(); __enable_irq(); TFC_Task(); if (ticks != before) return 99; "
     "NVIC_EnableIRQ(PIT_IRQn); PIT_TCTRL0 = 0; __disable_irq()", 2),
])
def test_a_timer_turned_off_and_on_again_while_masked_has_one_pending_bit(tmp_path, after, status):
    """The NVIC has one pending bit an IRQ: a PIT whose interrupt is turned off and on again inside a
    critical section calls its handler once at the unmask (not once for the kept call and once for
    the new one); clearing or disabling it afterwards leaves none (the review's case: a kept call
    left behind made the host fault with an unknown handler)."""
    src = tmp_path / "relatched.c"
    src.write_text(RELATCHED_PIT)
    program = build_program([str(src)], kit="tfc", defines=[f"AFTER={after}"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0)
        assert r.outcome == "controller_error" and f"status {status}" in r.message, (isolate, r.message)


C_LATCHED_API = """\
#include "spinner.h"
static int calls;
static void h(void) { calls++; }
int main(void) {
    spinner_every(0.001, h);
    spinner_sleep(0.01);
    spinner_disable_interrupts();      /* (--mcu-time: the ones due before it run in it) */
    int before = calls;
    spinner_set_servo(0.0);            /* --mcu-time: its time passes, masked: h held */
    BETWEEN;
    spinner_stop_every_latched(h);     /* kept */
    SECOND;
    int n = spinner_interrupts() + 2 * spinner_has_every(h);
    spinner_sleep(0.01);
    spinner_enable_interrupts();
    return 1 + calls - before + 10 * n;
}
"""


@pytest.mark.parametrize("between, mcu_time", [("spinner_sleep(0.01)", None), ("spinner_sleep(0.01)", 0.003),
                                               ("(void)0", 0.003)])  # (only --mcu-time's request let time pass)
@pytest.mark.parametrize("second, status", [("(void)0", 2), ("spinner_stop_every(h)", 1)])
def test_spinner_stop_every_latched_keeps_one_call_and_a_later_stop_drops_it(tmp_path, second, status, between,
                                                                             mcu_time):
    """spinner.h: a latched stop keeps the held call (also when the time passed in a request of
    --mcu-time); the handler counts as stopped at once (spinner_interrupts 0, spinner_has_every 0);
    a spinner_stop_every after it drops the kept call, once (no second stop of the slot)."""
    src = tmp_path / "latched_api.c"
    src.write_text(C_LATCHED_API)
    program = build_program([src], defines=[f"SECOND={second}", f"BETWEEN={between}"])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and f"status {status}" in r.message, (isolate, r.message)


# -- the NVIC's pending bits (--kit tfc): independent of the IRQ's enable bit, set by ISPR --------
DISABLED_PIT = PIT_AT_1KHZ + textwrap.dedent("""\
        DISABLE;
        int before = ticks;
        for (int k = 0; k < 4; k++) TFC_Task();                /* expiries: the pending bit, not taken */
        int held = ticks - before;
        BEFORE;
        ENABLE;
        int at_enable = ticks - before;
        PIT_TCTRL0 = 0;                                        /* (no expiry after it: only the pending one) */
        for (int k = 0; k < 5; k++) TFC_Task();
        return 1 + 100 * held + 10 * at_enable + (ticks - before) + (tif_at_entry == ticks ? 0 : 50);
    }
    """)
CMSIS_OFF, CMSIS_ON = "NVIC_DisableIRQ(PIT_IRQn)", "NVIC_EnableIRQ(PIT_IRQn)"
RAW_OFF, RAW_ON = "NVIC_ICER = 1u << (INT_PIT - 16)", "NVIC_ISER = 1u << (INT_PIT - 16)"


@pytest.mark.parametrize("disable, before, enable, status, mcu_status", [
    (CMSIS_OFF, "(void)0", CMSIS_ON, 12, 14),         # four expiries while disabled: one call, in the enable
    (RAW_OFF, "(void)0", RAW_ON, 2, 4),               # raw writes: seen at the next call, taken there
    (CMSIS_OFF, "PIT_TCTRL0 = 0", CMSIS_ON, 12, 12),   # the timer stopped: its pending bit stays
    (CMSIS_OFF, "PIT_TCTRL0 = 0; NVIC_ClearPendingIRQ(PIT_IRQn)", CMSIS_ON, 1, 1),  # stopped and cleared: none
    (CMSIS_OFF, "PIT_TCTRL0 = 0; NVIC_ICPR = 1u << (INT_PIT - 16)", CMSIS_ON, 1, 1),
    # still running, TIF set: the flag asserts the IRQ again, the clear does not hold
    (CMSIS_OFF, "NVIC_ClearPendingIRQ(PIT_IRQn)", CMSIS_ON, 12, 14),
    # masked too: the enable makes it pending-and-enabled, the unmask takes it
    (CMSIS_OFF, "__disable_irq(); NVIC_EnableIRQ(PIT_IRQn); TFC_Task(); if (ticks != before) return 99",
     "__enable_irq()", 12, 12),
])
@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_a_pit_expiry_while_its_irq_is_disabled_in_the_nvic_is_taken_once_at_the_enable(
        tmp_path, disable, before, enable, status, mcu_status, mcu_time):
    """--kit tfc (ARMv6-M, ARM DDI 0419, B3.4: an interrupt's pending bit is independent of its enable
    bit): a PIT expiring four times while NVIC_DisableIRQ(PIT_IRQn) calls nothing then and its
    handler once (TIF set) when the IRQ is enabled again - inside NVIC_EnableIRQ, or at the next call
    after a raw NVIC_ISER write; NVIC_ClearPendingIRQ of the stopped timer drops it; of a running
    one it cannot (its flag asserts the IRQ again). In process and isolated, with --mcu-time too.
    With --mcu-time 0.0005 the access that stops a PIT still running after the enable (PIT_TCTRL0 =
    0) is charged, as a read of a running timer's count is (docs/drive.md): the charges before it add
    up to a 2-ms physics step there, in which the 1-kHz PIT, its IRQ enabled, expires twice before
    the write stops it - two calls more (mcu_status); its pending call is taken once all the same."""
    src = tmp_path / "disabled.c"
    src.write_text(DISABLED_PIT)
    program = build_program([str(src)], kit="tfc", defines=[f"DISABLE={disable}", f"BEFORE={before}",
                                                            f"ENABLE={enable}"])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    status = status if mcu_time is None else mcu_status
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and f"status {status}" in r.message, (isolate, r.message)


PHASE_PIT = textwrap.dedent("""\
    #include "derivative.h"
    #include "spinner.h"
    #include "TFC/TFC.h"
    static volatile unsigned n;
    static double at[64];
    void PIT_IRQHandler(void) { PIT_TFLG0 = PIT_TFLG_TIF_MASK; at[n++] = spinner_get_time(); }
    int main(void) {
        TFC_Init();
        NVIC_DisableIRQ(PIT_IRQn);                             /* (TFC_Init enables it, as the library) */
        SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
        PIT_MCR = 0;
        PIT_LDVAL0 = 240000 - 1;                               /* 100 Hz */
        PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;  /* counts from t0, its IRQ off */
        double t0 = spinner_now();
        spinner_sleep(0.025);                                  /* expiries at 0.01, 0.02: pending */
        NVIC_EnableIRQ(PIT_IRQn);                              /* taken now, 0.026 */
        spinner_sleep(0.03);                                   /* 0.03, 0.04, 0.05: the PIT's own phase */
        for (unsigned i = 0; i < n; i++) printf("%.3f ", at[i] - t0);
        printf("\\n");
        return 0;
    }
    """)


@pytest.mark.parametrize("isolate", [False, True])
def test_a_timer_counting_with_its_irq_off_keeps_its_phase_and_pends_once(tmp_path, capfd, isolate):
    """The PIT counts while its IRQ is off in the NVIC: the expiries before NVIC_EnableIRQ set one
    pending bit (one call, at the enable) and the calls after it follow the timer's own period from
    its start, not one from the enable."""
    src = tmp_path / "phase.c"
    src.write_text(PHASE_PIT)
    r = drive(dataclasses.replace(build_program([src], kit="tfc"), isolate=isolate), track="floor",
              time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    assert capfd.readouterr().out.split() == ["0.026", "0.030", "0.040", "0.050"]


SET_PENDING = textwrap.dedent("""\
    #include "derivative.h"
    #include "spinner.h"
    #include "TFC/TFC.h"
    volatile int calls, outside;
    void PIT_IRQHandler(void) { calls++; outside += !spinner_in_interrupt(); }
    int main(void) {
        TFC_Init();
        NVIC_EnableIRQ(PIT_IRQn);
        STEPS;
        int now = calls;
        TFC_Task();
        TFC_Task();
        return 1 + 10 * now + calls + 100 * outside;
    }
    """)


@pytest.mark.parametrize("steps, status", [
    ("NVIC_SetPendingIRQ(PIT_IRQn)", 12),                  # enabled, unmasked: taken at once
    ("NVIC_SetPendingIRQ(PIT_IRQn); NVIC_SetPendingIRQ(PIT_IRQn)", 23),  # taken each time: it was not pending
    ("NVIC_ISPR = 1u << (INT_PIT - 16)", 2),                # a raw write: taken at the next call
    # masked: one bit however often it is set, taken at the unmask
    ("__disable_irq(); NVIC_SetPendingIRQ(PIT_IRQn); NVIC_SetPendingIRQ(PIT_IRQn); TFC_Task(); "
     "if (calls) return 99; __enable_irq()", 12),
    ("__disable_irq(); NVIC_SetPendingIRQ(PIT_IRQn); __enable_irq()", 12),  # (no call between)
    # disabled in the NVIC: taken at the enable
    ("NVIC_DisableIRQ(PIT_IRQn); NVIC_SetPendingIRQ(PIT_IRQn); TFC_Task(); if (calls) return 99; "
     "NVIC_EnableIRQ(PIT_IRQn)", 12),
    # masked, then disabled before the unmask: not taken at the unmask, at the enable
    ("__disable_irq(); NVIC_SetPendingIRQ(PIT_IRQn); TFC_Task(); NVIC_DisableIRQ(PIT_IRQn); __enable_irq(); "
     "TFC_Task(); if (calls) return 99; NVIC_EnableIRQ(PIT_IRQn)", 12),
    # cleared before it could be taken: none
    ("NVIC_DisableIRQ(PIT_IRQn); NVIC_SetPendingIRQ(PIT_IRQn); NVIC_ClearPendingIRQ(PIT_IRQn); "
     "NVIC_EnableIRQ(PIT_IRQn)", 1),
    ("__disable_irq(); NVIC_SetPendingIRQ(PIT_IRQn); TFC_Task(); NVIC_ClearPendingIRQ(PIT_IRQn); __enable_irq()", 1),
    # NVIC_GetPendingIRQ: the ISPR bit
    ("NVIC_DisableIRQ(PIT_IRQn); if (NVIC_GetPendingIRQ(PIT_IRQn)) return 98; NVIC_SetPendingIRQ(PIT_IRQn); "
     "if (NVIC_GetPendingIRQ(PIT_IRQn) != 1) return 97; "
     "NVIC_ClearPendingIRQ(PIT_IRQn); if (NVIC_GetPendingIRQ(PIT_IRQn)) return 95; NVIC_SetPendingIRQ(PIT_IRQn); "
     "NVIC_EnableIRQ(PIT_IRQn); if (NVIC_GetPendingIRQ(PIT_IRQn)) return 94", 12),
])
@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_nvic_set_pending_irq_runs_the_handler_once_when_enabled_and_unmasked(tmp_path, steps, status, mcu_time):
    """NVIC_SetPendingIRQ (and an NVIC_ISPR write) pends the IRQ in software (ARMv6-M, ARM DDI 0419,
    B3.4): its handler runs once, as an interrupt, as soon as the IRQ is enabled in the NVIC and
    interrupts are unmasked - inside the call, or at the next call after a raw write; one bit however
    often it is set; NVIC_ClearPendingIRQ drops it. In process and isolated, with --mcu-time too."""
    src = tmp_path / "set_pending.c"
    src.write_text(SET_PENDING)
    program = build_program([str(src)], kit="tfc", defines=[f"STEPS={steps}"])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and f"status {status}" in r.message, (isolate, r.message)


@pytest.mark.parametrize("isolate", [False, True])
def test_pending_irqs_enabled_together_are_taken_in_the_order_of_their_numbers(tmp_path, isolate):
    """TPM2 (IRQ 19), LPTMR0 (28, its Kinetis SDK vector name) pended while disabled in the NVIC, then
    both enabled by one NVIC_ISER write: taken at the next call, TPM2 first (the NVIC's order for
    equal priorities), each once."""
    src = tmp_path / "order.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "TFC/TFC.h"
        volatile int order;
        void TPM2_IRQHandler(void) { order = order * 10 + 2; }
        void LPTMR0_IRQHandler(void) { order = order * 10 + 3; }
        int main(void) {
            TFC_Init();
            NVIC_SetPendingIRQ(LPTMR0_IRQn);
            NVIC_SetPendingIRQ(TPM2_IRQn);
            TFC_Task();
            if (order) return 99;
            NVIC_ISER = (1u << (INT_TPM2 - 16)) | (1u << (INT_LPTimer - 16));
            TFC_Task();
            TFC_Task();
            return order;
        }
        """))
    r = drive(dataclasses.replace(build_program([src], kit="tfc"), isolate=isolate), track="floor",
              time_limit_s=2.0)
    assert r.outcome == "controller_error" and "status 23" in r.message, r.message


NVIC_ORDER = textwrap.dedent("""\
    #include "derivative.h"
    #include "spinner.h"
    #include "TFC/TFC.h"
    volatile int order, pit_calls;
    void TPM2_IRQHandler(void) { order = order * 10 + 2; TPM2_DOES; }
    void PIT_IRQHandler(void) { order = order * 10 + 1; if (++pit_calls == 1) { PIT_DOES; } }
    void LPTMR0_IRQHandler(void) { order = order * 10 + 3; }
    static void tick(void) { spinner_stop_every(tick); TICK_DOES; }
    int main(void) {
        TFC_Init();
        NVIC_EnableIRQ(TPM2_IRQn);
        NVIC_EnableIRQ(PIT_IRQn);
        NVIC_EnableIRQ(LPTMR0_IRQn);
        STEPS;
        TFC_Task();
        TFC_Task();
        return 1 + order;
    }
    """)
BOTH_OFF_AND_PENDING = ("NVIC_DisableIRQ(PIT_IRQn); NVIC_DisableIRQ(TPM2_IRQn); NVIC_SetPendingIRQ(PIT_IRQn); "
                        "NVIC_SetPendingIRQ(TPM2_IRQn); ")


@pytest.mark.parametrize("steps, does, status", [
    # two clears between two looks of the kit: both hold (NVIC_ClearPendingIRQ writes ICPR, write-1-to-clear)
    ("NVIC_DisableIRQ(PIT_IRQn); NVIC_DisableIRQ(LPTMR0_IRQn); NVIC_SetPendingIRQ(PIT_IRQn); "
     "NVIC_SetPendingIRQ(LPTMR0_IRQn); NVIC_ClearPendingIRQ(PIT_IRQn); NVIC_ClearPendingIRQ(LPTMR0_IRQn); "
     "NVIC_EnableIRQ(PIT_IRQn); NVIC_EnableIRQ(LPTMR0_IRQn)", {}, 1),
    # in a handler, set then cleared: not taken after it; cleared then set: taken after it
    ("NVIC_SetPendingIRQ(PIT_IRQn)",
     {"PIT_DOES": "NVIC_SetPendingIRQ(LPTMR0_IRQn); NVIC_ClearPendingIRQ(LPTMR0_IRQn)"}, 2),
    ("NVIC_SetPendingIRQ(PIT_IRQn)",
     {"PIT_DOES": "NVIC_ClearPendingIRQ(LPTMR0_IRQn); NVIC_SetPendingIRQ(LPTMR0_IRQn)"}, 14),
    # pending together at the unmask: the NVIC takes the lowest number first (TPM2 19, PIT 22, LPTMR0 28),
    # whatever the order they were pended or enabled in
    ("__disable_irq(); NVIC_SetPendingIRQ(LPTMR0_IRQn); NVIC_SetPendingIRQ(TPM2_IRQn); "
     "NVIC_SetPendingIRQ(PIT_IRQn); __enable_irq()", {}, 214),
    ("__disable_irq(); NVIC_SetPendingIRQ(LPTMR0_IRQn); TFC_Task(); NVIC_SetPendingIRQ(PIT_IRQn); TFC_Task(); "
     "NVIC_SetPendingIRQ(TPM2_IRQn); __enable_irq()", {}, 214),
    (BOTH_OFF_AND_PENDING + "__disable_irq(); NVIC_EnableIRQ(PIT_IRQn); NVIC_EnableIRQ(TPM2_IRQn); "
     "__enable_irq()", {}, 22),
    # enabled together (a raw write, then the CMSIS call that looks at it): the same
    (BOTH_OFF_AND_PENDING + "NVIC_ISER = 1u << (INT_PIT - 16); NVIC_EnableIRQ(TPM2_IRQn)", {}, 22),
    # ... and the first one's handler disables the next IRQ: that one waits for its enable
    (BOTH_OFF_AND_PENDING + "NVIC_ISER = 1u << (INT_PIT - 16); NVIC_EnableIRQ(TPM2_IRQn); "
     "if (order != 2) return 99; NVIC_EnableIRQ(PIT_IRQn)", {"TPM2_DOES": "NVIC_DisableIRQ(PIT_IRQn)"}, 22),
    # pended one by one in a handler of the program's own (spinner_every): after it, in the NVIC's order
    ("spinner_every(0.001, tick)",
     {"TICK_DOES": "NVIC_SetPendingIRQ(LPTMR0_IRQn); NVIC_SetPendingIRQ(PIT_IRQn); NVIC_SetPendingIRQ(TPM2_IRQn)"},
     214),
])
@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_nvic_pending_bits_clear_and_order_as_the_nvic_does(tmp_path, steps, does, status, mcu_time):
    """--kit tfc (ARMv6-M, ARM DDI 0419, B3.4): NVIC_ClearPendingIRQ of two IRQs before the kit looks
    clears both; in a handler, a clear after a set clears it; IRQs pending and enabled together are
    taken lowest number first, also when pended or enabled at different times under __disable_irq
    or in a handler. In process and isolated, with --mcu-time too."""
    src = tmp_path / "nvic_order.c"
    src.write_text(NVIC_ORDER)
    defines = [f"STEPS={steps}"] + [f"{k}={does.get(k, '(void)0')}" for k in ("TPM2_DOES", "PIT_DOES", "TICK_DOES")]
    program = build_program([str(src)], kit="tfc", defines=defines)
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and re.search(rf"status {status}\b", r.message), (isolate, r.message)


# -- NVIC_GetPendingIRQ of an expiry held by __disable_irq or a running handler (--kit tfc) ---------
HELD_PENDING = PIT_AT_1KHZ + textwrap.dedent("""\
        __disable_irq();                                       /* (--mcu-time: handlers due may run first) */
        int before = ticks;
        if (NVIC_GetPendingIRQ(PIT_IRQn)) return 99;           /* no time passed while masked: none */
        for (int k = 0; k < 4; k++) TFC_Task();                /* expiries held: one pending bit */
        if (ticks != before) return 98;
        int inside = NVIC_GetPendingIRQ(PIT_IRQn);
        INSIDE;
        int after_inside = NVIC_GetPendingIRQ(PIT_IRQn);
        __enable_irq();
        int at_unmask = ticks - before;
        if (NVIC_GetPendingIRQ(PIT_IRQn) != AFTER) return 97;
        PIT_TCTRL0 = 0;
        for (int k = 0; k < 3; k++) TFC_Task();
        if (ticks - before != at_unmask) return 96;            /* nothing more ran */
        if (tif_at_entry != ticks) return 95;                  /* TIF set at every entry */
        return 1 + 100 * inside + 10 * after_inside + at_unmask;
    }
    """)


@pytest.mark.parametrize("inside, after, status", [
    ("(void)0", 0, 112),                                       # pending inside, taken once at the unmask, 0 after
    # a running PIT: its flag (TIF && TIE) asserts the IRQ again at once, the clear does not hold
    ("NVIC_ClearPendingIRQ(PIT_IRQn)", 0, 112),
    ("NVIC_ICPR = 1u << (INT_PIT - 16)", 0, 112),
    # the timer's source off: the NVIC's bit stays (latched), taken at the unmask ...
    ("PIT_TCTRL0 = 0", 0, 112),
    ("PIT_TCTRL0 &= ~PIT_TCTRL_TIE_MASK", 0, 112),
    # ... unless cleared: then it reads 0 and does not run
    ("PIT_TCTRL0 = 0; NVIC_ClearPendingIRQ(PIT_IRQn)", 0, 101),
    # its IRQ disabled in the NVIC: still pending (independent of the enable bit), not taken at the unmask
    ("NVIC_DisableIRQ(PIT_IRQn)", 1, 111),
])
@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_nvic_get_pending_irq_reports_an_expiry_held_by_disable_irq(tmp_path, inside, after, status, mcu_time):
    """--kit tfc (ARMv6-M, ARM DDI 0419, B3.4: an enabled interrupt whose source asserts while PRIMASK
    is set is pending; its ISPR bit reads 1): a PIT running with its IRQ enabled that expires inside
    __disable_irq() reads NVIC_GetPendingIRQ(PIT_IRQn) == 1 there (0 right after the mask, before any
    time passed), its handler runs once at __enable_irq() and the bit reads 0 after. NVIC_ClearPendingIRQ
    of the running timer cannot clear it (its flag asserts the IRQ again); of the stopped one it does:
    0, and no call. (Before, the held expiry was the simulator's, not a bit the kit reported: 0.)
    In process and isolated, with --mcu-time too."""
    src = tmp_path / "held_pending.c"
    src.write_text(HELD_PENDING)
    program = build_program([str(src)], kit="tfc", defines=[f"INSIDE={inside}", f"AFTER={after}"])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and re.search(rf"status {status}\b", r.message), (isolate, r.message)


PENDING_IN_A_HANDLER = textwrap.dedent("""\
    #include "derivative.h"
    #include "spinner.h"
    #include "TFC/TFC.h"
    volatile int pit_on, pit_calls, reads, pend;
    static void read_pit(void) {
        if (!pit_on || !pit_calls) return;                  /* (from its first expiry: with --mcu-time the
                                                             * step its set-up is read at may pass first) */
        reads++;
        pend += NVIC_GetPendingIRQ(PIT_IRQn);                /* the PIT is due at this step, after this one */
    }
    void PIT_IRQHandler(void) { PIT_TFLG0 = PIT_TFLG_TIF_MASK; pit_calls++; }
    void LPTimer_IRQHandler(void) { LPTMR0_CSR |= LPTMR_CSR_TCF_MASK; read_pit(); }
    static void tick(void) { read_pit(); }
    int main(void) {
        TFC_Init();
        FIRST;                                                 /* a 2-ms interrupt set up before the PIT */
        TFC_Task();
        SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
        PIT_MCR = 0;
        PIT_LDVAL0 = 48000 - 1;                                /* 500 Hz: due at every 2-ms step too */
        PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
        NVIC_EnableIRQ(PIT_IRQn);
        pit_on = 1;
        for (int k = 0; k < 5; k++) TFC_Task();
        if (NVIC_GetPendingIRQ(PIT_IRQn)) return 99;           /* taken: 0 */
        if (reads < 3 || pit_calls < 3) return 90;
        return pend == reads ? 12 : 20 + pend;
    }
    """)
LPTMR_500HZ = ("SIM_SCGC5 |= SIM_SCGC5_LPTMR_MASK; LPTMR0_PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK; "
               "LPTMR0_CMR = LPTMR_CMR_COMPARE(2 - 1); LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK; "
               "NVIC_EnableIRQ(LPTimer_IRQn)")


@pytest.mark.parametrize("first", ["spinner_every(0.002, tick)", LPTMR_500HZ])
@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_nvic_get_pending_irq_in_a_handler_reports_another_irq_due_after_it(tmp_path, first, mcu_time):
    """--kit tfc (ARMv6-M, ARM DDI 0419, B3.4): while a handler runs, another enabled IRQ whose timer
    expired is pending (it is taken after the handler): a program's own 2-ms interrupt, or the LPTMR's
    handler, set up before a 2-ms PIT, reads NVIC_GetPendingIRQ(PIT_IRQn) == 1 at every step (the PIT
    due at the same step runs after it); main() reads 0 once it ran. In process and isolated."""
    src = tmp_path / "pending_in_handler.c"
    src.write_text(PENDING_IN_A_HANDLER)
    program = build_program([str(src)], kit="tfc", defines=[f"FIRST={first}"])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and re.search(r"status 12\b", r.message), (isolate, r.message)


LOOK_IN_A_LOOK = textwrap.dedent("""\
    #include "derivative.h"
    #include "spinner.h"
    #include "TFC/TFC.h"
    volatile int pit_calls, twice;
    static double last_s = -1.0;
    void PIT_IRQHandler(void) {
        PIT_TFLG0 = PIT_TFLG_TIF_MASK;
        double t = spinner_now();                              /* (the handler's time) */
        twice += t == last_s;
        last_s = t;
        pit_calls++;
    }
    static void tick(void) { (void)NVIC_GetPendingIRQ(PIT_IRQn); }  /* the kit looks at the registers */
    int main(void) {
        TFC_Init();
        spinner_every(0.002, tick);
        for (int k = 0; k < CALLS; k++) spinner_get_exposure();  /* where in a step the charge is */
        TFC_Task();
        SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
        PIT_MCR = 0;
        PIT_LDVAL0 = 48000 - 1;                                /* 500 Hz: one call a 2-ms step */
        PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
        NVIC_EnableIRQ(PIT_IRQn);
        for (int k = 0; k < 10; k++) TFC_Task();
        return pit_calls >= 8 && twice == 0 ? 12 : 20 + twice;
    }
    """)


@pytest.mark.parametrize("calls", [0, 1, 2, 3])
def test_a_timer_started_while_a_handler_looks_at_the_registers_starts_once(tmp_path, calls):
    """--kit tfc with --mcu-time 0.5 ms (a quarter step a call): the look that starts the PIT asks
    the simulator for the time, which charges the program's time first; where that crosses a step,
    a program's 2-ms interrupt due then runs inside the look, and its NVIC_GetPendingIRQ looks at the
    registers again. That look took the PIT being started for one started again and started it a
    second time: its handler ran twice a step (14 calls in 7 steps). Now one call a step, wherever
    in a step the charge falls (0 to 3 calls more before the set-up). In process and isolated."""
    src = tmp_path / "look_in_a_look.c"
    src.write_text(LOOK_IN_A_LOOK)
    program = build_program([str(src)], kit="tfc", defines=[f"CALLS={calls}"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, mcu_time=0.0005)
        assert r.outcome == "controller_error" and re.search(r"status 12\b", r.message), (isolate, r.message)


ISR_HELD = textwrap.dedent("""\
    #include "derivative.h"
    #include "TFC/TFC.h"
    volatile int ticks;
    void PIT_IRQHandler(void) { ticks++; }
    int main(void) {
        TFC_Init();
        for (int k = 0; k < 3; k++) TFC_Task();
        __disable_irq();                                       /* (--mcu-time: handlers due may run first) */
        int before = ticks;
        if (NVIC_GetPendingIRQ(PIT_IRQn)) return 99;           /* no time passed while masked: none */
        for (int k = 0; k < 4; k++) TFC_Task();                /* its calls held: one pending bit */
        int inside = NVIC_GetPendingIRQ(PIT_IRQn);
        __enable_irq();
        int at_unmask = ticks - before, after = NVIC_GetPendingIRQ(PIT_IRQn);
        return 1 + 100 * inside + 10 * after + at_unmask;
    }
    """)


@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_nvic_get_pending_irq_reports_a_held_call_of_a_vector_isr_runs(tmp_path, mcu_time):
    """--isr PIT_IRQHandler@1000 (the kit leaves the vector to --isr): its calls held by
    __disable_irq read as the IRQ's pending bit (ARMv6-M, ARM DDI 0419, B3.4), it runs once at the
    unmask, and reads 0 after. In process and isolated."""
    src = tmp_path / "isr_held.c"
    src.write_text(ISR_HELD)
    program = with_isrs(build_program([str(src)], kit="tfc"), [("PIT_IRQHandler", 0.001)])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0, **extra)
        assert r.outcome == "controller_error" and re.search(r"status 102\b", r.message), (isolate, r.message)
