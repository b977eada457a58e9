"""The S32K144 kit's Gpt channels as the RTD's Gpt driver (AUTOSAR SWS General Purpose Timer):
a running channel's elapsed time read live (no time passes in the read), a stopped channel's frozen
at its stop, a one-shot channel (-D GPT_CHANNEL_MODE_<n>=GPT_CH_MODE_ONESHOT) notifying once and
then expired (in its interrupt, notification or not: running while a critical section holds it), a
start of a running channel refused with a warning (GPT_E_BUSY), a start of 0 ticks an error at the
calling line (GPT_E_PARAM_VALUE). kits/s32k144/gpt.c; docs/firmware.md."""
from __future__ import annotations

import dataclasses
import re

import pytest

from simrunner.run.native import build_program
from simrunner.run.runner import drive

GPT_FIRMWARE = r"""
#include <stdio.h>
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 shots;
void Us_Notification(void) { shots++; }
int main(void) {
    Gpt_Init(NULL_PTR);
    Gpt_Init(&Gpt_Config_VS_0);
    if (spinner_param("zero", 0.0) != 0.0) Gpt_StartTimer(2U, 0U);
    Gpt_StartTimer(1U, 8000000U);                 /* 1 s of the 8 MHz clock, continuous */
    uint32 e0 = Gpt_GetTimeElapsed(1U), e1 = Gpt_GetTimeElapsed(1U);
    OsIf_TimeDelay(10U);
    uint32 e2 = Gpt_GetTimeElapsed(1U), r2 = Gpt_GetTimeRemaining(1U);
    Gpt_StartTimer(1U, 8000U);                    /* running: refused, it keeps its 1 s */
    uint32 e3 = Gpt_GetTimeElapsed(1U);
    Gpt_StopTimer(1U);
    OsIf_TimeDelay(10U);
    uint32 s1 = Gpt_GetTimeElapsed(1U), s2 = Gpt_GetTimeRemaining(1U);
    Gpt_EnableNotification(3U);
    Gpt_StartTimer(3U, 8000U);                    /* one-shot, 1 ms */
    OsIf_TimeDelay(20U);
    uint32 n1 = shots, x1 = Gpt_GetTimeElapsed(3U), y1 = Gpt_GetTimeRemaining(3U);
    Gpt_StartTimer(3U, 8000U);                    /* expired: starts again */
    OsIf_TimeDelay(20U);
    spinner_add_textf("live %u %u %u", (unsigned)e0, (unsigned)(e1 - e0), (unsigned)(e2 - e1));
    spinner_add_textf("busy %u %u", (unsigned)(e2 + r2), (unsigned)(e3 - e2));
    spinner_add_textf("stopped %u %u %u", (unsigned)(s1 - e2), (unsigned)(s1 + s2), (unsigned)Gpt_GetTimeElapsed(5U));
    spinner_add_textf("oneshot %u %u %u %u", (unsigned)n1, (unsigned)x1, (unsigned)y1, (unsigned)shots);
    return 0;
}
"""


