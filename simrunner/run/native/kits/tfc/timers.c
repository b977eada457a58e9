/* The KL25Z timers of a firmware's own timer interrupt (the simulator's TFC kit; registers in
 * include/TFC/sim_timers.h; docs/firmware.md, Timer interrupts).
 *
 * The registers are memory the firmware writes; the kit reads them before each request the
 * program waits on (spinner_kit_before_wait, called by the host) - the program's code between two
 * such requests takes no simulated time, so a timer is started at the time of its set-up - and
 * after each handler. A timer that counts with its interrupt enabled expires every period its
 * registers and clock give (spinner_every with a function of the kit; LPTMR0 free running and TPM2
 * counting up and down first after a shorter period: struct phase); its IRQ enabled in the NVIC,
 * the expiry sets the timer's flag, calls the program's handler of its vector and clears the flag
 * (the handler's write-1-to-clear is taken as done); its IRQ disabled, it sets the NVIC's pending
 * bit instead, which NVIC_EnableIRQ takes (below). Clearing the enable or the interrupt enable stops
 * the calls; a new period while it runs (a new LDVAL, CMR, MOD) takes effect at its next expiry, as
 * the hardware reloads it then. A handler that
 * --isr (or spinner_every) already runs is left to that: its rate is --isr's. A set-up the kit
 * cannot time ends the run with one line saying why.
 *
 * Clocks: those of the TFC library's clock set-up (TFC_CrystalClock: the FRDM-KL25Z's 8 MHz
 * crystal, the PLL at 48 MHz, CORE_CLOCK 48 MHz, PERIPHERAL_BUS_CLOCK = CORE_CLOCK / 2), the LPO
 * and the MCG's internal reference. KL25 Sub-Family Reference Manual (KL25P80M48SF0RM) sections
 * beside each number. */
#include <math.h>
#include <stdio.h>

#define TFC_SIM_TIMERS_RAW  /* the kit's own uses of the registers: no counter update */
#include "spinner.h"
#include "TFC/TFC.h"

#define BUS_CLOCK_HZ 24e6        /* PIT: the bus clock (RM 5.7 module clocks; TFC_CrystalClock.h) */
#define PLL_HALF_HZ 24e6         /* MCGPLLCLK/2: the 48 MHz PLL halved (RM 12.2.3 SOPT2 PLLFLLSEL) */
#define OSCERCLK_HZ 8e6          /* the FRDM-KL25Z's 8 MHz crystal (FRDM-KL25Z user's manual) */
#define LPO_HZ 1e3               /* the 1 kHz low-power oscillator (RM 5.4 LPO) */
#define SLOW_IRC_HZ 32768.0      /* MCGIRCLK, IRCS = 0: the slow IRC, factory trimmed (KL25 data sheet) */
#define FAST_IRC_HZ 4e6          /* MCGIRCLK, IRCS = 1: the fast IRC / 2^FCRDIV (RM 24.3.8, data sheet) */
#define IRQ_TPM2 19              /* IRQ numbers (RM 3.3.2.3, vector - 16) */
#define IRQ_PIT 22
#define IRQ_LPTMR 28

/* The registers, at their reset values (RM 32.3.1 PIT_MCR: MDIS set; 31.3.3 TPM MOD 0xFFFF; 24.3.1
 * MCG_C1 0x04, IRCLKEN clear) but SIM_SOPT2, which TFC_Init sets as the library's servo and motor
 * set-up does (TPM clock MCGPLLCLK/2). */
LPTMR_Type tfc_sim_lptmr0;
PIT_Type tfc_sim_pit = {.MCR = PIT_MCR_MDIS_MASK};
TPM_Type tfc_sim_tpm2 = {.MOD = 0xFFFFu};
NVIC_Type tfc_sim_nvic;
SIM_Type tfc_sim_sim;
MCG_Type tfc_sim_mcg = {.C1 = 0x04u};

extern void PIT_IRQHandler(void) __attribute__((weak));
extern void LPTimer_IRQHandler(void) __attribute__((weak));   /* CMSIS startup_MKL25Z4.s */
extern void LPTMR0_IRQHandler(void) __attribute__((weak));    /* Kinetis SDK / KDS startup */
extern void TPM2_IRQHandler(void) __attribute__((weak));

enum { PIT0, PIT1, LPTMR, TPM_2, N_TIMERS };
static void fire_pit0(void);
static void fire_pit1(void);
static void fire_lptmr(void);
static void fire_tpm2(void);

struct phase {  /* LPTMR0, TPM2: where in its counter's cycle a timer expires (phase_of) */
    double cycle, flag_at, hz;
};

static struct timer {
    const char *name;
    void (*fire)(void);     /* the kit's function spinner_every calls */
    double period_s;        /* the running period (0: not running) */
    double next_period_s;   /* a new one from the next expiry (0: none) */
    double regular_s;       /* the period its registers give (period_of; the first may be shorter: start) */
    struct phase ph;        /* LPTMR0, TPM2: its counter's cycle and phase of the expiry while it runs
                             * (cycle 0: none), which the counter keeps until the interrupt takes a new one */
    uint32_t flag_count;    /* ... the count there, */
    int flag_down;          /* ... counting down from it (TPM2, CPWMS) */
    unsigned started;       /* the wait at which it started */
    unsigned unrouted;      /* looks in a row at it counting, interrupt on, its IRQ off in the NVIC */
    int flagged;            /* its flag set by an expiry not yet taken (its IRQ was disabled then) */
    unsigned starts;        /* its interrupt's starts (start) */
} timers[N_TIMERS] = {
    {.name = "PIT channel 0", .fire = fire_pit0}, {.name = "PIT channel 1", .fire = fire_pit1},
    {.name = "LPTMR0", .fire = fire_lptmr}, {.name = "TPM2", .fire = fire_tpm2},
};
static uint32_t nvic_enabled;  /* the IRQs enabled in the NVIC */
static unsigned waits;         /* requests the program waited on (time may pass at each) */
static int firing;             /* a timer's handler runs (its flag set) */
static int firing_irq = -1;    /* ... that of this IRQ */

__attribute__((noreturn)) static void cannot(const struct timer *t, const char *why) {
    char text[400];
    snprintf(text, sizeof text, "%s: its interrupt is set up but %s: not emulated by the simulator's "
             "TFC kit (docs/firmware.md, Timer interrupts; --isr NAME@HZ runs a handler at a rate you give)",
             t->name, why);
    spinner_fail(text);
}

