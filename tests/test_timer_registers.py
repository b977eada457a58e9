"""A timer interrupt's handler and rate taken from the firmware's own timer set-up: the KL25Z's
PIT, LPTMR and TPM2 registers with --kit tfc (kits/tfc/timers.c), the S32K144 kit's Gpt channels
(kits/s32k144/gpt.c); and stopping a timer interrupt (``spinner_stop_every``, the clock's
``remove_interrupt``). docs/firmware.md, "Timer interrupts"."""
from __future__ import annotations

import dataclasses
import re
import textwrap

import pytest

from simrunner.run.native import build_program
from simrunner.run.native.build import with_isrs
from simrunner.run.runner import drive

TFC_FIRMWARE = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
static double t_setup, first, last;
void {handler}(void) {{
    if (!({flag})) return;
    {clear};
    if (++n == 1) first = spinner_get_time();
    if (n == {count}) last = spinner_get_time();
}}
int main(void) {{
    TFC_Init();
    t_setup = spinner_get_time();
    {setup}
    while (n < {count} && spinner_get_time() < 4.0) __WFI();
    printf("ticks %u setup %.6f first %.6f last %.6f\\n", n, t_setup, first, last);
    return 0;
}}
"""
PIT0 = dict(handler="PIT_IRQHandler", flag="PIT_TFLG0 & PIT_TFLG_TIF_MASK", clear="PIT_TFLG0 = PIT_TFLG_TIF_MASK")
PIT1 = dict(handler="PIT_IRQHandler", flag="PIT->CHANNEL[1].TFLG & PIT_TFLG_TIF_MASK",
            clear="PIT->CHANNEL[1].TFLG = PIT_TFLG_TIF_MASK")
LPTIMER = dict(handler="LPTimer_IRQHandler", flag="LPTMR0_CSR & LPTMR_CSR_TCF_MASK",
               clear="LPTMR0_CSR |= LPTMR_CSR_TCF_MASK")
LPTMR0 = dict(LPTIMER, handler="LPTMR0_IRQHandler")  # the Kinetis SDK's name of the vector
TPM2 = dict(handler="TPM2_IRQHandler", flag="TPM2_SC & TPM_SC_TOF_MASK", clear="TPM2_SC |= TPM_SC_TOF_MASK")
# the overflow flag read and cleared in the STATUS register, which mirrors SC TOF (RM 31.3.5)
TPM2_STATUS = dict(handler="TPM2_IRQHandler", flag="TPM2_STATUS & TPM_STATUS_TOF_MASK",
                   clear="TPM2_STATUS = TPM_STATUS_TOF_MASK")
PIT_100HZ = """SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
    PIT_MCR = 0;
    PIT->CHANNEL[0].LDVAL = 240000 - 1;              /* 100 Hz of the 24 MHz bus clock */
    PIT->CHANNEL[0].TCTRL = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_EnableIRQ(PIT_IRQn);"""
LPTMR_SETUP = """SIM_SCGC5 |= SIM_SCGC5_LPTMR_MASK;
    LPTMR0_CSR = 0;
    {extra}
    LPTMR0_PSR = {psr};
    LPTMR0_CMR = {cmr};
    LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK;
    enable_irq(INT_LPTimer - 16);"""
TPM2_SETUP = """SIM_SCGC6 |= SIM_SCGC6_TPM2_MASK;
    {extra}
    TPM2_SC = 0;
    TPM2_MOD = {mod};
    TPM2->SC = TPM_SC_PS({ps}) | TPM_SC_TOIE_MASK | TPM_SC_CMOD(1){cpwms};
    NVIC_ICPR = 1u << (INT_TPM2 - 16);
    NVIC_ISER = 1u << (INT_TPM2 - 16);"""

# (registers, what sets them, expected period s)
SETUPS = {
    "pit0": (PIT0, PIT_100HZ, 0.01),
    "pit1": (PIT1, """PIT_MCR &= ~PIT_MCR_MDIS_MASK;
    PIT_LDVAL1 = 480000 - 1;                          /* 50 Hz */
    PIT_TCTRL1 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_ISER |= 1u << (INT_PIT - 16);""", 0.02),
    # the LPO (1 kHz) bypassing the prescaler: CMR + 1 = 10 counts
    "lptmr_lpo": (LPTIMER, LPTMR_SETUP.format(extra="", psr="LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK",
                                              cmr="LPTMR_CMR_COMPARE(10 - 1)"), 0.01),
    # the LPO / 4 (PRESCALE 1: 2^2), 25 counts
    "lptmr_lpo_prescaled": (LPTMR0, LPTMR_SETUP.format(extra="", psr="LPTMR_PSR_PCS(1) | LPTMR_PSR_PRESCALE(1)",
                                                       cmr="24"), 0.1),
    # MCGIRCLK: the fast IRC (4 MHz) / 2^FCRDIV 2 = 1 MHz, / 16 (PRESCALE 3): 625 counts
    "lptmr_fast_irc": (LPTIMER, LPTMR_SETUP.format(
        extra="MCG_C1 |= MCG_C1_IRCLKEN_MASK; MCG_C2 |= MCG_C2_IRCS_MASK; MCG_SC = MCG_SC_FCRDIV(2);",
        psr="LPTMR_PSR_PCS(0) | LPTMR_PSR_PRESCALE(3)", cmr="624"), 0.01),
    # ERCLK32K from the LPO (SIM_SOPT1 OSC32KSEL 3), 20 counts
    "lptmr_erclk32k": (LPTIMER, LPTMR_SETUP.format(extra="SIM_SOPT1 |= SIM_SOPT1_OSC32KSEL(3);",
                                                   psr="LPTMR_PSR_PCS(2) | LPTMR_PSR_PBYP_MASK", cmr="19"), 0.02),
    # OSCERCLK (the 8 MHz crystal) / 256: 313 counts of 32 us
    "lptmr_oscerclk": (LPTIMER, LPTMR_SETUP.format(extra="", psr="LPTMR_PSR_PCS(3) | LPTMR_PSR_PRESCALE(7)",
                                                   cmr="312"), 313 * 256 / 8e6),
    # MCGPLLCLK/2 = 24 MHz (TFC_Init's choice) / 128: MOD + 1 = 1875 counts
    "tpm2": (TPM2, TPM2_SETUP.format(extra="", mod="1875 - 1", ps=7, cpwms=""), 0.01),
    # the flag in STATUS; the set-up as MKL25Z4.h's users write it: CONF DBGMODE, a CNT write, a priority
    "tpm2_status": (TPM2_STATUS, TPM2_SETUP.format(
        extra="TPM2_CONF |= TPM_CONF_DBGMODE(3); TPM2_CNT = TPM_CNT_COUNT(0); NVIC_IPR4 = 0;",
        mod="1875 - 1", ps=7, cpwms=""), 0.01),
    # up-down counting: 2 x MOD
    "tpm2_updown": (TPM2, TPM2_SETUP.format(extra="", mod="1875", ps=7, cpwms=" | TPM_SC_CPWMS_MASK"), 0.02),
    # OSCERCLK: 8 MHz / 8, 10000 counts
    "tpm2_oscerclk": (TPM2, TPM2_SETUP.format(
        extra="SIM_SOPT2 = (SIM_SOPT2 & ~SIM_SOPT2_TPMSRC_MASK) | SIM_SOPT2_TPMSRC(2);",
        mod="10000 - 1", ps=3, cpwms=""), 0.01),
}


def _firmware(tmp_path, name, regs, setup, count=20, **more):
    src = tmp_path / f"{name}.c"
    src.write_text(TFC_FIRMWARE.format(setup=setup, count=count, **{**regs, **more}))
    return build_program([src], kit="tfc")


def _ticks(capfd):
    out = capfd.readouterr().out
    m = re.search(r"ticks (\d+) setup ([\d.]+) first ([\d.]+) last ([\d.]+)", out)
    assert m, out
    return int(m[1]), float(m[2]), float(m[3]), float(m[4])


@pytest.mark.parametrize("name", list(SETUPS))
def test_a_timer_set_up_calls_its_handler_at_its_registers_rate(tmp_path, capfd, name):
    """Without --isr: the handler of the timer's vector runs every period its registers and clock
    give, from the set-up on (to the 2-ms physics step), with its flag set."""
    regs, setup, period_s = SETUPS[name]
    r = drive(_firmware(tmp_path, name, regs, setup), track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_returned", r.message
    n, t_setup, first, last = _ticks(capfd)
    assert n >= 20  # (the last __WFI() may wait out a camera frame)
    assert first - t_setup == pytest.approx(FIRST_S.get(name, period_s), abs=0.002)
    assert last - first == pytest.approx(19 * period_s, abs=0.002)


def test_tfc_init_leaves_the_pit_enabled_and_its_irq_on_as_the_library_does(tmp_path, capfd):
    """The library's TFC_Init (TFC_InitADCs: the camera's PIT channel 0) clears PIT_MCR MDIS, sets FRZ
    and enables the PIT's IRQ (enable_irq(INT_PIT-16)), so a team's channel 1 set up after it with
    LDVAL1 and TCTRL1 alone interrupts on the board: 100 calls in 1 s here, on both hosts, and no
    warning (was: the run ended "the PIT is disabled (PIT_MCR MDIS ...)" once the IRQ was enabled,
    and without the enable the handler was never called and the run warned that the board would not
    call it either)."""
    src = tmp_path / "pit1.c"
    src.write_text(TFC_FIRMWARE.format(setup=textwrap.dedent("""\
        PIT_LDVAL1 = PERIPHERAL_BUS_CLOCK / 100 - 1;      /* PIT_MCR and the NVIC: the library's */
            PIT_TCTRL1 = PIT_TCTRL_TEN_MASK | PIT_TCTRL_TIE_MASK;
            if ((PIT_MCR & PIT_MCR_MDIS_MASK) || !(PIT_MCR & PIT_MCR_FRZ_MASK)) return 1;"""),
        count=100, **PIT1))
    program = build_program([src], kit="tfc")
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=3.0)
        assert r.outcome == "controller_returned" and r.message == "main() returned", r.message
        n, t_setup, first, last = _ticks(capfd)
        assert n == 100 and last - first == pytest.approx(0.99, abs=0.002)
        assert not [w for w in r.warnings if "NVIC" in w], r.warnings


# the first period where it is not the period: up-down counting's first TOF as the count first turns at
# MOD, MOD + 1 counts in (RM 31.4.3.2)
FIRST_S = {"tpm2_updown": 1876 / 187500}


def test_a_pit_at_100_hz_calls_its_handler_100_times_a_second(tmp_path, capfd):
    """The issue's case: PIT channel 0 at 100 Hz, no --isr: 100 calls in 1 s, 10 ms apart from the
    set-up on, in the simulator's process and in a child process alike."""
    program = _firmware(tmp_path, "pit", PIT0, PIT_100HZ, count=100)
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=3.0)
        assert r.outcome == "controller_returned", r.message
        n, t_setup, first, last = _ticks(capfd)
        assert n >= 100 and (first - t_setup, last - t_setup) == (pytest.approx(0.01), pytest.approx(1.0))


