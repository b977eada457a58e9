"""spinner_now (the simulated time without a physics step; the kits' live timer counters read
it): its answer with --mcu-time (a read charged as any call: a loop polling the time ends), and the
round trips it costs (spinner_host.c, now_known)."""
from __future__ import annotations

import collections
import dataclasses
import re

import pytest

from simrunner.run.native import bridge, build_program
from simrunner.run.runner import drive

NOW_AFTER_CALLS = """\
#include "spinner.h"
int main(void) {
    double a = spinner_now();
    spinner_set_servo(0.0);          /* queued: with --mcu-time it lets the code's time pass */
    double b = spinner_now();        /* with --mcu-time a read is charged too */
    spinner_set_servo(0.0);
    double c = spinner_now();
    double d = spinner_now();        /* no call between: its own charge only */
    double e = spinner_get_time();
    spinner_add_textf("now %.0f %.0f %.0f %.0f", (b - a) * 1e6, (c - b) * 1e6, (d - c) * 1e6, (e - d) * 1e6);
    double f = spinner_now_uncharged();
    spinner_set_servo(0.0);
    double g = spinner_now_uncharged();  /* the time of set_servo's charge */
    double h = spinner_now_uncharged();  /* no call between: the same time */
    spinner_add_textf("uncharged %.0f %.0f", (g - f) * 1e6, (h - g) * 1e6);
    return 0;
}
"""


@pytest.fixture
def op_counts(monkeypatch):
    """The requests the simulator handles, by op (in-process and isolated alike: both go through
    ``_Session._handle``)."""
    ops = collections.Counter()
    handle = bridge._Session._handle

    def counting(self, op, payload):
        ops[op] += 1
        return handle(self, op, payload)

    monkeypatch.setattr(bridge._Session, "_handle", counting)
    return ops


@pytest.fixture(scope="module")
def now_after_calls(tmp_path_factory):
    src = tmp_path_factory.mktemp("now") / "now.c"
    src.write_text(NOW_AFTER_CALLS)
    return build_program([src])


@pytest.mark.parametrize("isolate", [False, True])
def test_with_mcu_time_spinner_now_includes_the_time_of_the_calls_before_it(now_after_calls, tmp_path, isolate):
    """--mcu-time 0.002 (one 2-ms physics step a call): each spinner_set_servo lets 2 ms pass, and
    each spinner_now read too (a read of the time is charged as any call: a loop polling it ends), so
    the time read after a set_servo is 4 ms later, a read right after a read 2 ms - not the time
    cached at the read before it (a counter timing the code between two reads read 0).
    spinner_now_uncharged (the kits' bookkeeping) is not charged: 2 ms after a set_servo, then 0."""
    csv = tmp_path / "log.csv"
    r = drive(dataclasses.replace(now_after_calls, isolate=isolate), track="floor", time_limit_s=1.0,
              csv=csv, mcu_time=0.002)
    assert r.outcome == "controller_returned", r.message
    text = csv.read_bytes()
    got = re.search(rb"now (\d+) (\d+) (\d+) (\d+)", text)
    assert got and [int(v) for v in got.groups()] == [4000, 4000, 2000, 4000], got  # (get_time: its charge, its step)
    got = re.search(rb"uncharged (\d+) (\d+)", text)
    assert got and [int(v) for v in got.groups()] == [2000, 0], got