/* The NVIC's pending bits (ARMv6-M Architecture Reference Manual, ARM DDI 0419, B3.4 the NVIC: an
 * interrupt's pending bit is independent of its enable bit; a pending, enabled interrupt is taken
 * when PRIMASK allows, which clears the bit; one bit a source, however often it was asserted; ISPR
 * sets it, ICPR clears it). A timer's expiry while its IRQ is disabled, and NVIC_SetPendingIRQ, set
 * the kit's bit (nvic_pending); once the IRQ is enabled the kit hands it to the simulator
 * (spinner_pend_every with the IRQ's take function, nvic_handed), which runs it as an interrupt when
 * PRIMASK allows - or takes it back if the IRQ is disabled (or the bit cleared) before it ran. An
 * expiry held by __disable_irq (or due after a running handler) is the simulator's pending call of
 * the timer's own function (spinner_every), not a bit here: NVIC_GetPendingIRQ asks the simulator for
 * it (spinner_every_pending). */
static uint32_t nvic_pending;  /* pending, not handed to the simulator (the IRQ disabled, or not looked at yet) */
static uint32_t nvic_handed;   /* pending, handed to the simulator: its take function has not run yet */
static uint32_t nvic_unpend;   /* NVIC_ICPR bits written since the last look */
#define KIT_IRQS ((1u << IRQ_TPM2) | (1u << IRQ_PIT) | (1u << IRQ_LPTMR))
static void take_tpm2(void);
static void take_pit(void);
static void take_lptmr(void);
static void nvic_settle(void);
static void (*take_of(int irq))(void) { return irq == IRQ_TPM2 ? take_tpm2 : irq == IRQ_PIT ? take_pit : take_lptmr; }

/* Raw NVIC_ISER / NVIC_ICER / NVIC_ISPR writes since the last look (write 1 to set / clear); a bit
 * written to both ISER and ICER is enabled (the "disable, set up, enable" sequence); one written to
 * both ICPR and ISPR is pending (ICPR is applied at the end of the look: sync). */
static void nvic_sync(void) {
    uint32_t set = NVIC->ISER[0], clear = NVIC->ICER[0];
    nvic_enabled = (nvic_enabled & ~clear) | set;
    nvic_unpend |= NVIC->ICPR[0];
    uint32_t pend = NVIC->ISPR[0];
    NVIC->ISER[0] = NVIC->ICER[0] = NVIC->ICPR[0] = NVIC->ISPR[0] = 0;
    if (pend & ~KIT_IRQS) {
        char text[300];
        snprintf(text, sizeof text, "NVIC_SetPendingIRQ / NVIC_ISPR 0x%08x: the simulator's TFC kit emulates the "
                 "pending bits of IRQ 19 (TPM2), 22 (PIT) and 28 (LPTMR0) only (docs/firmware.md, Timer "
                 "interrupts)", (unsigned)pend);
        spinner_fail(text);
    }
    nvic_pending |= pend;
    nvic_unpend &= ~pend;  /* (pending after a clear in the same interval) */
}

static int irq_on(int irq) { return (nvic_enabled >> irq) & 1u; }

/* MCGIRCLK (RM 24.3.1 C1 IRCLKEN, 24.3.2 C2 IRCS, 24.3.8 SC FCRDIV), or 0 when it is off. */
static double mcgirclk_hz(void) {
    if (!(MCG->C1 & MCG_C1_IRCLKEN_MASK)) return 0.0;
    if (!(MCG->C2 & MCG_C2_IRCS_MASK)) return SLOW_IRC_HZ;
    return FAST_IRC_HZ / (double)(1u << ((MCG->SC & MCG_SC_FCRDIV_MASK) >> 1));
}

static void (*lptmr_handler(void))(void) { return LPTimer_IRQHandler ? LPTimer_IRQHandler : LPTMR0_IRQHandler; }

static void (*handler_of(int i))(void) {
    return i == LPTMR ? lptmr_handler() : i == TPM_2 ? TPM2_IRQHandler : PIT_IRQHandler;
}

static const char *vector_of(int i) {
    return i == LPTMR ? "LPTimer_IRQHandler (or LPTMR0_IRQHandler)" : i == TPM_2 ? "TPM2_IRQHandler" : "PIT_IRQHandler";
}

/* A set-up the kit cannot time: why (period_of returns -1; an error once its IRQ is enabled). */
static const char *untimed_why;
static double untimed(const char *why) {
    untimed_why = why;
    return -1.0;
}

/* A PIT channel: (LDVAL + 1) bus clocks (RM 32.5.1 Timers). */
static double pit_period(int ch) {
    uint32_t ctrl = PIT->CHANNEL[ch].TCTRL;
    if (!(ctrl & PIT_TCTRL_TEN_MASK) || !(ctrl & PIT_TCTRL_TIE_MASK)) return 0.0;
    if (PIT->MCR & PIT_MCR_MDIS_MASK)
        return untimed("the PIT is disabled (PIT_MCR MDIS, set out of reset: clear it, PIT_MCR = 0, before the "
               "channels' set-up, RM 32.3.1); on the board its timers would not run");
    if (ctrl & PIT_TCTRL_CHN_MASK) return untimed("chained PIT timers (TCTRL CHN, RM 32.5.3)");
    return ((double)PIT->CHANNEL[ch].LDVAL + 1.0) / BUS_CLOCK_HZ;
}

/* The LPTMR in time counter mode: CMR + 1 counts (a free-running counter, CSR TFC: 65536, the first
 * CMR + 1: struct phase) of its
 * clock (RM 33.4.1 PCS: MCGIRCLK, LPO, ERCLK32K, OSCERCLK; chip configuration 3.8.3) divided by
 * 2^(PRESCALE + 1), or not divided with PBYP (RM 33.3.2). */
static double lptmr_period(void) {
    uint32_t csr = LPTMR0->CSR, psr = LPTMR0->PSR;
    if (!(csr & LPTMR_CSR_TEN_MASK) || !(csr & LPTMR_CSR_TIE_MASK)) return 0.0;
    if (csr & LPTMR_CSR_TMS_MASK) return untimed("pulse counter mode (CSR TMS) counts a pin's pulses");
    double hz = 0.0;
    switch (psr & LPTMR_PSR_PCS_MASK) {
    case 0:
        hz = mcgirclk_hz();
        if (hz == 0.0) return untimed("its clock MCGIRCLK is off (MCG_C1 IRCLKEN clear, as the TFC library's clock "
                              "set-up leaves it; RM 24.3.1)");
        break;
    case 1: hz = LPO_HZ; break;
    case 2: /* ERCLK32K: SIM_SOPT1 OSC32KSEL (RM 12.2.2) */
        if (((SIM->SOPT1 & SIM_SOPT1_OSC32KSEL_MASK) >> 18) != 3u)
            return untimed("its clock ERCLK32K is not the LPO (SIM_SOPT1 OSC32KSEL != 3: the FRDM-KL25Z has no 32 kHz "
                   "crystal, RTC_CLKIN is a pin)");
        hz = LPO_HZ;
        break;
    default: hz = OSCERCLK_HZ; break;
    }
    double divide = (psr & LPTMR_PSR_PBYP_MASK) ? 1.0 : (double)(2u << ((psr & LPTMR_PSR_PRESCALE_MASK) >> 3));
    double counts = (csr & LPTMR_CSR_TFC_MASK) ? 65536.0 : (double)(LPTMR0->CMR & 0xFFFFu) + 1.0;
    return counts * divide / hz;
}