STOPPING = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
void PIT_IRQHandler(void) {{ PIT_TFLG0 = PIT_TFLG_TIF_MASK; n++; }}
int main(void) {{
    TFC_Init();
    {setup}
    while (n < 10) spinner_sleep(0.001);
    {stop}
    unsigned at_stop = n;
    spinner_sleep(0.2);
    unsigned after = n;
    {restart}
    spinner_sleep(0.1);
    printf("at_stop %u after %u restarted %u\\n", at_stop, after, n);
    return 0;
}}
"""


@pytest.mark.parametrize("stop, restart, restarted", [
    ("PIT_TCTRL0 &= ~PIT_TCTRL_TEN_MASK;", "PIT_TCTRL0 |= PIT_TCTRL_TEN_MASK;", 20),
    ("PIT->CHANNEL[0].TCTRL &= ~PIT_TCTRL_TIE_MASK;", "PIT->CHANNEL[0].TCTRL |= PIT_TCTRL_TIE_MASK;", 20),
    # the IRQ disabled in the NVIC: the PIT counts on, its expiries set the IRQ's pending bit, taken once
    # at the enable (ARMv6-M B3.4; before the NVIC's pending bits were emulated: 20, the expiries dropped)
    ("NVIC_DisableIRQ(PIT_IRQn);", "NVIC_EnableIRQ(PIT_IRQn);", 21),
    ("NVIC_ICER = 1u << (INT_PIT - 16);", "NVIC_ISER = 1u << (INT_PIT - 16);", 21),
])
def test_stopping_a_timer_stops_its_handler(tmp_path, capfd, stop, restart, restarted):
    """Clearing TEN or TIE, or disabling the IRQ (CMSIS or the raw NVIC write): no call in the
    0.2 s after it; undone, the calls go on (10 in the next 0.1 s, and with the IRQ the pending one)."""
    src = tmp_path / "stop.c"
    src.write_text(STOPPING.format(setup=PIT_100HZ, stop=stop, restart=restart))
    r = drive(build_program([src], kit="tfc"), track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    out = capfd.readouterr().out
    at_stop, after, n = map(int, re.search(r"at_stop (\d+) after (\d+) restarted (\d+)", out).groups())
    assert (at_stop, after, n) == (10, 10, restarted), out


def test_a_new_load_value_takes_effect_at_the_next_expiry(tmp_path, capfd):
    """A handler that writes a new LDVAL (100 Hz -> 50 Hz) at its 10th call: the PIT loads it
    when the period running then expires (KL25 RM 32.3.4), so the 11th call is 10 ms after the
    10th and the ones after 20 ms apart."""
    src = tmp_path / "reload.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "spinner.h"
        #include "TFC\\\\TFC.h"
        static volatile unsigned n;
        static double at[16];
        void PIT_IRQHandler(void) {
            PIT_TFLG0 = PIT_TFLG_TIF_MASK;
            at[n++] = spinner_get_time();
            if (n == 10) PIT_LDVAL0 = 480000 - 1;
        }
        int main(void) {
            TFC_Init();
            %s
            while (n < 14) __WFI();
            for (int i = 1; i < 14; i++) printf("%%.4f ", at[i] - at[i - 1]);
            printf("\\n");
            return 0;
        }
        """) % PIT_100HZ)
    r = drive(build_program([src], kit="tfc"), track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    gaps = [float(x) for x in capfd.readouterr().out.split()]
    assert gaps == [0.01] * 10 + [0.02] * 3


def test_isr_overrides_the_registers_rate(tmp_path, capfd):
    """--isr PIT_IRQHandler@20 with the PIT set up for 100 Hz: --isr's rate, from the start (the
    kit sets no flag then: the handler here does not test it)."""
    program = _firmware(tmp_path, "isr", dict(PIT0, flag="1"), PIT_100HZ, count=10)
    r = drive(with_isrs(program, [("PIT_IRQHandler", 0.05)]), track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    n, _, first, last = _ticks(capfd)
    assert n >= 10 and (first, last) == (pytest.approx(0.05), pytest.approx(0.5))


@pytest.mark.parametrize("setup", [
    "PIT_MCR = 0; PIT_LDVAL0 = 240000 - 1; PIT_TCTRL0 = PIT_TCTRL_TIE_MASK;",    # never enabled
    "PIT_MCR = 0; PIT_LDVAL0 = 240000 - 1; PIT_TCTRL0 = PIT_TCTRL_TEN_MASK;",    # no interrupt
    "NVIC_DisableIRQ(PIT_IRQn); PIT_MCR = 0; PIT_LDVAL0 = 240000 - 1; "
    "PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;",  # no NVIC (TFC_Init enabled it, as the library)
    "",                                                                         # no set-up at all
])
def test_a_handler_whose_timer_never_runs_is_never_called(tmp_path, capfd, setup):
    r = drive(_firmware(tmp_path, "never", PIT0, setup, count=1), track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_returned", r.message
    assert _ticks(capfd)[0] == 0


@pytest.mark.parametrize("setup, why", [
    ("PIT_MCR = 0; PIT_TCTRL1 = PIT_TCTRL_CHN_MASK | PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK; "
     "NVIC_EnableIRQ(PIT_IRQn);", "PIT channel 1: its interrupt is set up but chained PIT timers"),
    ("PIT_MCR = PIT_MCR_MDIS_MASK; PIT_LDVAL0 = 1000; PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK; "
     "NVIC_EnableIRQ(PIT_IRQn);", "the PIT is disabled (PIT_MCR MDIS"),
    ("LPTMR0_PSR = LPTMR_PSR_PCS(0); LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK; "
     "NVIC_EnableIRQ(LPTimer_IRQn);", "its clock MCGIRCLK is off"),
    ("LPTMR0_PSR = LPTMR_PSR_PCS(2); LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK; "
     "NVIC_EnableIRQ(LPTimer_IRQn);", "its clock ERCLK32K is not the LPO"),
    ("TPM2_SC = TPM_SC_TOIE_MASK | TPM_SC_CMOD(2); NVIC_EnableIRQ(TPM2_IRQn);", "external clock pin"),
    ("TPM2_C0SC = TPM_CnSC_CHIE_MASK; TPM2_SC = TPM_SC_CMOD(1); NVIC_EnableIRQ(TPM2_IRQn);",
     "a channel interrupt (CnSC CHIE)"),
])
def test_a_set_up_the_kit_cannot_time_ends_the_run_saying_why(tmp_path, setup, why):
    """One line naming the timer and why, at the firmware's next call (line 16: the loop)."""
    r = drive(_firmware(tmp_path, "bad", dict(LPTIMER, handler="PIT_IRQHandler"), setup), track="floor",
              time_limit_s=2.0)
    assert r.outcome == "controller_error" and why in r.message and "bad.c:16" in r.message, r.message
    assert "\n" not in r.message.split("bad.c:16")[0]


def test_a_timer_without_its_handler_ends_the_run_naming_the_vector(tmp_path):
    r = drive(_firmware(tmp_path, "nohandler", dict(PIT0, handler="Other_IRQHandler"), PIT_100HZ),
              track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error" and "defines no PIT_IRQHandler" in r.message, r.message
    assert "misspelt" not in r.message  # (Other_IRQHandler is not near it)
    r = drive(_firmware(tmp_path, "typo", dict(PIT0, handler="PIT_IRQHandlr"), PIT_100HZ),
              track="floor", time_limit_s=2.0)  # a typo: the name it defines is said
    assert "defines no PIT_IRQHandler (it defines PIT_IRQHandlr: misspelt?)" in r.message, r.message


def test_firmware_without_timers_reads_and_writes_no_interrupt(tmp_path):
    """The kit's look at the registers before each wait sets up nothing for a firmware that
    writes none: no handler is counted (its exit status)."""
    src = tmp_path / "plain.c"
    src.write_text(textwrap.dedent("""\
        #include "derivative.h"
        #include "spinner.h"
        #include "TFC\\\\TFC.h"
        int main(void) {
            TFC_Init();
            for (int i = 0; i < 50; i++) TFC_Task();
            return spinner_interrupts();
        }
        """))
    r = drive(build_program([src], kit="tfc"), track="floor", time_limit_s=10.0)
    assert r.outcome == "controller_returned", r.message


# -- the S32K144 kit's Gpt -----------------------------------------------------------------------

S32K_GPT = """\
#include <stdio.h>
#include "Gpt.h"
#include "OsIf.h"
#include "spinner.h"
static volatile uint32 ticks;
static double first, last;
void {name}(void) {{ if (++ticks == 1) first = spinner_get_time(); last = spinner_get_time(); }}
int main(void) {{
    Gpt_StartTimer({channel}U, 8000U);          /* 1 ms at the kit's 8 MHz Gpt clock */
    Gpt_EnableNotification({channel}U);
    double t0 = spinner_get_time();
    while (ticks < 200U) OsIf_TimeDelay(1U);
    {stop};
    uint32 at_stop = ticks;
    OsIf_TimeDelay(100U);
    printf("ticks %u first %.6f last %.6f after %u\\n", at_stop, first - t0, last - first, ticks - at_stop);
    return 0;
}}
"""


@pytest.mark.parametrize("name, channel, defines, stop", [
    ("Gpt_Notification", 0, [], "Gpt_StopTimer(0U)"),                       # the sample's configuration
    ("EmuTimer_Notification", 2, ["GPT_NOTIFICATION_2=EmuTimer_Notification"], "Gpt_DisableNotification(2U)"),
])
def test_an_s32k144_gpt_notification_runs_at_its_channels_rate(tmp_path, capfd, name, channel, defines, stop):
    """Gpt_StartTimer(ch, 8000) + Gpt_EnableNotification(ch) without --isr: the channel's
    notification (the kit's configuration, or -D GPT_NOTIFICATION_<n>=NAME) every 8000 ticks of
    the 8 MHz Gpt clock; stopping the timer or the notification stops it."""
    src = tmp_path / "gpt.c"
    src.write_text(S32K_GPT.format(name=name, channel=channel, stop=stop))
    r = drive(build_program([src], kit="s32k144", defines=defines), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    m = re.search(r"ticks (\d+) first ([\d.]+) last ([\d.]+) after (\d+)", capfd.readouterr().out)
    assert int(m[1]) in (200, 201) and int(m[4]) == 0
    assert float(m[2]) == pytest.approx(0.0, abs=0.002)  # (1 kHz: two calls a 2-ms step)
    assert float(m[3]) == pytest.approx(0.001 * (int(m[1]) - 1), abs=0.002)


def test_an_s32k144_notification_given_with_isr_keeps_isrs_rate(tmp_path, capfd):
    """--isr Gpt_Notification@500 with the channel set up for 1 kHz: --isr's rate from the start
    (200 calls at 0.4 s), and Gpt_StopTimer does not stop it (50 more in the next 0.1 s)."""
    src = tmp_path / "gpt.c"
    src.write_text(S32K_GPT.format(name="Gpt_Notification", channel=0, stop="Gpt_StopTimer(0U)"))
    program = build_program([src], kit="s32k144")
    r = drive(with_isrs(program, [("Gpt_Notification", 0.002)]), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    m = re.search(r"ticks (\d+) first (\S+) last (\S+) after (\d+)", capfd.readouterr().out)
    assert (int(m[1]), int(m[4])) == (200, 50) and float(m[3]) == pytest.approx(0.002 * 249)


def test_an_s32k144_channel_without_a_notification_says_how_to_name_one(tmp_path):
    src = tmp_path / "gpt.c"
    src.write_text(S32K_GPT.format(name="Control_Isr", channel=3, stop="Gpt_StopTimer(3U)"))
    r = drive(build_program([src], kit="s32k144"), track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_error" and "gpt.c:10" in r.message, r.message
    assert "-D GPT_NOTIFICATION_3=NAME" in r.message and "--isr NAME@HZ" in r.message


# -- stopping a timer interrupt ------------------------------------------------------------------

def test_the_clock_stops_an_interrupt_even_one_due_at_the_same_step():
    """``Spinner.stop_every``: a handler stopped by another due at the same step is not run; one
    that stops itself runs no more; the others keep their rate."""
    calls = []

    def main(s):
        def a():
            calls.append(("a", s.get_time()))
            if len([n for n, _ in calls if n == "a"]) == 3:  # at 0.03 s, before b's call then
                s.stop_every(b)
                s.stop_every(a)

        def b():
            calls.append(("b", s.get_time()))

        s.every(0.01, a)
        s.every(0.01, b)
        s.every(0.02, lambda: calls.append(("c", s.get_time())))
        s.sleep(0.1)

    r = drive(main, track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    assert [n for n, _ in calls] == ["a", "b", "a", "b", "c", "a", "c", "c", "c", "c"]
    assert [t for _, t in calls[5:]] == pytest.approx([0.03, 0.04, 0.06, 0.08, 0.1])


C_STOP = """\
#include <stdio.h>
#include "spinner.h"
static int a, b;
static void tick_a(void) { if (++a == 5) spinner_stop_every(tick_a); }
static void tick_b(void) { b++; }
int main(void) {
    spinner_every(0.01, tick_a);
    spinner_every(0.01, tick_b);
    spinner_sleep(0.1);
    spinner_stop_every(tick_b);
    int set = spinner_has_every(tick_a) + spinner_has_every(tick_b);
    spinner_every(0.02, tick_a);                    /* the freed slot again */
    spinner_sleep(0.1);
    printf("a %d b %d set %d interrupts %d\\n", a, b, set, spinner_interrupts());
    return 0;
}
"""


def test_c_stop_every_stops_a_handler_in_process_and_isolated(tmp_path, capfd):
    src = tmp_path / "stop.c"
    src.write_text(C_STOP)
    program = build_program([src])
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=1.0)
        assert r.outcome == "controller_returned", r.message
        assert "a 10 b 10 set 0 interrupts 1" in capfd.readouterr().out



C_STOP_QUEUED = """\
#include <stdio.h>
#include "spinner.h"
static int a, b;
static double b_first_s = -1;
static void tick_a(void) { a++; }
static void tick_b(void) { if (b++ == 0) b_first_s = spinner_get_time(); }
int main(void) {
    spinner_every(0.001, tick_a);
    spinner_sleep(0.01);
    double t0 = spinner_get_time();
    spinner_set_speed(0.1);          /* queued: --mcu-time lets 3 ms pass in it, tick_a due then */
    spinner_stop_every(tick_a);      /* queued after it */
    %s
    spinner_sleep(0.01);
    printf("a %%d b %%d after %%.4f\\n", a, b, b_first_s - t0);
    return 0;
}
"""


@pytest.mark.parametrize("isolate", [False, True])
def test_a_handler_due_in_a_request_queued_before_its_stop_is_its_own(tmp_path, capfd, isolate):
    """--mcu-time: a queued call lets time pass and the handler is due in it; the program stops the
    handler after that call (before the simulator has read the stop). The tick is the stopped
    handler's - not a fault (an unknown slot), not the handler that took the freed slot."""
    for name, reuse in (("alone", ""), ("reuse", "spinner_every(0.001, tick_b);")):
        src = tmp_path / f"{name}.c"
        src.write_text(C_STOP_QUEUED % reuse)
        program = dataclasses.replace(build_program([src]), isolate=isolate)
        r = drive(program, track="floor", time_limit_s=1.0, mcu_time=0.003)
        assert r.outcome == "controller_returned", r.message
        out = capfd.readouterr().out
        a, b, after = re.search(r"a (\d+) b (\d+) after (\S+)", out).groups()
        # tick_a: 3 ms charged to spinner_every, 10 ms asleep, 3 charged to the sleep, 3 to get_time,
        # 3 to set_speed, 3 to the stop (charged as every call): one a millisecond, in whole 2-ms steps
        assert int(a) == 24, out
        if reuse:  # tick_b: only after its spinner_every (3 ms more charged to it; the stale bug: 2 ms)
            assert float(after) == pytest.approx(0.012) and int(b) == 12, out



C_REARM = """\
#include <stdio.h>
#include "spinner.h"
static int n;
static void tick(void) {  /* a new period at each expiry, all inside one sleep */
    n++;
    spinner_stop_every(tick);
    spinner_every(n % 2 ? 0.002 : 0.003, tick);
}
int main(void) {
    spinner_every(0.002, tick);
    spinner_sleep(0.2);
    printf("ticks %d interrupts %d\\n", n, spinner_interrupts());
    return 0;
}
"""


def test_a_handler_that_sets_itself_up_anew_at_each_call_runs_on(tmp_path, capfd):
    """A handler stopped and set up again in itself, 67 times within one waiting call (2 ms and 3 ms
    periods: 4 ms on the 2-ms steps): it keeps its slot (at most 32), one interrupt all along."""
    src = tmp_path / "rearm.c"
    src.write_text(C_REARM)
    r = drive(build_program([src]), track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    assert "ticks 67 interrupts 1" in capfd.readouterr().out


UNROUTED = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
void PIT_IRQHandler(void) {{ PIT_TFLG0 = PIT_TFLG_TIF_MASK; n++; }}
int main(void) {{
    TFC_Init();
    NVIC_DisableIRQ(PIT_IRQn);  /* (TFC_Init enables it, as the library's TFC_InitADCs) */
    SIM_SCGC6 |= SIM_SCGC6_PIT_MASK;
    PIT_MCR = 0;
    PIT_LDVAL0 = 240000 - 1;
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    for (int i = 0; i < {late}; i++) TFC_Task();
    {enable}
    spinner_sleep(0.5);
    printf("calls %u\\n", n);
    return 0;
}}
"""


@pytest.mark.parametrize("isolate", [False, True])
def test_a_timer_whose_irq_the_nvic_keeps_off_is_warned_about(tmp_path, capfd, isolate):
    """PIT channel 0 counts with TIE set and the program has PIT_IRQHandler, but PIT_IRQn is disabled
    (after TFC_Init, which enables it) and never enabled again: no call (as on the board) and one
    warning of the run saying so and what to write."""
    src = tmp_path / "unrouted.c"
    src.write_text(UNROUTED.format(late=100, enable=""))
    program = dataclasses.replace(build_program([src], kit="tfc"), isolate=isolate)
    r = drive(program, track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    assert "calls 0" in capfd.readouterr().out
    assert [re.sub(r"^[^:\s]*/", "", w) for w in r.warnings if "NVIC" in w] == [  # (at the program's disable)
        "unrouted.c:8: PIT channel 0 counts with its interrupt enabled but PIT_IRQn is not enabled in the NVIC: "
        "PIT_IRQHandler is never called, on the board too (NVIC_EnableIRQ(PIT_IRQn); docs/firmware.md, "
        "Timer interrupts)"]


def test_an_irq_enabled_a_little_later_is_not_warned_about(tmp_path, capfd):
    """The same timer with PIT_IRQn enabled after 10 library calls: the handler runs, no warning.
    51 calls: the PIT counted from its set-up, its expiry in those calls is pending and taken at the
    enable, then 50 in the 0.5 s (ARMv6-M B3.4; 50 before the NVIC's pending bits were emulated)."""
    src = tmp_path / "late.c"
    src.write_text(UNROUTED.format(late=10, enable="NVIC_EnableIRQ(PIT_IRQn);"))
    r = drive(build_program([src], kit="tfc"), track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    assert "calls 51" in capfd.readouterr().out
    assert not [w for w in r.warnings if "NVIC" in w]


def test_spinner_warn_adds_a_warning_of_the_run_once_per_text(tmp_path):
    """spinner_warn: the run goes on; each distinct text is listed once, in the order first given, at
    the program's line that called it (its first call's)."""
    src = tmp_path / "warn.c"
    src.write_text(textwrap.dedent("""\
        #include "spinner.h"
        int main(void) {
            for (int i = 0; i < 3; i++) { spinner_warn("first"); spinner_sleep(0.01); }
            spinner_warn("second");
            spinner_sleep(0.01);
            return 0;
        }
        """))
    for isolate in (False, True):
        r = drive(dataclasses.replace(build_program([src]), isolate=isolate), track="floor", time_limit_s=1.0)
        assert r.outcome == "controller_returned", r.message
        assert [re.sub(r"^[^:\s]*/", "", w) for w in r.warnings if w.endswith(("first", "second"))] == [
            "warn.c:3: first", "warn.c:4: second"], isolate


def test_check_shows_the_kits_warning(tmp_path):
    """simrunner check lists the run's own warnings beside its checks: the timer left off in the NVIC."""
    from simrunner.run.check import check_controller

    src = tmp_path / "unrouted.c"
    src.write_text(UNROUTED.format(late=100, enable="while (1) TFC_Task();"))
    report = check_controller(build_program([src], kit="tfc"), track="floor")
    assert not report.problems
    assert any("PIT_IRQn is not enabled in the NVIC" in w for w in report.warnings), report.warnings


# -- the counters read live ----------------------------------------------------------------------

COUNTERS = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
int main(void) {
    TFC_Init();
    PIT_MCR = 0;
    PIT_LDVAL0 = 24000000 - 1;                        /* 1 s of the 24 MHz bus clock, no interrupt */
    PIT_TCTRL0 = PIT_TCTRL_TEN_MASK;
    LPTMR0_PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK; /* the 1 kHz LPO */
    LPTMR0_CMR = 999;
    LPTMR0_CSR = LPTMR_CSR_TEN_MASK;
    TPM2_MOD = 0xFFFF;
    TPM2_SC = TPM_SC_CMOD(1) | TPM_SC_PS(7);          /* 24 MHz / 128 = 187.5 kHz */
    unsigned c0 = PIT_CVAL0, n0 = LPTMR0_CNR, t0 = TPM2_CNT;
    double s0 = spinner_now();
    TFC_Delay_mS(10);
    double s1 = spinner_now();
    LPTMR0_CNR = 0;                                   /* latch, then read (RM 33.3.4) */
    unsigned c1 = PIT->CHANNEL[0].CVAL, n1 = LPTMR0->CNR, t1 = TPM2->CNT;
    PIT_LDVAL0 = 240000 - 1;                          /* loaded at the next expiry (RM 32.3.4) */
    TPM2_SC = 0;
    TPM2_MOD = 1000;
    TPM2_SC = TPM_SC_CMOD(1) | TPM_SC_PS(7) | TPM_SC_CPWMS_MASK;
    TFC_Delay_mS(10);
    double s2 = spinner_now();
    unsigned c2 = PIT_CVAL0, t2 = TPM2_CNT;
    TPM2_CNT = 0;                                     /* any write clears it (RM 31, TPMx_CNT) */
    double s3 = spinner_now();
    TFC_Delay_mS(4);
    unsigned t3 = TPM2_CNT, d3 = (unsigned)((spinner_now() - s3) * 1e6 + 0.5);
    spinner_add_textf("tpm2w %u %u", d3, t3);
    LPTMR0_CSR = 0;
    unsigned n2 = LPTMR0_CNR;
    spinner_add_textf("us %d %d", (int)((s1 - s0) * 1e6 + 0.5), (int)((s2 - s1) * 1e6 + 0.5));
    spinner_add_textf("pit %u %u %u", c0, c1, c2);
    spinner_add_textf("lptmr %u %u %u", n0, n1, n2);
    spinner_add_textf("tpm2 %u %u %u", t0, t1, t2);
    return 0;
}
"""


def test_running_counters_read_the_count_at_the_time_of_the_read(tmp_path):
    """PIT CVAL counts down from LDVAL at 24 MHz (a new LDVAL waits for the expiry), LPTMR0 CNR up
    at its clock (0 once disabled), TPM2 CNT up at its clock (and down again with CPWMS), over the
    simulated time of two TFC_Delay_mS(10) (whole 2-ms physics steps)."""
    src = tmp_path / "counters.c"
    src.write_text(COUNTERS)
    r = drive(build_program([src], kit="tfc"), track="floor", time_limit_s=1.0, csv=tmp_path / "log.csv")
    assert r.outcome == "controller_returned", r.message
    lines = [part for s in r.log.data_text if s for part in s.split(" | ")]
    got = {s.split()[0]: [int(v) for v in s.split()[1:]] for s in lines}
    d1_us, d2_us = got["us"]
    assert d1_us >= 10000 and d2_us >= 10000 and d1_us % 2000 == 0 and d2_us % 2000 == 0
    load = 24000000 - 1  # the new LDVAL waits for the 1-s period's end
    assert got["pit"] == [load, load - 24 * d1_us, load - 24 * (d1_us + d2_us)]
    assert got["lptmr"] == [0, d1_us // 1000, 0]  # the 1 kHz LPO; disabled: 0
    phase = d2_us * 187500 // 1000000 % 2000  # up to MOD = 1000, then down to 0
    assert got["tpm2"] == [0, d1_us * 187500 // 1000000, phase if phase <= 1000 else 2000 - phase]
    d3_us, t3 = got["tpm2w"]  # counted from the write
    phase = d3_us * 187500 // 1000000 % 2000
    assert d3_us >= 4000 and t3 == (phase if phase <= 1000 else 2000 - phase), got["tpm2w"]


# -- the counters in phase with their interrupts ---------------------------------------------------
def _last_text_both_hosts(program, prefix: str, csv, *, time_limit_s: float, mcu_time) -> list[str]:
    """Drive ``program`` in process and --isolate (on the floor): the last text line starting with
    ``prefix`` each logged, in that order."""
    texts = []
    for isolate in (False, True):
        r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=time_limit_s,
                  mcu_time=mcu_time, csv=csv)
        assert r.outcome == "controller_returned", r.message
        text = [part for s in r.log.data_text if s for part in s.split(" | ") if part.startswith(prefix)]
        assert text, r.log.data_text
        texts.append(text[-1])
    return texts



IN_PHASE = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
{pre}
void {handler}(void) {{ {clear}; n++; }}
int main(void) {{
    TFC_Init();
    for (int i = 0; i < {extra}; i++) (void)spinner_get_time();  /* (the --mcu-time charge's phase) */
    {setup}
    unsigned prev = 0, wraps = 0, reads = 0, held = 0, bad = 0, bad_wraps = 0, bad_n = 0, bad_p = 0;
    double bad_at = -1.0;
    while (reads < 150) {{
        int masked = reads % 2;              /* every other read in a critical section with a wait */
        if (masked) __disable_irq();
        spinner_sleep(0.002);
        unsigned c = {read}, p = NVIC_GetPendingIRQ({irq}), k = n;
        if (masked) __enable_irq();
        if (reads > 0 && ({wrapped})) wraps++;   /* reads are less than a period apart */
        held += p;
        if (wraps != k + p && bad++ == 0) bad_at = spinner_now_uncharged(), bad_wraps = wraps, bad_n = k, bad_p = p;
        prev = c, reads++;
    }}
    spinner_add_textf("reads %u wraps %u n %u held %u bad %u first_bad_at %.4f wraps_then %u n_then %u pending_then %u",
                      reads, wraps, n, held, bad, bad_at, bad_wraps, bad_n, bad_p);
    spinner_sleep(0.1);  /* (a frame of the log after the text) */
    return 0;
}}
"""
# TPM2 counting up and down: its reads, 2 to 6 ms apart (less than MOD = 30000 counts of 3 MHz), tell a
# turn at the top from the counts the time between them gives
UPDOWN_READ = """#include <math.h>
static unsigned tops, tops_seen, last_c;
static int down;
static double last_t = -1.0;
static unsigned read_updown(void) {
    unsigned c = TPM2_CNT;
    double t = spinner_now_uncharged();  /* the count's time (--mcu-time charged the read before it) */
    if (last_t >= 0.0) {
        double d = (t - last_t) * 3e6;
        int turn = down ? fabs((double)last_c - c - d) > fabs((double)last_c + c - d)
                        : fabs((double)c - last_c - d) > fabs(60000.0 - last_c - c - d);
        if (turn && (down = !down)) tops++;   /* (a turn at the top) */
    }
    last_c = c, last_t = t;
    return c;
}
static int topped(void) { int w = tops != tops_seen; tops_seen = tops; return w; }"""
# (the vector, its flag's clear, the set-up: a 10-ms period unless said, the IRQ, the counter's read,
# a reload between two reads: PIT CVAL counts down, LPTMR0 CNR and TPM2 CNT up)
IN_PHASE_TIMERS = {
    "pit": dict(handler="PIT_IRQHandler", clear="PIT_TFLG0 = PIT_TFLG_TIF_MASK", irq="PIT_IRQn",
                setup="""PIT_MCR = 0;
    PIT_LDVAL0 = 240000 - 1;
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_EnableIRQ(PIT_IRQn);""", read="PIT_CVAL0", wrapped="c > prev"),
    # a new LDVAL (7 ms -> 9 ms) at the 2nd call, loaded at the next expiry, a physics step before
    # its handler (21 ms after the start, the handler at 22 ms): the interrupt's new period counts
    # from the handler, the counter's too
    "pit_reload": dict(handler="PIT_IRQHandler", irq="PIT_IRQn",
                       clear="PIT_TFLG0 = PIT_TFLG_TIF_MASK; if (n == 1) PIT_LDVAL0 = 216000 - 1",
                       setup="""PIT_MCR = 0;
    PIT_LDVAL0 = 168000 - 1;
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_EnableIRQ(PIT_IRQn);""", read="PIT_CVAL0", wrapped="c > prev"),
    # a set-up changed (30 ms -> 10 ms) before a wait (the kit looks at NVIC_GetPendingIRQ): the
    # interrupt starts again with the new period, the counter with it
    "pit_set_up_twice": dict(handler="PIT_IRQHandler", clear="PIT_TFLG0 = PIT_TFLG_TIF_MASK", irq="PIT_IRQn",
                             setup="""PIT_MCR = 0;
    PIT_LDVAL0 = 720000 - 1;
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;
    NVIC_EnableIRQ(PIT_IRQn);
    (void)NVIC_GetPendingIRQ(PIT_IRQn);
    PIT_LDVAL0 = 240000 - 1;
    (void)NVIC_GetPendingIRQ(PIT_IRQn);""", read="PIT_CVAL0", wrapped="c > prev"),
    "lptmr": dict(handler="LPTimer_IRQHandler", clear="LPTMR0_CSR |= LPTMR_CSR_TCF_MASK", irq="LPTimer_IRQn",
                  setup="""LPTMR0_PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK;  /* the 1 kHz LPO */
    LPTMR0_CMR = 10 - 1;
    LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK;
    NVIC_EnableIRQ(LPTimer_IRQn);""", read="LPTMR0_CNR", wrapped="c < prev"),
    "tpm2": dict(handler="TPM2_IRQHandler", clear="TPM2_SC |= TPM_SC_TOF_MASK", irq="TPM2_IRQn",
                 setup="""TPM2_MOD = 30000 - 1;                              /* 24 MHz / 8: 3 MHz */
    TPM2_SC = TPM_SC_PS(3) | TPM_SC_TOIE_MASK | TPM_SC_CMOD(1);
    NVIC_EnableIRQ(TPM2_IRQn);""", read="TPM2_CNT", wrapped="c < prev"),
    # free running (CSR TFC): 65536 counts of MCGIRCLK's 4 MHz (16.384 ms), the flag as CNR passes
    # CMR = 39999 (the count goes on: the first 10 ms in, RM 33.3.1)
    "lptmr_tfc": dict(handler="LPTimer_IRQHandler", clear="LPTMR0_CSR |= LPTMR_CSR_TCF_MASK", irq="LPTimer_IRQn",
                      setup="""MCG_C1 |= MCG_C1_IRCLKEN_MASK; MCG_C2 |= MCG_C2_IRCS_MASK; MCG_SC = MCG_SC_FCRDIV(0);
    LPTMR0_PSR = LPTMR_PSR_PCS(0) | LPTMR_PSR_PBYP_MASK;
    LPTMR0_CMR = 40000 - 1;
    LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK | LPTMR_CSR_TFC_MASK;
    NVIC_EnableIRQ(LPTimer_IRQn);""", read="LPTMR0_CNR",
                      wrapped="((40000u - prev) & 0xFFFFu) != 0 && ((40000u - prev) & 0xFFFFu) <= ((c - prev) & 0xFFFFu)",
                      min_wraps=15),
    # up-down counting (SC CPWMS): 3 MHz, MOD 30000: up 10 ms, down 10 ms, the flag as the count turns
    # at the top (RM 31.4.3.2; the first 10 ms in); the reads tell the turns by the time between them
    "tpm2_updown": dict(handler="TPM2_IRQHandler", clear="TPM2_SC |= TPM_SC_TOF_MASK", irq="TPM2_IRQn",
                        setup="""TPM2_MOD = 30000;
    TPM2_SC = TPM_SC_PS(3) | TPM_SC_TOIE_MASK | TPM_SC_CMOD(1) | TPM_SC_CPWMS_MASK;
    NVIC_EnableIRQ(TPM2_IRQn);""", pre=UPDOWN_READ, read="read_updown()", wrapped="topped()", min_wraps=12),
}


@pytest.mark.parametrize("timer", list(IN_PHASE_TIMERS))
@pytest.mark.parametrize("mcu_time", [0.0013, None])
def test_a_running_counter_is_in_phase_with_its_interrupt(tmp_path, timer, mcu_time):
    """A 100-Hz timer's counter, read every 2 to 6 ms (every other read in a critical section with a
    wait): each reload it shows (a wrap since the read before) is an expiry whose handler has run or
    is pending (NVIC_GetPendingIRQ) - never one the interrupt has not reached. With --mcu-time the
    simulator charges the code's time before it starts the timer's interrupt (spinner_every): the
    counter counts from then too (failed before: the counter started at the kit's look, before that
    charge, so it reloaded a physics step before its interrupt fell due). With the charge's phase
    varied (a call more before the set-up); in process and --isolate alike."""
    regs = IN_PHASE_TIMERS[timer]
    results = {}
    for extra in (0, 1):
        src = tmp_path / f"in_phase_{timer}_{extra}.c"
        src.write_text(IN_PHASE.format(extra=extra, **{"pre": "", **regs}))
        program = build_program([src], kit="tfc")
        texts = _last_text_both_hosts(program, "reads", tmp_path / "log.csv", time_limit_s=3.0, mcu_time=mcu_time)
        results[extra, False], results[extra, True] = texts
    for (extra, isolate), text in results.items():
        got = dict(zip(text.split()[0::2], text.split()[1::2]))
        assert got["reads"] == "150" and int(got["wraps"]) >= regs.get("min_wraps", 25), text
        assert int(got["held"]) > 0, text  # (some reads found an expiry held by the section)
    assert all(" bad 0 " in text for text in results.values()), results
    assert results[0, False] == results[0, True] and results[1, False] == results[1, True], results


RESTARTED = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
static unsigned count[2];
static double at[2];
void {handler}(void) {{ {clear}; if (n < 2) count[n] = {read}, at[n] = spinner_now(); n++; }}
int main(void) {{
    TFC_Init();
    {setup}
    spinner_sleep(0.004);
    double t1 = spinner_now();
    {restart}
    while (n < 2) spinner_sleep(0.001);
    spinner_add_textf("restarted %.4f first %.4f %u second %.4f %u", t1, at[0], count[0], at[1], count[1]);
    return 0;
}}
"""
# (the vector, its flag's clear, a 10-ms set-up, the counter's read, a restart of the counter while
# its interrupt runs, the count its handler reads at most a physics step after an expiry)
RESTARTS = {
    # TEN cleared and set again (the count read between): the channel starts again from LDVAL (RM 32.5.1)
    "pit_ten": dict(IN_PHASE_TIMERS["pit"], restart="""PIT_TCTRL0 = 0;
    (void)PIT_CVAL0;
    PIT_TCTRL0 = PIT_TCTRL_TIE_MASK | PIT_TCTRL_TEN_MASK;""", near=lambda c: c > 240000 - 1 - 24 * 2000),
    # any write to CNT clears the counter (RM 31.4.3.3): the overflow MOD + 1 counts later
    "tpm2_cnt": dict(IN_PHASE_TIMERS["tpm2"], restart="TPM2_CNT = 0;", near=lambda c: c < 3 * 2000),
}


@pytest.mark.parametrize("timer", list(RESTARTS))
@pytest.mark.parametrize("mcu_time", [None, 0.0013])
def test_a_counter_started_again_while_its_interrupt_runs_takes_the_interrupt_with_it(tmp_path, timer, mcu_time):
    """A running timer's counter started again (PIT TEN cleared and set, a write to TPM2 CNT) 4 ms
    into a 10-ms period: its next expiry is a period after that, as on the board, so its handler
    reads the count just reloaded (failed before: the interrupt kept its old phase, the handler ran
    6 ms into the new count). In process and --isolate alike."""
    regs = dict(RESTARTS[timer])
    near = regs.pop("near")
    src = tmp_path / f"restarted_{timer}.c"
    src.write_text(RESTARTED.format(**regs))
    program = build_program([src], kit="tfc")
    results = _last_text_both_hosts(program, "restarted", tmp_path / "log.csv", time_limit_s=1.0,
                                    mcu_time=mcu_time)
    assert results[0] == results[1], results
    v = results[0].split()
    restarted, first, c1, second, c2 = float(v[1]), float(v[3]), int(v[4]), float(v[6]), int(v[7])
    assert 0.010 - 1e-9 <= first - restarted <= 0.010 + 0.0021 + (mcu_time or 0.0), results
    assert near(c1) and near(c2) and second - first <= 0.0121, results


FIRST_PERIOD = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
static volatile unsigned n;
static double at[3];
static unsigned count[3];
{pre}
void {handler}(void) {{ {clear}; if (n < 3) at[n] = spinner_now(), count[n] = {read}; n++; }}
int main(void) {{
    TFC_Init();
    double t0 = spinner_now();
    {setup}
    while (spinner_now() < t0 + {run}) spinner_sleep(0.001);
    spinner_add_textf("first %.5f n %u at %.5f %.5f %.5f count %u %u %u", t0, n, at[0], at[1], at[2],
                      count[0], count[1], count[2]);
    spinner_sleep(0.1);  /* (a frame of the log after the text) */
    return 0;
}}
"""
# (the set-up, the run's length s, the first expiry s after the set-up, the regular period s (None:
# no second within the run), the count the handler reads at the expiry and per second late)
FIRST_PERIODS = {
    # free running (CSR TFC) on the 1 kHz LPO: TCF as CNR passes CMR = 99 - 0.1 s in - and then every
    # 65536 counts (65.5 s), not at the 16-bit wrap alone (RM 33.3.1 CSR TCF, TFC)
    "lptmr_tfc_lpo": (dict(IN_PHASE_TIMERS["lptmr"], setup="""LPTMR0_PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK;
    LPTMR0_CMR = 99;
    LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK | LPTMR_CSR_TFC_MASK;
    NVIC_EnableIRQ(LPTimer_IRQn);"""), 3.0, 0.1, None, 100, 1e3),
    # ... on MCGIRCLK's 4 MHz: CMR = 39999, 10 ms in, then every 16.384 ms, the count going on from 40000
    "lptmr_tfc_fast": (IN_PHASE_TIMERS["lptmr_tfc"], 0.05, 0.01, 65536 / 4e6, 40000, 4e6),
    # up-down counting (SC CPWMS), MOD 30000 of 3 MHz: TOF as the count turns at the top, MOD + 1
    # counts in, and every 2 x MOD; the handler reads MOD - 1 going down (RM 31.4.3.2)
    "tpm2_updown": (dict(IN_PHASE_TIMERS["tpm2_updown"], pre="", read="TPM2_CNT"), 0.06, 30001 / 3e6, 0.02, 29999, -3e6),
}


@pytest.mark.parametrize("timer", list(FIRST_PERIODS))
@pytest.mark.parametrize("mcu_time", [None, 0.0013])
def test_an_interrupt_whose_expiry_is_not_at_the_counts_start_has_a_shorter_first_period(tmp_path, timer, mcu_time):
    """LPTMR0 free running (TFC) interrupts as its count passes CMR, TPM2 counting up and down
    (CPWMS) as its count turns at MOD: the first expiry CMR + 1 (MOD + 1) counts after the start,
    then every 65536 (2 x MOD) counts, the counter going on through each (its handler reads CMR + 1,
    MOD - 1; failed before: the kit interrupted at the 16-bit wrap, at the count's return to 0). In
    process and --isolate alike."""
    regs, run, first, period, count, per_s = FIRST_PERIODS[timer]
    src = tmp_path / f"first_{timer}.c"
    src.write_text(FIRST_PERIOD.format(run=run, **{"pre": "", **regs}))
    program = build_program([src], kit="tfc")
    results = _last_text_both_hosts(program, "first", tmp_path / "log.csv", time_limit_s=run + 1.0,
                                    mcu_time=mcu_time)
    assert results[0] == results[1], results
    v = results[0].split()
    t0, n, at, counts = float(v[1]), int(v[3]), [float(x) for x in v[5:8]], [int(x) for x in v[9:12]]
    late = 0.0021 + 2 * (mcu_time or 0.0)  # (a physics step; the set-up's charged time)
    assert first - 1e-6 <= at[0] - t0 <= first + late, results
    if period is None:
        assert n == 1, results  # (the next 65.5 s later)
    else:
        assert n >= 3 and all(abs(at[j + 1] - at[j] - period) <= late for j in (0, 1)), results
    for j in range(min(n, 3)):  # (read within `late` of the expiry)
        lo, hi = sorted((count, count + per_s * late))
        assert lo <= counts[j] <= hi, (j, results)


RESHAPED = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\\\\\TFC.h"
static volatile unsigned n;
static double at[4];
static unsigned count[4];
void {handler}(void) {{ {clear}; if (n < 4) at[n] = spinner_now(), count[n] = {read}; if (n == 1) {{ {change}; }} n++; }}
int main(void) {{
    TFC_Init();
    {setup}
    while (n < 4) spinner_sleep(0.001);
    spinner_add_textf("reshaped %.5f %.5f %.5f %.5f count %u %u %u %u", at[0], at[1], at[2], at[3],
                      count[0], count[1], count[2], count[3]);
    spinner_sleep(0.1);  /* (a frame of the log after the text) */
    return 0;
}}
"""
# (the set-up, a change in the 2nd handler, the periods after it: to the 3rd (the old one) and the 4th
# (from the 3rd expiry's count on, by the new set-up), the counts the 3rd and 4th handlers read)
RESHAPES = {
    # MOD 30000 -> 15000 counting up and down: the count goes on down from 29999 - past the new MOD, from
    # MOD - 1 = 14999 - the next turn at the top a new period later (10 ms)
    "tpm2_updown_mod": (dict(FIRST_PERIODS["tpm2_updown"][0], change="TPM2_MOD = 15000"), 0.02, 0.01, 14999, 14999),
    # free running, CMR 39999 -> 19999: from 40000 the count passes the new CMR 45536 counts on (11.384 ms)
    "lptmr_tfc_cmr": (dict(IN_PHASE_TIMERS["lptmr_tfc"], change="LPTMR0_CMR = 20000 - 1"), 65536 / 4e6,
                      45536 / 4e6, 40000, 20000),
    # free running turned off: the count 40000 at the 3rd expiry is 0 in the new cycle of CMR + 1 counts
    # (the handler reads the counter as the expiry left it), the flag every CMR + 1 counts from there
    "lptmr_tfc_off": (dict(IN_PHASE_TIMERS["lptmr_tfc"], change="LPTMR0_CSR &= ~LPTMR_CSR_TFC_MASK"), 65536 / 4e6,
                      0.01, 0, 0),
}


@pytest.mark.parametrize("timer", list(RESHAPES))
@pytest.mark.parametrize("mcu_time", [None, 0.0013])
def test_a_new_set_up_while_its_interrupt_runs_takes_effect_at_the_next_expiry_the_count_going_on(
        tmp_path, timer, mcu_time):
    """A new CMR or MOD, or free running (TFC) turned off, in a handler: the next expiry still the old
    set-up's, then the count goes on from that expiry's by the new set-up - the counter and the
    interrupt together. In process and --isolate alike."""
    regs, old, new, c3, c4 = RESHAPES[timer]
    src = tmp_path / f"reshaped_{timer}.c"
    src.write_text(RESHAPED.format(**regs))
    program = build_program([src], kit="tfc")
    results = _last_text_both_hosts(program, "reshaped", tmp_path / "log.csv", time_limit_s=1.0,
                                    mcu_time=mcu_time)
    assert results[0] == results[1], results
    v = results[0].split()
    at, counts = [float(x) for x in v[1:5]], [int(x) for x in v[6:10]]
    assert abs(at[2] - at[1] - old) <= 0.0021 and abs(at[3] - at[2] - new) <= 0.0021, results
    assert counts[2] == c3 and counts[3] == c4, results