@pytest.fixture(scope="module")
def gpt_program(tmp_path_factory):
    src = tmp_path_factory.mktemp("gpt") / "gpt_main.c"
    src.write_text(GPT_FIRMWARE)
    return build_program([src], kit="s32k144", defines=["GPT_NOTIFICATION_3=Us_Notification",
                                                         "GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])


def numbers(r):
    lines = [part for s in r.log.data_text if s for part in s.split(" | ")]
    return {s.split()[0]: [int(v) for v in s.split()[1:]] for s in lines}


def test_gpt_channels_count_live_stop_frozen_and_a_one_shot_notifies_once(gpt_program, tmp_path):
    r = drive(gpt_program, track="floor", time_limit_s=1.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    # no time passes in a read; 10 ms are 80000 ticks of 8 MHz
    assert got["live"] == [0, 0, 80000]
    # the refused start keeps the 1-s target and the count; a warning says why
    assert got["busy"] == [8000000, 0]
    assert any(re.match(r"\S*gpt_main\.c:16: Gpt_StartTimer\(1, \.\.\.\) on a running channel was refused", w)
               and "GPT_E_BUSY" in w for w in r.warnings), r.warnings
    # stopped: the elapsed time of the stop, for ever; elapsed + remaining = the target; never started: 0
    assert got["stopped"] == [0, 8000000, 0]
    # one-shot: one notification, then expired (elapsed = target, remaining 0); started again: one more
    assert got["oneshot"] == [1, 8000, 0, 2]


def test_gpt_start_of_zero_ticks_ends_the_run_at_its_line(gpt_program):
    r = drive(gpt_program, track="floor", time_limit_s=1.0, params={"zero": 1})
    assert r.outcome == "controller_error"
    assert "gpt_main.c:11" in r.message and "GPT_E_PARAM_VALUE" in r.message, r.message
    assert "\n" not in r.message


HELD_ONE_SHOT = r"""
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 shots;
void Us_Notification(void) { shots++; }
int main(void) {
    Gpt_Init(NULL_PTR);
    Gpt_EnableNotification(3U);
    Gpt_StartTimer(3U, 8000U);                    /* one-shot, 1 ms */
    OsIf_SuspendAllInterrupts();
    OsIf_TimeDelay(5U);                           /* it expires here: its interrupt is held */
    uint32 x = Gpt_GetTimeElapsed(3U), y = Gpt_GetTimeRemaining(3U);
    START;                                        /* the driver still has it running */
    uint32 held = shots;
    OsIf_ResumeAllInterrupts();                   /* the interrupt: the notification, then expired */
    uint32 resumed = shots;
    Gpt_StartTimer(3U, 8000U);
    OsIf_TimeDelay(5U);
    spinner_add_textf("held %u %u %u %u %u", (unsigned)x, (unsigned)y, (unsigned)held, (unsigned)resumed,
                      (unsigned)shots);
    return 0;
}
"""


@pytest.mark.parametrize("start, warned", [
    ("(void)0", False),
    ("Gpt_StartTimer(3U, 8000U)", True),                      # refused inside: still running
    ("Gpt_StopTimer(3U); Gpt_StartTimer(3U, 8000U)", True),   # restarted inside: the start after the resume is refused
])
def test_a_one_shot_whose_expiry_a_critical_section_holds_is_running_until_its_interrupt(tmp_path, start, warned):
    """The RTD's one-shot channel turns expired in its interrupt (Gpt_ProcessCommonInterrupt; S32K1
    RTD 2.0.0 Gpt.c), which a critical section holds: until then Gpt_StartTimer is refused
    (GPT_E_BUSY, Gpt_ValidateChannelStatus) and the reads give the target elapsed, 0 remaining; at
    the resume the notification runs; a stop inside drops it (the LPIT's flag cleared,
    Lpit_Gpt_Ip_StopTimer)."""
    src = tmp_path / "held.c"
    src.write_text(HELD_ONE_SHOT.replace("START;", start + ";"))
    program = build_program([src], kit="s32k144", defines=["GPT_NOTIFICATION_3=Us_Notification",
                                                          "GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])
    r = drive(program, track="floor", time_limit_s=1.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    x, y, held, resumed, shots = numbers(r)["held"]
    assert (x, y, held) == (8000, 0, 0)
    if "Stop" in start:  # stopped inside: no notification; the restart inside notifies once
        assert (resumed, shots) == (0, 1)
    else:  # the held one at the resume, then the restart's
        assert (resumed, shots) == (1, 2)
    assert any("GPT_E_BUSY" in w for w in r.warnings) == warned, r.warnings


def test_a_one_shot_that_expired_before_a_critical_section_is_expired_in_it(tmp_path):
    """Its interrupt ran at its expiry (interrupts enabled then), with a notification or not: a start
    inside a later critical section or handler is a new start, not refused."""
    src = tmp_path / "before.c"
    before = (HELD_ONE_SHOT.replace("OsIf_SuspendAllInterrupts();\n    OsIf_TimeDelay(5U);",
                                    "OsIf_TimeDelay(5U);\n    OsIf_SuspendAllInterrupts();")
              .replace("START;", "Gpt_StartTimer(3U, 8000U);"))
    assert "OsIf_TimeDelay(5U);\n    OsIf_SuspendAllInterrupts();" in before
    for defines in (["GPT_NOTIFICATION_3=Us_Notification"], []):
        src.write_text(before if defines else before.replace("Gpt_EnableNotification(3U);", ""))
        program = build_program([src], kit="s32k144", defines=defines + ["GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])
        r = drive(program, track="floor", time_limit_s=1.0, csv=tmp_path / "log.csv")
        assert r.outcome == "controller_returned", r.message
        x, y, held, resumed, shots = numbers(r)["held"]
        notified = 1 if defines else 0
        # expired at 1 ms; restarted inside the section (not refused); its second expiry at 6 ms,
        # after the resume; the start after the resume is refused (it runs until 6 ms)
        assert (x, y, held, resumed) == (8000, 0, notified, notified)
        assert shots == 2 * notified
        assert sum("GPT_E_BUSY" in w for w in r.warnings) == 1, r.warnings



QUIET_ONE_SHOT = r"""
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 shots;
void Us_Notification(void) { shots++; }
int main(void) {
    Gpt_Init(NULL_PTR);
    BEFORE;
    Gpt_StartTimer(3U, 8000U);                    /* one-shot, 1 ms */
    AFTER;
    MASK;
    OsIf_TimeDelay(5U);                           /* it expires here */
    uint32 x = Gpt_GetTimeElapsed(3U), y = Gpt_GetTimeRemaining(3U);
    Gpt_StartTimer(3U, 8000U);
    uint32 x2 = Gpt_GetTimeElapsed(3U);
    uint32 held = shots;
    UNMASK;
    uint32 x3 = Gpt_GetTimeElapsed(3U), y3 = Gpt_GetTimeRemaining(3U);
    Gpt_StartTimer(3U, 16000U);                   /* accepted once expired */
    uint32 r = Gpt_GetTimeRemaining(3U);
    OsIf_TimeDelay(5U);
    spinner_add_textf("quiet %u %u %u %u %u %u %u %u", (unsigned)x, (unsigned)y, (unsigned)x2, (unsigned)held,
                      (unsigned)x3, (unsigned)y3, (unsigned)r, (unsigned)shots);
    return 0;
}
"""

# the notification: none configured; configured, never enabled; enabled, then disabled while running
QUIET = [([], "(void)0", "(void)0"),
         (["GPT_NOTIFICATION_3=Us_Notification"], "(void)0", "(void)0"),
         (["GPT_NOTIFICATION_3=Us_Notification"], "Gpt_EnableNotification(3U)", "Gpt_DisableNotification(3U)")]


def quiet_one_shot(tmp_path, defines, before, after, masked):
    src = tmp_path / "quiet.c"
    text = QUIET_ONE_SHOT.replace("BEFORE;", before + ";").replace("AFTER;", after + ";")
    mask, unmask = ("OsIf_SuspendAllInterrupts()", "OsIf_ResumeAllInterrupts()") if masked else ("(void)0", "(void)0")
    src.write_text(text.replace("MASK;", mask + ";", 1).replace("UNMASK;", unmask + ";"))
    return build_program([src], kit="s32k144", defines=defines + ["GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])


@pytest.mark.parametrize("defines, before, after", QUIET)
def test_a_one_shot_without_notification_whose_expiry_a_critical_section_holds_is_running_until_its_interrupt(
        tmp_path, defines, before, after):
    """The RTD's one-shot channel turns expired in its interrupt whether or not its notification
    is enabled (S32K1 RTD 2.0.0 Gpt.c: Gpt_StartTimer enables a one-shot channel's interrupt,
    Gpt_ProcessCommonInterrupt sets GPT_STATUS_EXPIRED and notifies only if enabled): inside the
    section it reads its target elapsed and 0 remaining, Gpt_StartTimer is refused (GPT_E_BUSY);
    the unmask runs the interrupt, no notification called: expired, a start is accepted. Alike in
    process and isolated."""
    program = quiet_one_shot(tmp_path, defines, before, after, masked=True)
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  csv=tmp_path / f"log{isolate}.csv")
        assert r.outcome == "controller_returned", (isolate, r.message)
        x, y, x2, held, x3, y3, remaining, shots = numbers(r)["quiet"]
        assert (x, y, x2, held) == (8000, 0, 8000, 0), isolate  # running: the start inside refused
        assert (x3, y3, remaining, shots) == (8000, 0, 16000, 0), isolate  # expired at the unmask
        busy = [w for w in r.warnings if "GPT_E_BUSY" in w]
        assert len(busy) == 1 and "until its interrupt has run" in busy[0], (isolate, r.warnings)


@pytest.mark.parametrize("defines, before, after", QUIET)
def test_a_one_shot_without_notification_expires_at_its_expiry_when_not_held(tmp_path, defines, before, after):
    """No critical section: expired from its expiry on (the target elapsed, 0 remaining), a start
    accepted, no warning, no notification. Alike in process and isolated."""
    program = quiet_one_shot(tmp_path, defines, before, after, masked=False)
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  csv=tmp_path / f"log{isolate}.csv")
        assert r.outcome == "controller_returned", (isolate, r.message)
        x, y, x2, held, x3, y3, remaining, shots = numbers(r)["quiet"]
        # expired at 1 ms; started again at 5 ms (accepted), running at 6 ms: the later start refused
        assert (x, y, x2, held) == (8000, 0, 0, 0), isolate
        assert (x3, y3, remaining, shots) == (0, 8000, 8000, 0), isolate
        busy = [w for w in r.warnings if "GPT_E_BUSY" in w]
        assert len(busy) == 1 and "until its interrupt" not in busy[0], (isolate, r.warnings)


ENABLED_LATE = r"""
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 shots;
static volatile double at_s;
void Us_Notification(void) { shots++; at_s = spinner_now(); }
int main(void) {
    Gpt_Init(NULL_PTR);
    Gpt_StartTimer(3U, 80000U);                   /* one-shot, 10 ms */
    OsIf_TimeDelay(4U);
    Gpt_EnableNotification(3U);                   /* its interrupt at 10 ms notifies */
    OsIf_TimeDelay(20U);
    spinner_add_textf("late %u %u", (unsigned)shots, (unsigned)(at_s * 1000.0 + 0.5));
    return 0;
}
"""


def test_a_one_shot_notification_enabled_while_it_runs_is_called_at_its_expiry(tmp_path):
    """The one-shot's interrupt is timed from its start: a notification enabled later is called
    at its expiry (the RTD's interrupt tests the notification's flag then), once."""
    src = tmp_path / "late.c"
    src.write_text(ENABLED_LATE)
    program = build_program([src], kit="s32k144", defines=["GPT_NOTIFICATION_3=Us_Notification",
                                                          "GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  csv=tmp_path / f"log{isolate}.csv")
        assert r.outcome == "controller_returned", (isolate, r.message)
        assert numbers(r)["late"] == [1, 10], isolate


DEINIT_DUE = r"""
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 shots;
void Us_Notification(void) { shots++; }
int main(void) {
    Gpt_Init(NULL_PTR);
    ENABLE;
    Gpt_StartTimer(3U, 8000U);                    /* one-shot, 1 ms */
    for (int k = 0; k < 6; k++) spinner_add_textf("q%d", k);  /* --mcu-time 0.0005: 3 ms of code */
    Gpt_DeInit();                                 /* after its expiry (with --mcu-time) */
    OsIf_TimeDelay(5U);
    spinner_add_textf("deinit %u %u %u", (unsigned)Gpt_GetTimeElapsed(3U), (unsigned)Gpt_GetTimeRemaining(3U),
                      (unsigned)shots);
    Gpt_EnableNotification(5U);                   /* none configured, nothing else runs: an error */
    OsIf_TimeDelay(5U);
    return 0;
}
"""


@pytest.mark.parametrize("enable", ["(void)0", "Gpt_EnableNotification(3U)"])
@pytest.mark.parametrize("mcu_time", [None, 0.0005])
def test_gpt_deinit_after_a_one_shots_expiry_in_code_time_leaves_it_initialized(tmp_path, enable, mcu_time):
    """Gpt_DeInit resets every channel to its initialized state (never started: 0 elapsed, 0
    remaining). With --mcu-time the code before it may take a one-shot past its expiry: its
    interrupt, due then, runs before the DeInit (the notification, if enabled, once), not after it -
    an interrupt run after would make the channel expired again and count the kit's timers wrong
    (g.own: then enabling a notification none configures was accepted). Alike in process and
    isolated."""
    src = tmp_path / "deinit.c"
    src.write_text(DEINIT_DUE.replace("ENABLE;", enable + ";"))
    program = build_program([src], kit="s32k144", defines=["GPT_NOTIFICATION_3=Us_Notification",
                                                          "GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])
    extra = {} if mcu_time is None else {"mcu_time": mcu_time}
    notified = 1 if mcu_time is not None and "Enable" in enable else 0
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  csv=tmp_path / f"log{isolate}.csv", **extra)
        assert numbers(r)["deinit"] == [0, 0, notified], isolate
        assert r.outcome == "controller_error" and "channel 5 has no notification" in r.message, (isolate, r.message)


CODE_TIME = r"""
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 shots;
void Us_Notification(void) { shots++; }
int main(void) {
    Gpt_Init(NULL_PTR);
    ENABLE;
    OsIf_TimeDelay(4U);
    Gpt_StartTimer(3U, 32000U);                   /* one-shot, 4 ms */
    for (int k = 0; k < NQ; k++) spinner_add_textf("q%d", k);  /* --mcu-time: the code's time */
    uint32 mismatched = 0, expired_at = 0;
    for (int k = 1; k <= 5; k++) {                /* interrupts enabled: expired once its interrupt ran */
        uint32 e = Gpt_GetTimeElapsed(3U);
        if (NOTIFIED && (e == 32000U) != (shots == 1)) mismatched++;
        if (e == 32000U && !expired_at) expired_at = k;
        OsIf_TimeDelay(1U);
    }
    Gpt_StartTimer(3U, 32000U);                   /* one-shot, 4 ms */
    for (int k = 0; k < NQ; k++) spinner_add_textf("r%d", k);
    OsIf_SuspendAllInterrupts();                  /* (--mcu-time: the code's time passes before it) */
    uint32 x = Gpt_GetTimeElapsed(3U);
    Gpt_StartTimer(3U, 32000U);                   /* no time passed in the section: nothing held */
    OsIf_ResumeAllInterrupts();
    spinner_add_textf("code %u %u %u", (unsigned)mismatched, (unsigned)expired_at, (unsigned)x);
    OsIf_TimeDelay(20U);
    return 0;
}
"""


@pytest.mark.parametrize("enable", ["(void)0", "Gpt_EnableNotification(3U)"])
@pytest.mark.parametrize("nq", [2, 3])
def test_with_mcu_time_a_one_shot_expires_in_its_interrupt_when_its_count_reaches_the_target(tmp_path, enable, nq):
    """--mcu-time 0.0007 charges the kit's own requests too (the timer's spinner_every): the channel
    counts from the time its interrupt is timed from, so a read that finds it expired (interrupts
    enabled) finds its interrupt run - the notification called - and a one-shot whose count
    expired before a critical section is not held in it (no GPT_E_BUSY "until its interrupt has
    run": three queued calls before it). Before, the count ran from before that charge: expired a
    physics step before its interrupt. Alike in process and isolated. With two queued calls the
    count reaches the target inside the section, where the read and the start are charged (a read
    of the time is a charged call): its interrupt is held there, and the start is refused as the
    RTD refuses it, saying so."""
    src = tmp_path / "code_time.c"
    notified = 1 if "Enable" in enable else 0
    src.write_text(CODE_TIME.replace("ENABLE;", enable + ";").replace("NQ", str(nq))
                   .replace("NOTIFIED", str(notified)))
    program = build_program([src], kit="s32k144", defines=["GPT_NOTIFICATION_3=Us_Notification",
                                                          "GPT_CHANNEL_MODE_3=GPT_CH_MODE_ONESHOT"])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0,
                  csv=tmp_path / f"log{isolate}.csv", mcu_time=0.0007)
        assert r.outcome == "controller_returned", (isolate, r.message)
        mismatched, expired_at, _ = numbers(r)["code"]
        assert mismatched == 0 and expired_at > 0, (isolate, numbers(r))
        held = any("until its interrupt has run" in w for w in r.warnings)
        assert held == (nq == 2), (isolate, r.warnings)