/* TPM2's overflow: MOD + 1 counts (up-down counting, CPWMS: 2 x MOD, the first MOD + 1: struct
 * phase) of the TPM clock (SIM_SOPT2
 * TPMSRC, RM 12.2.3) divided by 2^PS (RM 31.3.1, 31.4.3). */
static double tpm2_period(void) {
    uint32_t sc = TPM2->SC, cmod = (sc & TPM_SC_CMOD_MASK) >> 3;
    if (cmod == 0) return 0.0;
    for (int ch = 0; ch < 2; ch++)
        if (TPM2->CONTROLS[ch].CnSC & TPM_CnSC_CHIE_MASK) return untimed("a channel interrupt (CnSC CHIE)");
    if (!(sc & TPM_SC_TOIE_MASK)) return 0.0;
    if (cmod != 1) return untimed("it counts the external clock pin (SC CMOD = 2, RM 31.3.1)");
    double hz = 0.0;
    switch ((SIM->SOPT2 & SIM_SOPT2_TPMSRC_MASK) >> 24) {
    case 0: return untimed("the TPM clock is off (SIM_SOPT2 TPMSRC = 0)");
    case 1:
        if (!(SIM->SOPT2 & SIM_SOPT2_PLLFLLSEL_MASK))
            return untimed("its clock is MCGFLLCLK (SIM_SOPT2 PLLFLLSEL = 0), off while the TFC library runs the PLL");
        hz = PLL_HALF_HZ;
        break;
    case 2: hz = OSCERCLK_HZ; break;
    default:
        hz = mcgirclk_hz();
        if (hz == 0.0) return untimed("its clock MCGIRCLK is off (MCG_C1 IRCLKEN clear; RM 24.3.1)");
    }
    uint32_t mod = TPM2->MOD & 0xFFFFu;
    if ((sc & TPM_SC_CPWMS_MASK) && mod == 0) return untimed("MOD is 0 in up-down counting (SC CPWMS)");
    double counts = (sc & TPM_SC_CPWMS_MASK) ? 2.0 * mod : (double)mod + 1.0;
    return counts * (double)(1u << (sc & TPM_SC_PS_MASK)) / hz;
}

/* The timer counts with its interrupt enabled (whatever the NVIC says). */
static int armed(int i) {
    if (i == LPTMR) return (LPTMR0->CSR & LPTMR_CSR_TEN_MASK) && (LPTMR0->CSR & LPTMR_CSR_TIE_MASK);
    if (i == TPM_2) return (TPM2->SC & TPM_SC_CMOD_MASK) && (TPM2->SC & TPM_SC_TOIE_MASK);
    uint32_t ctrl = PIT->CHANNEL[i - PIT0].TCTRL;
    return (ctrl & PIT_TCTRL_TEN_MASK) && (ctrl & PIT_TCTRL_TIE_MASK) && !(PIT->MCR & PIT_MCR_MDIS_MASK);
}

static int irq_of(int i) { return i == LPTMR ? IRQ_LPTMR : i == TPM_2 ? IRQ_TPM2 : IRQ_PIT; }

static const void *nvic_disabled_at[32];  /* where the program called NVIC_DisableIRQ (a return address) */

/* A timer set up to interrupt, with the program's handler, whose IRQ the NVIC keeps off for
 * UNROUTED_LOOKS looks in a row (a set-up that enables it later is not warned about): on the board
 * the handler is never called either, which the run's end alone would not explain. */
#define UNROUTED_LOOKS 50
static void warn_unrouted(int i) {
    struct timer *t = &timers[i];
    if (!armed(i) || irq_on(irq_of(i)) || handler_of(i) == NULL) {
        t->unrouted = 0;
        return;
    }
    if (++t->unrouted != UNROUTED_LOOKS) return;
    static const char *const irq_names[] = {"PIT_IRQn", "PIT_IRQn", "LPTimer_IRQn", "TPM2_IRQn"};
    char text[300];
    snprintf(text, sizeof text, "%s counts with its interrupt enabled but %s is not enabled in the NVIC: "
             "%s is never called, on the board too (NVIC_EnableIRQ(%s); docs/firmware.md, Timer interrupts)",
             t->name, irq_names[i], vector_of(i), irq_names[i]);
    spinner_warn_at(text, nvic_disabled_at[irq_of(i)]);  /* (where the program disabled it, if it did) */
}

static double period_of(int i) {
    return i == LPTMR ? lptmr_period() : i == TPM_2 ? tpm2_period() : pit_period(i - PIT0);
}

/* Stop a timer's calls; `source`: because its own interrupt enable (or the timer) was turned off -
 * then an expiry that has not been taken yet (held by __disable_irq, or due after the running
 * handler) keeps the NVIC's pending bit and runs once, as on the board (ARMv6-M, ARM DDI 0419, B3.4:
 * pending until taken or cleared; NVIC_ICPR): its handler, or with its IRQ disabled by then the bit
 * the kit keeps for NVIC_EnableIRQ (fire). */
static void stop(struct timer *t, int source) {
    if (source) spinner_stop_every_latched(t->fire);
    else spinner_stop_every(t->fire);
    t->period_s = t->next_period_s = t->regular_s = 0.0;
    t->ph.cycle = 0.0;
}

/* The counters, counting simulated time (spinner_now_uncharged: the time of the program's last
 * call, or a handler's; the program's use of a counting timer is a read of the time, charged with
 * --mcu-time before the counter is made: tfc_sim_pit_now): a counter starts at the look that finds
 * it enabled - a use of LPTMR0, PIT or TPM2 in the program (its accessor, below), the look before a
 * wait or after a handler - which is the time of
 * the write, as the program's code between two calls takes no simulated time; one whose interrupt
 * starts with it counts from the time that interrupt is timed from (start). The looks (`look`)
 * read the time only for a change (a start, a new LDVAL): a running counter's count is made at the
 * program's read, so a running timer costs no round trip per wait. */