PIT_READS = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
void PIT_IRQHandler(void) {
    PIT_TFLG0 = PIT_TFLG_TIF_MASK;
    spinner_add_textf("isr %u cval %u", ++n, (unsigned)PIT_CVAL0);
}
int main(void) {
    TFC_Init();
    PIT_MCR = 0;
    PIT_LDVAL0 = 240000 - 1;          /* 100 Hz of the 24 MHz bus clock: 5 physics steps of 2 ms */
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_EnableIRQ(PIT_IRQn);
    for (int i = 0; i < 50; i++) {
        spinner_sleep(0.002);
        if (i % 10 == 3) spinner_add_textf("main cval %u", (unsigned)PIT_CVAL0);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def pit_reads(tmp_path_factory):
    src = tmp_path_factory.mktemp("pit") / "pit.c"
    src.write_text(PIT_READS)
    return build_program([src], kit="tfc")


def test_a_running_timer_costs_no_time_request_per_wait_nor_per_handler(pit_reads, tmp_path, op_counts):
    """A 100-Hz PIT read in its handler and now and then in main(): the handler's reads take the
    time its interrupt came with, the kit's look before each wait reads none for a counter running
    unchanged - one time request per read of main() (5: OP_NOW) and the look that starts it (OP_NOW_UNCHARGED),
    none per wait (50) or handler (10). The counts are
    the PIT's: at each expiry CVAL is LDVAL; four sleeps into a period 8 ms of its 10 are gone.
    In-process and isolated runs log the same bytes."""
    ops = op_counts
    logs = []
    for isolate in (False, True):
        ops.clear()
        csv = tmp_path / f"log{isolate}.csv"
        r = drive(dataclasses.replace(pit_reads, isolate=isolate), track="floor", time_limit_s=1.0, csv=csv)
        assert r.outcome == "controller_returned", r.message
        reads = ops[bridge.OP_NOW] + ops[bridge.OP_NOW_UNCHARGED]  # (the look's: spinner_now_uncharged)
        assert reads == 6, ops  # (and the look that starts it)
        logs.append(csv.read_bytes())
    assert logs[0] == logs[1]
    isr = [int(v) for v in re.findall(rb"isr \d+ cval (\d+)", logs[0])]
    main = {int(v) for v in re.findall(rb"main cval (\d+)", logs[0])}
    assert len(isr) == 10 and set(isr) == {239999}
    assert main == {239999 - 24 * 8000}, main  # (four 2-ms sleeps into a period)


NOW_IN_SECTION = """\
#include "spinner.h"
static int ticks;
static void tick(void) { ticks++; }
int main(void) {
    spinner_every(0.01, tick);
    for (int i = 0; i < 50; i++) {
        spinner_sleep(0.002);
        spinner_disable_interrupts();
        double t = spinner_now();     /* a counter read inside a critical section */
        spinner_enable_interrupts();
        if (i % 10 == 9) spinner_add_textf("at %.3f ticks %d", t, ticks);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def now_in_section(tmp_path_factory):
    src = tmp_path_factory.mktemp("section") / "section.c"
    src.write_text(NOW_IN_SECTION)
    return build_program([src])


def test_a_time_read_in_a_critical_section_sends_no_mask(now_in_section, tmp_path, op_counts):
    """spinner_now lets no time pass, so no handler can fall due in it: a section around it holds
    nothing and sends nothing (it sent the mask with the read and made the unmask a round trip:
    two messages a pass). The ticks come as without the section, in both modes alike."""
    ops = op_counts
    logs = []
    for isolate in (False, True):
        ops.clear()
        csv = tmp_path / f"log{isolate}.csv"
        r = drive(dataclasses.replace(now_in_section, isolate=isolate), track="floor", time_limit_s=1.0, csv=csv)
        assert r.outcome == "controller_returned", r.message
        assert ops[bridge.OP_IRQ_MASK] + ops[bridge.OP_IRQ_MASK_WAIT] == 0, ops
        assert ops[bridge.OP_NOW] == 50
        logs.append(csv.read_bytes())
    assert logs[0] == logs[1]
    assert re.findall(rb"at ([0-9.]+) ticks (\d+)", logs[0]) == [
        (b"%.3f" % (0.02 * k), b"%d" % (2 * k)) for k in range(1, 6)]


PIT_SET_UP_THEN_READS = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
void PIT_IRQHandler(void) { PIT_TFLG0 = PIT_TFLG_TIF_MASK; n++; }
int main(void) {
    TFC_Init();
    PIT_MCR = 0;
    PIT_LDVAL0 = 240000 - 1;          /* 100 Hz */
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_EnableIRQ(PIT_IRQn);
    double t0 = spinner_now();
    for (int i = 0; i < 20; i++) {    /* no waiting call: the code's time passes in the calls */
        TFC_SetServo(0, 0.0f);
        (void)PIT_CVAL0;
    }
    spinner_add_textf("handlers %u in %.0f ms", n, (spinner_now() - t0) * 1e3);
    return 0;
}
"""


def test_with_mcu_time_a_timer_set_up_counts_from_its_set_up_when_only_counters_are_read(tmp_path):
    """--mcu-time 0.002: the queued calls of twenty TFC_SetServo let time pass (2 ms a call), each
    counter read after one is where it passes; the timer set up before them runs from its set-up
    (the kit's registers are looked at before the time passes), as on the board: its handler once
    every 10 ms of it, not never."""
    src = tmp_path / "setup.c"
    src.write_text(PIT_SET_UP_THEN_READS)
    csv = tmp_path / "log.csv"
    r = drive(build_program([src], kit="tfc"), track="floor", time_limit_s=1.0, csv=csv, mcu_time=0.002)
    assert r.outcome == "controller_returned", r.message
    got = re.search(rb"handlers (\d+) in (\d+) ms", csv.read_bytes())
    assert got and int(got.group(2)) >= 40, got
    assert int(got.group(1)) == int(got.group(2)) // 10, got


TWO_RUNS = """\
#include "spinner.h"
int main(void) {
    double a = spinner_now();
    spinner_sleep(0.1);
    double b = spinner_now();
    spinner_add_textf("now %.3f %.3f", a, b);
    return 0;
}
"""


def test_a_second_run_in_the_process_does_not_read_the_first_runs_time(tmp_path):
    """The in-process host serves run after run (a batch worker's): spinner_now's cached answer
    belongs to its run - the second run's first read is its start, not the first run's end."""
    src = tmp_path / "two.c"
    src.write_text(TWO_RUNS)
    program = build_program([src])
    got = []
    for _ in range(2):
        r = drive(program, track="floor", time_limit_s=1.0, csv=tmp_path / "log.csv")
        assert r.outcome == "controller_returned", r.message
        got.append([s for s in r.log.data_text if s.startswith("now ")])
    assert got == [["now 0.000 0.100"]] * 2, got


# -- a busy wait on the clock (--mcu-time: each read is charged, so the wait ends) ---------------------

NOW_BUSY_WAIT = """\
#include "spinner.h"
int main(void) {
    double t0 = spinner_get_time();
    long reads = 0;
    while (spinner_now() < t0 + 0.005) reads++;   /* a busy wait on the clock */
    spinner_add_textf("from %.4f to %.4f reads %ld", t0, spinner_now_uncharged(), reads);
    return 0;
}
"""

PIT_BUSY_WAIT = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
int main(void) {
    TFC_Init();
    PIT_MCR = 0;
    PIT_LDVAL1 = 0xFFFFFFFFu;                  /* free running, down at the 24 MHz bus clock */
    PIT_TCTRL1 = PIT_TCTRL_TEN_MASK;
    spinner_sleep(0.002);                      /* the look that starts it, then a step */
    double t0 = spinner_now_uncharged();
    uint32_t c0 = PIT_CVAL1;
    long reads = 0;
    while (c0 - PIT_CVAL1 < 120000u) reads++;  /* 5 ms of ticks */
    spinner_add_textf("from %.4f to %.4f reads %ld", t0, spinner_now_uncharged(), reads);
    return 0;
}
"""

GPT_BUSY_WAIT = """\
#include "Gpt.h"
#include "spinner.h"
int main(void) {
    Gpt_Init(&Gpt_Config_VS_0);
    Gpt_StartTimer(1U, 8000000U);              /* 1 s of the 8 MHz clock, continuous */
    double t0 = spinner_now_uncharged();
    uint32 e0 = Gpt_GetTimeElapsed(1U);
    long reads = 0;
    while (Gpt_GetTimeElapsed(1U) - e0 < 40000U) reads++;   /* 5 ms of ticks */
    spinner_add_textf("from %.4f to %.4f reads %ld", t0, spinner_now_uncharged(), reads);
    return 0;
}
"""


def _busy_wait(tmp_path, source: str, kit: str | None = None, isolate: bool = False, **kw):
    """``(run result, (from_s, to_s, reads) or None)`` of a busy-wait program on the floor."""
    src = tmp_path / "wait.c"
    src.write_text(source)
    program = dataclasses.replace(build_program([src], kit=kit), isolate=isolate)
    r = drive(program, track="floor", time_limit_s=1.0, csv=tmp_path / "log.csv", **kw)
    got = re.search(rb"from ([0-9.]+) to ([0-9.]+) reads (\d+)", (tmp_path / "log.csv").read_bytes())
    return r, None if got is None else (float(got.group(1)), float(got.group(2)), int(got.group(3)))


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_with_mcu_time_a_busy_wait_on_spinner_now_ends_at_its_time(tmp_path, isolate):
    """``while (spinner_now() < t0 + 0.005) {}``: each read is charged, so with --mcu-time 0.0001 the
    wait ends at the first 2-ms step at or after t0 + 5 ms, 0.008 s, after some 50 reads (6 ms of
    them less get_time's carried 0.1 ms); measured (--mcu-scale 40) there too, after the CPU its
    reads take. (Before, the read was exempt: no time passed and the watchdog ended the run.)"""
    r, got = _busy_wait(tmp_path, NOW_BUSY_WAIT, isolate=isolate, mcu_time=0.0001)
    assert r.outcome == "controller_returned", r.message
    assert got[:2] == (0.002, 0.008) and 55 <= got[2] <= 60, got
    r, got = _busy_wait(tmp_path, NOW_BUSY_WAIT, isolate=isolate, mcu_time="measured", mcu_scale=40.0)
    assert r.outcome == "controller_returned", r.message
    assert got[0] == 0.002 and 0.007 <= got[1] <= 0.010 and got[2] > 0, got


def test_without_mcu_time_a_busy_wait_on_spinner_now_is_stalled_as_before(tmp_path):
    """Without --mcu-time a read of the time lets none pass: the loop never ends and the watchdog
    stops it at its line (unchanged)."""
    r, got = _busy_wait(tmp_path, NOW_BUSY_WAIT, wall_limit_s=1.0)
    assert r.outcome == "stalled" and "wait.c:5" in r.message, r.message


def test_with_mcu_time_a_busy_wait_on_a_tfc_timer_register_ends_at_its_time(tmp_path):
    """A loop polling PIT_CVAL1 for 5 ms of its ticks: with --mcu-time 0.0001 each use of the running
    PIT is a charged read of the time, so the loop ends 5 ms (a whole step: 6) later, after some 50
    reads; measured, there too. Without --mcu-time the count never moves (a read lets no time pass)
    and the watchdog stops the run, as before."""
    r, got = _busy_wait(tmp_path, PIT_BUSY_WAIT, kit="tfc", mcu_time=0.0001)
    assert r.outcome == "controller_returned", r.message
    assert round(got[1] - got[0], 6) == 0.006 and 45 <= got[2] <= 60, got
    r, got = _busy_wait(tmp_path, PIT_BUSY_WAIT, kit="tfc", mcu_time="measured", mcu_scale=40.0)
    assert r.outcome == "controller_returned", r.message
    assert 0.005 <= got[1] - got[0] <= 0.008, got
    r, _ = _busy_wait(tmp_path, PIT_BUSY_WAIT, kit="tfc", wall_limit_s=1.0)
    assert r.outcome == "stalled", r.message


def test_with_mcu_time_a_busy_wait_on_a_gpt_channel_is_charged_read_by_read(tmp_path):
    """Gpt_GetTimeElapsed polled for 5 ms of ticks: without --mcu-time the kit's poll rule ends it (64
    free reads at one time, then a physics step a read: 65 reads, 6 ms), with --mcu-time 0.0001 the
    reads' own time does, as on the board (each 0.1 ms: some 50 reads). The poll rule is unchanged."""
    r, plain = _busy_wait(tmp_path, GPT_BUSY_WAIT, kit="s32k144")
    assert r.outcome == "controller_returned", r.message
    assert plain == (0.0, 0.006, 65), plain
    r, got = _busy_wait(tmp_path, GPT_BUSY_WAIT, kit="s32k144", mcu_time=0.0001)
    assert r.outcome == "controller_returned", r.message
    assert 0.005 <= got[1] - got[0] <= 0.008 and 45 <= got[2] <= 60, got