static struct counter {
    int on;                 /* counting */
    double start_s;         /* when the count was at its start value */
    uint32_t load;          /* PIT: the LDVAL of the period under way */
    uint32_t next_load;     /* PIT: a new LDVAL, loaded at next_at_s (RM 32.3.4) */
    double next_at_s;       /* (0: none) */
    uint32_t shown;         /* TPM2: the CNT the kit wrote last (another there: the program wrote it) */
    int fresh;              /* its count started (or was cleared) since the last look ended (start) */
} pit_count[2], lptmr_count, tpm2_count;

/* PIT channel ch (RM 32.3 memory map: 32.3.1 MCR, 32.3.2-3 LTMR64H/L, 32.3.4 LDVALn, 32.3.5 CVALn,
 * 32.3.6 TCTRLn, 32.3.7 TFLGn; 32.5.1 timers): while TEN is set and the module enabled (MCR
 * MDIS clear) CVAL counts down from LDVAL at the bus clock and is loaded with LDVAL again at the
 * count after 0 (a period of LDVAL + 1); a new LDVAL written meanwhile is loaded at the next expiry,
 * not at once (RM 32.3.4 LDVAL). Disabled, CVAL keeps its value (RM 32.3.5 CVAL: "unreliable"). */
static int pit_counting(int ch) {
    return (PIT->CHANNEL[ch].TCTRL & PIT_TCTRL_TEN_MASK) && !(PIT->MCR & PIT_MCR_MDIS_MASK);
}

static void pit_counter(int ch, int look) {
    struct counter *k = &pit_count[ch];
    PIT_CHANNEL_Type *r = &PIT->CHANNEL[ch];
    int on = pit_counting(ch);
    if (!on) {
        k->on = 0;
        return;
    }
    if (look && k->on && r->LDVAL == (k->next_at_s > 0.0 ? k->next_load : k->load)) return;
    double now = spinner_now_uncharged();
    if (!k->on) {
        k->on = 1, k->start_s = now, k->load = r->LDVAL, k->next_at_s = 0.0, k->fresh = 1;
    }
    if (k->next_at_s > 0.0 && now >= k->next_at_s) {
        k->start_s = k->next_at_s, k->load = k->next_load, k->next_at_s = 0.0;
    }
    double period = (double)k->load + 1.0;
    double ticks = (now - k->start_s) * BUS_CLOCK_HZ + 1e-6;
    if (r->LDVAL != (k->next_at_s > 0.0 ? k->next_load : k->load)) {  /* written since: at the next expiry */
        k->next_load = r->LDVAL;
        k->next_at_s = k->start_s + (double)((uint64_t)(ticks / period) + 1) * period / BUS_CLOCK_HZ;
    }
    r->CVAL = k->load - (uint32_t)((uint64_t)ticks % (uint64_t)period);
}

/* The cycle of LPTMR0's or TPM2's running interrupt (start; NULL: none): its counter counts by it, the
 * registers' new CMR, MOD, TFC, CPWMS or clock taking effect with the interrupt's, at its next expiry
 * (fire: the counter goes on from the expiry's count; on the board TPM MOD is buffered up to that
 * expiry, RM 31.4.8.1 MOD register update, and the LPTMR's CSR, PSR and CMR are to be changed with
 * the timer disabled or, CMR, with TCF set: RM 33.3 register descriptions). (A MOD = 1 up-down cycle counts as up counting's: 0, 1, 0, 1.) */
static const struct phase *held_phase(int i) {
    const struct timer *t = &timers[i];
    return t->period_s > 0.0 && t->ph.cycle > 0.0 ? &t->ph : NULL;
}

/* LPTMR0's count rate (RM 33.4.1 PCS, 33.3.2 PSR), 0 where it would not count. */
static double lptmr_count_hz(void) {
    uint32_t psr = LPTMR0->PSR;
    double hz;
    switch (psr & LPTMR_PSR_PCS_MASK) {
    case 0: hz = mcgirclk_hz(); break;
    case 1: hz = LPO_HZ; break;
    case 2: hz = ((SIM->SOPT1 & SIM_SOPT1_OSC32KSEL_MASK) >> 18) == 3u ? LPO_HZ : 0.0; break;
    default: hz = OSCERCLK_HZ; break;
    }
    return (psr & LPTMR_PSR_PBYP_MASK) ? hz : hz / (double)(2u << ((psr & LPTMR_PSR_PRESCALE_MASK) >> 3));
}

/* LPTMR0 in time counter mode (RM 33.4.5 LPTMR counter): CNR counts up at its clock from 0 while TEN
 * is set, back to 0 after it equals CMR (with CSR TFC: free running, 16 bits); clearing TEN resets it
 * to 0. On the KL25 a read of CNR gives the count latched by the last write to it (RM 33.3.4: write
 * any value, then read): here every read gives the count now, as the write-then-read does. */
static int lptmr_counting(void) {
    uint32_t csr = LPTMR0->CSR;
    return (csr & LPTMR_CSR_TEN_MASK) && !(csr & LPTMR_CSR_TMS_MASK) && lptmr_count_hz() != 0.0;
}

static void lptmr_counter(int look) {
    struct counter *k = &lptmr_count;
    uint32_t csr = LPTMR0->CSR;
    double hz = lptmr_count_hz();
    if (!lptmr_counting()) {
        if (k->on && !(csr & LPTMR_CSR_TEN_MASK)) LPTMR0->CNR = 0;
        k->on = 0;
        return;
    }
    if (look && k->on) return;
    double now = spinner_now_uncharged();
    if (!k->on) k->on = 1, k->start_s = now, k->fresh = 1;
    const struct phase *held = held_phase(LPTMR);
    if (held) hz = held->hz;
    uint64_t ticks = (uint64_t)((now - k->start_s) * hz + 1e-6);
    uint64_t wrap = held ? (uint64_t)held->cycle
                         : (csr & LPTMR_CSR_TFC_MASK) ? 65536u : (uint64_t)(LPTMR0->CMR & 0xFFFFu) + 1u;
    LPTMR0->CNR = (uint32_t)(ticks % wrap);
}

/* TPM2's counter (RM 31.4.3 Counter): while SC CMOD selects the TPM clock, CNT counts up at the
 * TPM clock / 2^PS from 0 to MOD and again from 0; with SC CPWMS up to MOD and down to 0 (RM 31.4.3.2
 * up-down counting). It starts at 0 (its value while stopped is kept). A write to CNT clears it
 * (RM chapter 31, TPMx_CNT: "writing any value to COUNT clears the counter"): the kit sees a value
 * it did not write there at the next use of TPM2 or the next look, before time passes, and counts
 * from 0 then (a write of the very count shown then is not seen). */
static double tpm_clock_hz(void) {
    switch ((SIM->SOPT2 & SIM_SOPT2_TPMSRC_MASK) >> 24) {
    case 1: return (SIM->SOPT2 & SIM_SOPT2_PLLFLLSEL_MASK) ? PLL_HALF_HZ : 0.0;
    case 2: return OSCERCLK_HZ;
    case 3: return mcgirclk_hz();
    default: return 0.0;
    }
}

static int tpm2_counting(void) {
    uint32_t sc = TPM2->SC;
    return ((sc & TPM_SC_CMOD_MASK) >> 3) == 1u && tpm_clock_hz() / (double)(1u << (sc & TPM_SC_PS_MASK)) != 0.0;
}

static void tpm2_counter(int look) {
    struct counter *k = &tpm2_count;
    uint32_t sc = TPM2->SC, mod = TPM2->MOD & 0xFFFFu;
    double hz = tpm_clock_hz() / (double)(1u << (sc & TPM_SC_PS_MASK));
    if (!tpm2_counting()) {
        k->on = 0;
        return;
    }
    int cleared = k->on && TPM2->CNT != k->shown;  /* the program wrote CNT */
    if (look && k->on && !cleared) return;
    double now = spinner_now_uncharged();
    if (!k->on || cleared) k->on = 1, k->start_s = now, k->fresh = 1;
    const struct phase *held = held_phase(TPM_2);
    int updown = (sc & TPM_SC_CPWMS_MASK) != 0;
    if (held) hz = held->hz, updown = held->flag_at != 0.0, mod = (uint32_t)(updown ? held->cycle / 2 : held->cycle - 1);
    uint64_t ticks = (uint64_t)((now - k->start_s) * hz + 1e-6);
    if (!updown) {
        TPM2->CNT = (uint32_t)(ticks % ((uint64_t)mod + 1u));
    } else {
        uint64_t p = mod ? ticks % (2u * (uint64_t)mod) : 0u;
        TPM2->CNT = (uint32_t)(p <= mod ? p : 2u * mod - p);
    }
    k->shown = TPM2->CNT;
}

static void counters(void) {  /* a look */
    pit_counter(0, 1);
    pit_counter(1, 1);
    lptmr_counter(1);
    tpm2_counter(1);
}

static struct counter *counter_of(int i) {
    return i == LPTMR ? &lptmr_count : i == TPM_2 ? &tpm2_count : &pit_count[i - PIT0];
}

/* Where in its counter's cycle a timer expires (LPTMR0 and TPM2; the PIT expires as CVAL reloads):
 * the cycle (counts), the phase of the expiry in it (counts from the counter's start value), the
 * counts' rate. LPTMR0 (RM 33.3.1 CSR: TCF set when CNR equals CMR and CNR increments; TFC 0 "CNR
 * is reset whenever TCF is set", 1 "CNR is reset on overflow"):
 * CMR + 1 counts, its flag as the count goes back to 0; free running (TFC), 65536 counts with its
 * flag as the count passes CMR - first CMR + 1 counts after the start, then every 65536. TPM2 (RM
 * 31.4.3.1 up counting: TOF as the counter changes from MOD to 0; 31.4.3.2 up-down counting, CPWMS:
 * "the TOF bit is set when the TPM counter changes from MOD to (MOD - 1)", a period of 2 x MOD):
 * MOD + 1 counts, its flag at 0; up-down, 2 x MOD counts with its flag MOD + 1 counts in, the count
 * MOD - 1 going down. An interrupt whose expiry is not where the count starts has a shorter first
 * period (start). */
static int phase_of(int i, struct phase *f) {
    if (i == LPTMR) {
        uint32_t cmr = LPTMR0->CMR & 0xFFFFu;
        f->hz = lptmr_count_hz();
        f->cycle = (LPTMR0->CSR & LPTMR_CSR_TFC_MASK) ? 65536.0 : (double)cmr + 1.0;
        f->flag_at = (LPTMR0->CSR & LPTMR_CSR_TFC_MASK) ? (double)((cmr + 1u) & 0xFFFFu) : 0.0;
    } else if (i == TPM_2) {
        uint32_t sc = TPM2->SC, mod = TPM2->MOD & 0xFFFFu;
        f->hz = tpm_clock_hz() / (double)(1u << (sc & TPM_SC_PS_MASK));
        f->cycle = (sc & TPM_SC_CPWMS_MASK) ? 2.0 * mod : (double)mod + 1.0;
        f->flag_at = (sc & TPM_SC_CPWMS_MASK) && mod > 1u ? (double)mod + 1.0 : 0.0;
    } else {
        return 0;
    }
    return f->hz > 0.0 && f->cycle > 0.0;
}

/* The count at phase p of the cycle (its direction: TPM2 up-down), and back. */
static uint32_t count_at(int i, double p, int *down) {
    uint32_t c = (uint32_t)(p + 1e-6), mod = TPM2->MOD & 0xFFFFu;
    *down = i == TPM_2 && (TPM2->SC & TPM_SC_CPWMS_MASK) && c > mod;
    return *down ? 2u * mod - c : c;
}

static double phase_at(int i, const struct phase *f, uint32_t c, int down) {
    if (i == TPM_2 && (TPM2->SC & TPM_SC_CPWMS_MASK)) {
        uint32_t mod = TPM2->MOD & 0xFFFFu;
        if (c >= mod) {  /* (a count at or past a new, smaller MOD: going down from its top) */
            if (!down || mod < 2u) return fmod((double)mod, f->cycle);
            c = mod - 1u;
        }
        return down && c > 0u ? 2.0 * mod - c : (double)c;
    }
    return fmod((double)c, f->cycle);
}

static double handler_s = -1.0;  /* the time of the kit's running handler (fire, take; else -1) */
static int starting;  /* start() waits for the simulator's time (sync: a look asked meanwhile) */

/* Start timer i's interrupt: every period_s from the time the simulator reads the request
 * (spinner_every). On the board one write (TEN, CMOD) starts the counter and its interrupt, and an
 * expiry reloads the counter as it interrupts: the counter counts from the interrupt's start too -
 * one that started (or was cleared) since the last look, or any running one at a `restart` (a new
 * period: at an expiry, RM 32.3.4; or a set-up changed before time passed). That time is not the
 * look's: with --mcu-time the simulator charges the code's time before the request, so a counter
 * left at the look's time (spinner_now_uncharged) would reload that much before its interrupt fell
 * due - a program comparing the two, or NVIC_GetPendingIRQ, would see the count past an expiry whose
 * handler had not run. spinner_now_uncharged after the request returns the time it was read at:
 * without --mcu-time no time passed, the same time without a round trip (the look, or the program's
 * use of the timer, asked it since the last call); with it, one round trip. In the kit's handlers
 * (fire, take) no time passes and nothing is charged: the handler's time, asked as it starts. A PIT
 * counter that was counting before its interrupt was enabled (TIE set later) keeps its count.
 *
 * LPTMR0 and TPM2 expire at a phase of their counter's cycle (struct phase): the interrupt's first
 * period runs from the counter's phase to it - from the start value, CMR + 1 counts free running
 * (TFC), MOD + 1 counting up and down (CPWMS) - and the regular period_s from that expiry on
 * (next_period_s: fire starts it again `at_expiry`). The counter keeps its count at an expiry (no
 * reload in those modes): at_expiry it goes on from the count of the expiry (flag_count: CMR + 1,
 * MOD - 1 going down; 0 in the reloading modes), at the phase that count has in the registers' cycle
 * now (a CMR, MOD or mode changed since takes effect there, as a new period does); a counter counting
 * before its interrupt was enabled keeps its phase, the interrupt timed from it. */
static void start(int i, double period_s, int restart, int at_expiry) {
    struct timer *t = &timers[i];
    if (period_s < 1e-5) {
        char why[120];
        snprintf(why, sizeof why, "its period %.3g s is shorter than the simulator's 10 us (a 100 kHz timer)", period_s);
        cannot(t, why);
    }
    struct counter *k = counter_of(i);
    struct phase f;
    int phased = phase_of(i, &f) && k->on;
    int follow = phased || (k->on && (k->fresh || restart));
    double lead = 0.0, first_s = period_s;  /* (the counter's phase at the start, counts) */
    if (phased) {
        if (at_expiry) lead = phase_at(i, &f, t->flag_count, t->flag_down);
        else if (!k->fresh && !restart)
            lead = fmod((spinner_now_uncharged() - k->start_s) * f.hz + 1e-6, f.cycle);
        double first = fmod(f.flag_at - lead + f.cycle, f.cycle);
        if (first > 1e-6 && f.cycle - first > 1e-6) first_s = fmax(first / f.hz, 1e-5);
        t->ph = f;
        t->flag_count = count_at(i, f.flag_at, &t->flag_down);
    }
    spinner_every(first_s, t->fire);
    t->period_s = first_s, t->regular_s = period_s, t->started = waits;
    t->next_period_s = first_s != period_s ? period_s : 0.0;
    unsigned mine = ++t->starts;
    if (!follow) return;
    double armed_s = handler_s;
    if (armed_s < 0.0) {
        starting = 1;
        armed_s = spinner_now_uncharged();
        starting = 0;
    }
    if (!k->on || t->starts != mine) return;  /* (stopped or started again by a handler run meanwhile) */
    k->start_s = armed_s - (phased ? lead / f.hz : 0.0), k->fresh = 0;
    if (i == PIT0 || i == PIT1) {  /* the period's LDVAL from the start: one written since it, waiting
                                    * for the expiry, is the interrupt's new period */
        if (k->next_at_s > 0.0) k->load = k->next_load;
        k->next_at_s = 0.0;
    }
}

/* A running timer's registers give another interrupt than its own: a new period, or (LPTMR0, TPM2)
 * another phase of the counter to expire at. */
static int reshaped(int i, double period_s) {
    struct phase f;
    return period_s != timers[i].regular_s || (phase_of(i, &f) && f.flag_at != timers[i].ph.flag_at);
}

/* The program's LPTMR0, PIT and TPM2 (sim_timers.h): the registers with their counters now. A use
 * of a timer whose counter counts reads the time (spinner_now): with --mcu-time, in main(), the
 * program's time since its last charged call passes first - a handler due in it runs before the
 * access, as on the board - so a loop polling a counter ends; without it no time passes (a round trip
 * once a time at most, as before). A set-up of a stopped timer reads none. */
LPTMR_Type *tfc_sim_lptmr0_now(void) {
    if (lptmr_counting()) (void)spinner_now();
    lptmr_counter(0);
    return &tfc_sim_lptmr0;
}

PIT_Type *tfc_sim_pit_now(void) {
    if (pit_counting(0) || pit_counting(1)) (void)spinner_now();
    pit_counter(0, 0);
    pit_counter(1, 0);
    return &tfc_sim_pit;
}

TPM_Type *tfc_sim_tpm2_now(void) {
    if (tpm2_counting()) (void)spinner_now();
    tpm2_counter(0);
    return &tfc_sim_tpm2;
}

/* Read every timer's registers: start, stop, or note a new period (look_once), again when a handler
 * asked for a look while start() waited for the time: with --mcu-time that round trip charges the
 * program's time, so handlers due then run inside it (a program's own, another timer's expiry), and
 * a look one of them asks for (NVIC_GetPendingIRQ, a handler's end) reads the NVIC only and leaves
 * the timers to the look in progress. (It looked at them there: the timer being started, its
 * counter not yet marked started, was taken for one started again and started twice, its handler
 * called twice an expiry.) */
static int look_again;
static void look_once(void);
static void sync(void) {
    if (starting) {
        nvic_sync();
        look_again = 1;
        return;
    }
    do {
        look_again = 0;
        look_once();
    } while (look_again);
}

static void look_once(void) {
    nvic_sync();
    counters();
    for (int i = 0; i < N_TIMERS; i++) {
        struct timer *t = &timers[i];
        warn_unrouted(i);
        double period_s = period_of(i);
        if (period_s < 0.0) {
            if (irq_on(irq_of(i))) cannot(t, untimed_why);
            period_s = 0.0;  /* (its IRQ disabled: it calls nothing, on the board neither) */
        }
        void (*handler)(void) = handler_of(i);
        int isr_own = handler != NULL && spinner_has_every(handler);  /* --isr runs it */
        if (period_s > 0.0 && isr_own) period_s = 0.0;
        if (period_s > 0.0 && !irq_on(irq_of(i)) && (handler == NULL || period_s < 1e-5))
            period_s = 0.0;  /* (the errors below once its IRQ is enabled) */
        if (period_s == 0.0) {
            if (t->period_s > 0.0) stop(t, !isr_own);
            continue;
        }
        if (handler == NULL) {
            char why[200];
            snprintf(why, sizeof why, "the program defines no %s (on the board the start-up file's default "
                     "handler would take it and loop for ever)", vector_of(i));
            cannot(t, why);
        }
        if (t->period_s == 0.0) {
            start(i, period_s, 0, 0);
        } else if (reshaped(i, period_s) && t->started == waits) {  /* no time passed since its start */
            stop(t, 0);
            start(i, period_s, 1, 0);
        } else if (counter_of(i)->fresh) {  /* its counter started again while it ran (TEN cleared and set,
                                             * a write to CNT): the interrupt with it, from the start value
                                             * (the expiry it kept pending, TIF / TOF still set, runs once) */
            stop(t, 1);
            start(i, period_s, 1, 0);
        } else {  /* (a first period running: the regular one next) */
            t->next_period_s = reshaped(i, period_s) || period_s != t->period_s ? period_s : 0.0;
        }
    }
    for (int i = 0; i < N_TIMERS; i++) counter_of(i)->fresh = 0;  /* (the look is over: start) */
    if (nvic_unpend) {  /* NVIC_ClearPendingIRQ: a stopped timer's kept call does not run (a running
                         * one's source still asserts its IRQ: on the board it is pending again) */
        for (int i = 0; i < N_TIMERS; i++)
            if (timers[i].period_s == 0.0 && ((nvic_unpend >> irq_of(i)) & 1u)) spinner_unpend_every(timers[i].fire);
    }
    if (nvic_unpend || nvic_pending || nvic_handed) nvic_settle();
    nvic_unpend = 0;
}

/* NVIC_EnableIRQ, NVIC_DisableIRQ (CMSIS), enable_irq, disable_irq (the TFC library's arm_cm0.c): a
 * pending bit of the IRQ enabled is taken now, inside the call, when interrupts are unmasked. */
void tfc_sim_nvic_enable(int irq) {
    nvic_sync();
    if (irq < 0 || irq >= 32) return;
    nvic_enabled |= 1u << irq;
    nvic_disabled_at[irq] = NULL;
    if (((nvic_pending >> irq) & 1u) && !firing) sync();  /* (the look: a clear written since applies first;
                                                            * in a handler: the look after it) */
}

void tfc_sim_nvic_disable(int irq) {
    nvic_sync();
    if (irq >= 0 && irq < 32) nvic_enabled &= ~(1u << irq), nvic_disabled_at[irq] = __builtin_return_address(0);
    if (irq >= 0 && irq < 32 && ((nvic_handed >> irq) & 1u) && !firing) sync();  /* (taken back) */
}

/* NVIC_SetPendingIRQ: taken now, inside the call, if the IRQ is enabled and interrupts unmasked. */
void tfc_sim_nvic_set_pending(int irq) {
    if (irq >= 0 && irq < 32) NVIC->ISPR[0] |= 1u << irq;
    if (firing) nvic_sync();  /* (in a handler: the look after it, it runs after the handler; the bit
                               * set now, so that an NVIC_ClearPendingIRQ after it in the handler clears it) */
    else sync();
}

/* NVIC_GetPendingIRQ: the IRQ's pending bit - the kit's, or an expiry of one of its timers that
 * fell due and has not run (ARMv6-M, ARM DDI 0419, B3.4: a source that asserts while PRIMASK is set,
 * or while another exception is active, makes its interrupt pending; ISPR reads 1 until it is taken
 * or cleared). That call the simulator holds (the mask, a latched stop, or due at this step after
 * the running handler): the kit asks it (spinner_every_pending, a round trip only while masked or
 * in a handler). A clear (ICPR) holds for a stopped timer's call only, as in sync: a running one's
 * flag (TIF && TIE) asserts the IRQ again. The IRQ of the running timer handler reads the kit's bit
 * alone (on the board the active IRQ's own source does not pend it until it returns). */
uint32_t tfc_sim_nvic_pending(int irq) {
    if (firing) nvic_sync();
    else sync();
    if (irq < 0 || irq >= 32) return 0u;
    uint32_t pending = nvic_pending | nvic_handed;
    if (firing) pending &= ~nvic_unpend;  /* (a clear in the handler: applied after it) */
    if ((pending >> irq) & 1u) return 1u;
    if (!((KIT_IRQS >> irq) & 1u) || (firing && irq == firing_irq)) return 0u;
    if (!spinner_interrupts_disabled() && !spinner_in_interrupt()) return 0u;  /* (none can be held) */
    for (int i = 0; i < N_TIMERS; i++) {
        if (irq_of(i) != irq) continue;
        if (firing && ((nvic_unpend >> irq) & 1u) && !armed(i)) continue;  /* (cleared after the handler) */
        if (spinner_every_pending(timers[i].fire)) return 1u;
        /* a vector --isr runs (the kit left its timer to it): the simulator holds the vector's own call */
        if (spinner_has_every(handler_of(i)) && spinner_every_pending(handler_of(i))) return 1u;
    }
    return 0u;
}

void spinner_kit_before_wait(void) {
    if (firing) return;  /* (a handler's own requests: read when it returns) */
    waits++;
    sync();
}

/* An expiry: a new period from now on (its counter reloaded with it: start), the flag set, the
 * handler, the flag cleared. Its IRQ disabled in the NVIC (or its pending bit handed to the
 * simulator already: one bit), the flag is kept for the take and the bit set instead (ARMv6-M, ARM
 * DDI 0419, B3.4). */
static void fire(int i, volatile uint32_t *flag, uint32_t mask) {
    struct timer *t = &timers[i];
    double next = t->next_period_s;
    handler_s = spinner_now_uncharged();  /* (the handler's time: no round trip) */
    waits++;  /* (time passed since the last look: a change now is a reload, not a set-up) */
    if (next > 0.0 && t->period_s > 0.0) {
        stop(t, 0);
        start(i, next, 1, 1);
    }
    uint32_t bit = 1u << irq_of(i);
    if (!irq_on(irq_of(i)) || (nvic_handed & bit)) {
        t->flagged = 1;
        if (!(nvic_handed & bit)) nvic_pending |= bit;
        handler_s = -1.0;
        return;
    }
    *flag |= mask;
    if (i == TPM_2) TPM2->STATUS |= TPM_STATUS_TOF_MASK;  /* (STATUS TOF mirrors SC TOF, RM 31.3.5) */
    firing = 1, firing_irq = irq_of(i);
    handler_of(i)();
    firing = 0, firing_irq = -1;
    *flag &= ~mask;
    if (i == TPM_2) TPM2->STATUS &= ~TPM_STATUS_TOF_MASK;
    waits++;
    sync();
    handler_s = -1.0;
}

static void fire_pit0(void) { fire(PIT0, &PIT->CHANNEL[0].TFLG, PIT_TFLG_TIF_MASK); }
static void fire_pit1(void) { fire(PIT1, &PIT->CHANNEL[1].TFLG, PIT_TFLG_TIF_MASK); }
static void fire_lptmr(void) { fire(LPTMR, &LPTMR0->CSR, LPTMR_CSR_TCF_MASK); }
static void fire_tpm2(void) { fire(TPM_2, &TPM2->SC, TPM_SC_TOF_MASK); }

static volatile uint32_t *flag_of(int i, uint32_t *mask) {
    if (i == LPTMR) return *mask = LPTMR_CSR_TCF_MASK, &LPTMR0->CSR;
    if (i == TPM_2) return *mask = TPM_SC_TOF_MASK, &TPM2->SC;
    return *mask = PIT_TFLG_TIF_MASK, &PIT->CHANNEL[i - PIT0].TFLG;
}

/* The IRQ's pending bit taken (the simulator runs it when PRIMASK allows, its IRQ enabled): the flags
 * of its timers' expiries set, its handler once, the flags cleared (the handler's write-1-to-clear
 * taken as done). Pended in software with no expiry, the handler finds no flag set, as on the board. */
static void take(int irq) {
    uint32_t bit = 1u << irq;
    handler_s = spinner_now_uncharged();  /* (the handler's time: no round trip) */
    nvic_handed &= ~bit;
    int first = irq == IRQ_TPM2 ? TPM_2 : irq == IRQ_PIT ? PIT0 : LPTMR;
    int last = irq == IRQ_PIT ? PIT1 : first;
    if (handler_of(first) == NULL) {
        char why[200];
        snprintf(why, sizeof why, "its IRQ is pending and enabled but the program defines no %s (on the board the "
                 "start-up file's default handler would take it and loop for ever)", vector_of(first));
        cannot(&timers[first], why);
    }
    uint32_t masks[N_TIMERS] = {0};
    for (int i = first; i <= last; i++)
        if (timers[i].flagged) *flag_of(i, &masks[i]) |= masks[i];
    if (masks[TPM_2]) TPM2->STATUS |= TPM_STATUS_TOF_MASK;
    waits++;
    firing = 1, firing_irq = irq;
    handler_of(first)();
    firing = 0, firing_irq = -1;
    for (int i = first; i <= last; i++) {
        if (masks[i]) *flag_of(i, &masks[i]) &= ~masks[i];
        timers[i].flagged = 0;
    }
    if (masks[TPM_2]) TPM2->STATUS &= ~TPM_STATUS_TOF_MASK;
    waits++;
    sync();
    handler_s = -1.0;
}

static void take_tpm2(void) { take(IRQ_TPM2); }
static void take_pit(void) { take(IRQ_PIT); }
static void take_lptmr(void) { take(IRQ_LPTMR); }

/* The NVIC's pending bits after a look: ICPR clears one (and its timers' flags) unless a running
 * timer's flag asserts it again (on the board TIF && TIE keep it pending); a bit handed to the
 * simulator and not taken comes back when its IRQ is disabled or it is cleared; a pending bit of an
 * enabled IRQ is handed to it (in the order of the IRQ numbers: the NVIC's for equal priorities).
 * The simulator runs the bits handed in the order they were handed: one handed before (held by
 * __disable_irq, or after the running handler) with a higher number than a new one is handed again
 * after it; all are marked handed before the first is, as that one may run at once (inside its
 * call, whose look must not hand the others first). */
static void nvic_settle(void) {
    static const int irqs[] = {IRQ_TPM2, IRQ_PIT, IRQ_LPTMR};
    uint32_t hand = 0;
    for (int k = 0; k < 3; k++) {
        int irq = irqs[k];
        uint32_t bit = 1u << irq;
        if (nvic_unpend & bit) {
            int asserted = 0;
            for (int i = 0; i < N_TIMERS; i++)
                if (irq_of(i) == irq && timers[i].flagged && armed(i)) asserted = 1;
            if (!asserted) {
                for (int i = 0; i < N_TIMERS; i++)
                    if (irq_of(i) == irq) timers[i].flagged = 0;
                nvic_pending &= ~bit;
                if (nvic_handed & bit) spinner_unpend_every(take_of(irq)), nvic_handed &= ~bit;
            }
        }
        if ((nvic_handed & bit) && !irq_on(irq)) {
            spinner_unpend_every(take_of(irq));
            nvic_handed &= ~bit, nvic_pending |= bit;
        }
        if ((nvic_pending & bit) && irq_on(irq)) nvic_pending &= ~bit, hand |= bit;
    }
    if (hand == 0) return;
    uint32_t lowest = hand & (~hand + 1u), again = nvic_handed & ~(lowest | (lowest - 1u));
    for (int k = 0; k < 3; k++)
        if ((again >> irqs[k]) & 1u) spinner_unpend_every(take_of(irqs[k]));
    hand |= again;
    nvic_handed |= hand;
    for (int k = 0; k < 3; k++)  /* (one taken at once may have its handler disable or clear the next) */
        if (((hand & nvic_handed) >> irqs[k]) & 1u) spinner_pend_every(take_of(irqs[k]));
}

/* TFC_InitADCs (TFC_Init calls it): the library's camera timing on PIT channel 0 leaves the PIT
 * module enabled and its IRQ on in the NVIC - the FRDM-TFC library's TFC_ADC.c, InitPIT: SIM_SCGC6 |=
 * SIM_SCGC6_PIT_MASK; PIT_MCR |= PIT_MCR_FRZ_MASK; PIT_MCR &= ~PIT_MCR_MDIS_MASK; enable_irq(INT_PIT-16)
 * (RM 32.3.1 MCR: MDIS set out of reset) - so a channel the program sets up after it interrupts
 * without a PIT_MCR write or an NVIC_EnableIRQ of its own, as on the board. Channel 0's registers stay
 * the program's: the kit reads the camera itself (tfc.c), and the library's PIT_IRQHandler is not
 * there. */
void tfc_sim_timers_library_pit(void) {
    SIM->SCGC6 |= SIM_SCGC6_PIT_MASK;
    PIT->MCR = (PIT->MCR | PIT_MCR_FRZ_MASK) & ~PIT_MCR_MDIS_MASK;
    tfc_sim_nvic_enable(IRQ_PIT);
}

/* TFC_Init: the TPM clock as the library's servo and motor set-up selects it (MCGPLLCLK/2). */
void tfc_sim_timers_init(void) {
    SIM->SOPT2 = (SIM->SOPT2 & ~SIM_SOPT2_TPMSRC_MASK) | SIM_SOPT2_PLLFLLSEL_MASK | SIM_SOPT2_TPMSRC(1);
}
