/* The RTD's Gpt channels on the simulated car (the simulator's S32K144 kit; include/Gpt.h;
 * docs/firmware.md, "The S32K144 kit" and "Timer interrupts").
 *
 * A channel counts simulated time in ticks of the kit's Gpt clock, --param s32k_gpt_tick_hz
 * (default 8 MHz: the channel tick frequency github.com/michalfrohlich/NXP-Cup-EXPO's
 * src/timebase.c notes for its sample-based configuration, "GPT channel 2 is configured in
 * ConfigTools at 8 MHz tick frequency"), from Gpt_StartTimer. The channel states and reads are the
 * AUTOSAR SWS General Purpose Timer's (Gpt_GetTimeElapsed, Gpt_GetTimeRemaining, Gpt_StartTimer):
 * running, a continuous channel wrapping at its target, a one-shot channel expiring there (it then
 * reads the target elapsed and 0 remaining); stopped, the count at the stop; never started, 0. A
 * start of a running channel is refused (GPT_E_BUSY: the RTD reports it and keeps the channel as it
 * is; here a warning of the run), a start of 0 ticks ends the run at the calling line
 * (GPT_E_PARAM_VALUE). The mode is the generated configuration's (GPT_CH_MODE_CONTINUOUS /
 * GPT_CH_MODE_ONESHOT in Gpt_VS_0_PBcfg.c, which the build does not see): -D GPT_CHANNEL_MODE_<n>=
 * GPT_CH_MODE_ONESHOT makes channel n one-shot; continuous otherwise. Its notification is the
 * function the kit's Gpt configuration names for it (below): once the channel runs and its
 * notification is enabled, it is called at each expiry (spinner_every; a one-shot's once), until
 * Gpt_StopTimer or Gpt_DisableNotification. A one-shot channel's interrupt is the kit's timer from
 * its start, notification or not: it sets the channel expired (below, elapsed_at). A notification
 * that --isr (or spinner_every) already runs is left to that: its rate is --isr's. The reads let no
 * simulated time pass (spinner_now: the count at the program's last call, or at a handler's time;
 * with --mcu-time a read of main()'s is charged, the program's time since its last call passing
 * first), but after 64 reads without any time passing each read lets one physics step pass (main()
 * only), so a loop polling them moves on. */
#include <stdio.h>

#include "spinner.h"
#include "Gpt.h"
#include "sim_poll.h"

/* The kit's Gpt configuration: the notification of each channel, as the sample project's generated
 * generate/src/Gpt_VS_0_PBcfg.c names them (channel 0, Receiver_Timeout: Gpt_Notification; channel
 * 1, LinearCameraShutter: NewCameraFrame, the camera driver's own, which the kit's camera needs not);
 * a channel of your own configuration: -D GPT_NOTIFICATION_<n>=NAME (n = 0..7), the name your
 * configuration gives its notification. */
#define GPT_NOTIFIED 8
#ifndef GPT_NOTIFICATION_0
#define GPT_NOTIFICATION_0 Gpt_Notification
#endif
#define STR_(x) #x
#define STR(x) STR_(x)
#define DECLARE(fn) extern void fn(void) __attribute__((weak));
DECLARE(GPT_NOTIFICATION_0)
#define N0 GPT_NOTIFICATION_0, STR(GPT_NOTIFICATION_0)
#ifdef GPT_NOTIFICATION_1
DECLARE(GPT_NOTIFICATION_1)
#define N1 GPT_NOTIFICATION_1, STR(GPT_NOTIFICATION_1)
#else
#define N1 NULL, NULL
#endif
#ifdef GPT_NOTIFICATION_2
DECLARE(GPT_NOTIFICATION_2)
#define N2 GPT_NOTIFICATION_2, STR(GPT_NOTIFICATION_2)
#else
#define N2 NULL, NULL
#endif
#ifdef GPT_NOTIFICATION_3
DECLARE(GPT_NOTIFICATION_3)
#define N3 GPT_NOTIFICATION_3, STR(GPT_NOTIFICATION_3)
#else
#define N3 NULL, NULL
#endif
#ifdef GPT_NOTIFICATION_4
DECLARE(GPT_NOTIFICATION_4)
#define N4 GPT_NOTIFICATION_4, STR(GPT_NOTIFICATION_4)
#else
#define N4 NULL, NULL
#endif
#ifdef GPT_NOTIFICATION_5
DECLARE(GPT_NOTIFICATION_5)
#define N5 GPT_NOTIFICATION_5, STR(GPT_NOTIFICATION_5)
#else
#define N5 NULL, NULL
#endif
#ifdef GPT_NOTIFICATION_6
DECLARE(GPT_NOTIFICATION_6)
#define N6 GPT_NOTIFICATION_6, STR(GPT_NOTIFICATION_6)
#else
#define N6 NULL, NULL
#endif
#ifdef GPT_NOTIFICATION_7
DECLARE(GPT_NOTIFICATION_7)
#define N7 GPT_NOTIFICATION_7, STR(GPT_NOTIFICATION_7)
#else
#define N7 NULL, NULL
#endif

#define NUM_GPT 256

/* The channels' modes, as -D GPT_CHANNEL_MODE_<n> gives them (continuous by default). */
#define MODE_(n) (GPT_CHANNEL_MODE_##n + 0 == GPT_CH_MODE_ONESHOT)
#ifndef GPT_CHANNEL_MODE_0
#define GPT_CHANNEL_MODE_0 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_1
#define GPT_CHANNEL_MODE_1 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_2
#define GPT_CHANNEL_MODE_2 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_3
#define GPT_CHANNEL_MODE_3 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_4
#define GPT_CHANNEL_MODE_4 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_5
#define GPT_CHANNEL_MODE_5 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_6
#define GPT_CHANNEL_MODE_6 GPT_CH_MODE_CONTINUOUS
#endif
#ifndef GPT_CHANNEL_MODE_7
#define GPT_CHANNEL_MODE_7 GPT_CH_MODE_CONTINUOUS
#endif
int s32k_sim_esc_timers(void);  /* s32k144.c: the ESC driver's state machine's timer, 0 or 1 */

static const unsigned char one_shot[GPT_NOTIFIED] = {MODE_(0), MODE_(1), MODE_(2), MODE_(3), MODE_(4), MODE_(5),
                                                     MODE_(6), MODE_(7)};

/* The generated configuration's names: Gpt_Init takes any (the kit's configuration is above). */
struct Gpt_ConfigType { uint8 unused; };
const Gpt_ConfigType Gpt_Config_VS_0, Gpt_Config;

static void notify(int ch);
#define FIRE(n) static void fire##n(void) { notify(n); }
FIRE(0) FIRE(1) FIRE(2) FIRE(3) FIRE(4) FIRE(5) FIRE(6) FIRE(7)

static const struct {
    void (*fn)(void);       /* the notification, NULL when the program defines none */
    const char *name;       /* its name in the configuration (NULL: none configured) */
    void (*fire)(void);     /* the kit's function spinner_every calls (the channel's interrupt) */
} config[GPT_NOTIFIED] = {
    {N0, fire0}, {N1, fire1}, {N2, fire2}, {N3, fire3}, {N4, fire4}, {N5, fire5}, {N6, fire6}, {N7, fire7},
};

enum { INITIALIZED, RUNNING, STOPPED, EXPIRED };  /* the SWS's channel states */

static struct {
    double tick_hz;
    int inited;
    int own;                /* the kit's timers running (spinner_every): notifications, one-shots' interrupts */
    SimPoll poll;           /* main()'s reads at one time (sim_poll.h) */
    struct { double start_s; Gpt_ValueType target, frozen; uint8 state, notify, every; } ch[NUM_GPT];
} g;

static void init(void) {
    if (g.inited) return;
    g.inited = 1;
    g.tick_hz = spinner_param("s32k_gpt_tick_hz", 8e6);
}

static int is_one_shot(Gpt_ChannelType c) { return c < GPT_NOTIFIED && one_shot[c]; }

/* The notification's call: enabled, the program's function, not left to --isr (or spinner_every). */
static int notified(Gpt_ChannelType c) {
    return c < GPT_NOTIFIED && g.ch[c].notify && config[c].fn != NULL && !spinner_has_every(config[c].fn);
}

/* The channel's interrupt (the kit's timer): a one-shot's expires it, then notifies (SWS, one-shot
 * mode) if its notification is enabled then; a continuous one's timer runs only to notify. */
static void notify(int ch) {
    if (is_one_shot((Gpt_ChannelType)ch)) {
        if (!g.ch[ch].every) return;  /* stopped since it fell due (a call the host still ran, spinner.h): the
                                       * later call set the channel's state (Gpt_DeInit runs a due one first) */
        g.ch[ch].state = EXPIRED;
        spinner_stop_every(config[ch].fire);
        g.ch[ch].every = 0;
        g.own--;
        if (!notified((Gpt_ChannelType)ch)) return;
    }
    config[ch].fn();
}

static void quiet(Gpt_ChannelType c) {
    if (c < GPT_NOTIFIED && g.ch[c].every) {
        spinner_stop_every(config[c].fire);
        g.ch[c].every = 0;
        g.own--;
    }
}

/* The period of channel c's timer: its target; under the simulator's 10 us an error when it notifies,
 * else (a one-shot's interrupt only) 10 us - the reads past its target give it expired, unless held. */
static double period_of(Gpt_ChannelType c) {
    double period_s = g.ch[c].target / g.tick_hz;
    if (period_s < 1e-5 && notified(c)) {
        char text[300];
        snprintf(text, sizeof text, "Gpt channel %u: a period of %u ticks at %.6g Hz (--param s32k_gpt_tick_hz) "
                 "is shorter than the simulator's 10 us (a 100 kHz timer)", (unsigned)c, (unsigned)g.ch[c].target,
                 g.tick_hz);
        spinner_fail(text);
    }
    return period_s < 1e-5 ? 1e-5 : period_s;
}

/* Start or stop the channel's timer as its state says (a start: from now): a running channel's
 * notification calls; a running one-shot's interrupt, notification or not (it sets it expired, as
 * the RTD's Gpt_StartTimer enables a one-shot channel's interrupt for that: S32K1 RTD 2.0.0 Gpt.c). */
static void arm(Gpt_ChannelType c) {
    quiet(c);
    if (g.ch[c].state != RUNNING || c >= GPT_NOTIFIED || !(is_one_shot(c) || notified(c))) return;
    spinner_every(period_of(c), config[c].fire);
    g.ch[c].every = 1;
    g.own++;
}

/* The simulated time of a read: now, no time passing, unless main() reads at one time again and
 * again (a poll), where each read after SIM_POLLS_FREE lets one physics step pass. */
static double read_time(void) {
    return sim_poll_time(&g.poll);
}

/* Non-zero while an interrupt due now would be held: masked (__disable_irq, OsIf_SuspendAllInterrupts)
 * or inside a handler (the next one runs after it returns). */
static int interrupts_held(void) { return spinner_interrupts_disabled() || spinner_in_interrupt(); }

/* Channel c's elapsed ticks at time now_s. A one-shot past its target reads the target; it turns
 * expired in its interrupt, as the RTD's does, with its notification or without (S32K1 RTD 2.0.0
 * Gpt.c: Gpt_StartTimer enables a one-shot channel's interrupt, Gpt_ProcessCommonInterrupt sets
 * GPT_STATUS_EXPIRED, then notifies if the notification is enabled). That is notify(), the kit's
 * timer from the start, which the simulator runs at the expiry or, held by disabled interrupts or a
 * running handler, at the unmask or after the handler - until then the driver has it running
 * (Gpt_GetTimeElapsed's rollover case: the target elapsed, 0 remaining; Gpt_StartTimer refuses it,
 * GPT_E_BUSY). Not held, a read past its target finds it expired (its interrupt due at this step
 * follows). */
static Gpt_ValueType elapsed_at(Gpt_ChannelType c, double now_s) {
    if (g.ch[c].state == STOPPED) return g.ch[c].frozen;
    if (g.ch[c].state == EXPIRED) return g.ch[c].target;
    if (g.ch[c].state != RUNNING) return 0U;
    uint64_t n = (uint64_t)((now_s - g.ch[c].start_s) * g.tick_hz + 1e-6);
    if (is_one_shot(c) && n >= g.ch[c].target) {
        if (!(g.ch[c].every && interrupts_held())) g.ch[c].state = EXPIRED;  /* (its interrupt due at this step follows) */
        return g.ch[c].target;
    }
    return (Gpt_ValueType)(n % g.ch[c].target);
}

void Gpt_Init(const Gpt_ConfigType *ConfigPtr) {
    (void)ConfigPtr;
    Gpt_DeInit();
}

void Gpt_DeInit(void) {
    init();
    if (g.own > 0) (void)spinner_now();  /* with --mcu-time, the code's time before it passes first: an
                                          * interrupt due in it runs before the channels are reset, as on
                                          * the board (a stop queued after it would leave it to run after) */
    for (int c = 0; c < NUM_GPT; c++) {
        quiet((Gpt_ChannelType)c);
        g.ch[c].state = INITIALIZED, g.ch[c].notify = 0U;
    }
}

void Gpt_StartTimer(Gpt_ChannelType Channel, Gpt_ValueType Value) {
    init();
    if (Value == 0U) {
        char text[200];
        snprintf(text, sizeof text, "Gpt_StartTimer(%u, 0): a target of 0 ticks (the RTD refuses it: "
                 "GPT_E_PARAM_VALUE); expected 1 or more", (unsigned)Channel);
        spinner_fail(text);
    }
    double now = spinner_now();
    if (g.ch[Channel].state == RUNNING && !(elapsed_at(Channel, now), g.ch[Channel].state == EXPIRED)) {
        char text[400];
        snprintf(text, sizeof text, "Gpt_StartTimer(%u, ...) on a running channel was refused, as the RTD "
                 "refuses it (GPT_E_BUSY): the channel keeps its target and count; stop it first "
                 "(Gpt_StopTimer)%s", (unsigned)Channel,
                 is_one_shot(Channel) && elapsed_at(Channel, now) == g.ch[Channel].target
                     ? " (a one-shot channel is running until its interrupt has run: its expiry is held by "
                       "disabled interrupts or a running handler)" : "");
        spinner_warn(text);
        return;
    }
    g.ch[Channel].start_s = now;
    g.ch[Channel].target = Value;
    g.ch[Channel].state = RUNNING;
    arm(Channel);
    if (g.ch[Channel].every) {  /* it counts from the time its interrupt is timed from: with --mcu-time the
                                 * simulator charges the timer's request (spinner_every) before it starts it
                                 * (else no time passes: the same time, no round trip) */
        double armed_at = spinner_now_uncharged();
        if (g.ch[Channel].state == RUNNING && g.ch[Channel].start_s == now) g.ch[Channel].start_s = armed_at;
    }
}

void Gpt_StopTimer(Gpt_ChannelType Channel) {
    init();
    if (g.ch[Channel].state != RUNNING) return;
    Gpt_ValueType at = elapsed_at(Channel, spinner_now());
    if (g.ch[Channel].state == RUNNING) {  /* a one-shot past its target (its interrupt held): expired,
                                            * its notification dropped (the RTD's Gpt_StopTimer; the
                                            * LPIT's Lpit_Gpt_Ip_StopTimer clears the channel's flag) */
        if (is_one_shot(Channel) && at == g.ch[Channel].target) g.ch[Channel].state = EXPIRED;
        else g.ch[Channel].state = STOPPED, g.ch[Channel].frozen = at;
    }
    quiet(Channel);
}

Gpt_ValueType Gpt_GetTimeElapsed(Gpt_ChannelType Channel) {
    init();
    return elapsed_at(Channel, read_time());
}

Gpt_ValueType Gpt_GetTimeRemaining(Gpt_ChannelType Channel) {
    init();
    Gpt_ValueType elapsed = elapsed_at(Channel, read_time());
    int state = g.ch[Channel].state;
    return state == RUNNING || state == STOPPED ? g.ch[Channel].target - elapsed : 0U;
}

void Gpt_EnableNotification(Gpt_ChannelType Channel) {
    init();
    g.ch[Channel].notify = 1U;
    void (*fn)(void) = Channel < GPT_NOTIFIED ? config[Channel].fn : NULL;
    if (fn == NULL && spinner_interrupts() - g.own - s32k_sim_esc_timers() <= 0) {  /* nothing the kit or --isr calls */
        const char *name = Channel < GPT_NOTIFIED ? config[Channel].name : NULL;
        char text[600];
        if (name != NULL)
            snprintf(text, sizeof text, "Gpt_EnableNotification: channel %u's notification %s (the kit's Gpt "
                     "configuration) is not a function of the program; give yours as -D GPT_NOTIFICATION_%u=NAME, or "
                     "its rate as --isr NAME@HZ (docs/firmware.md, \"Timer interrupts\")", (unsigned)Channel, name,
                     (unsigned)Channel);
        else
            snprintf(text, sizeof text, "Gpt_EnableNotification: channel %u has no notification in the kit's Gpt "
                     "configuration; name yours as your generated configuration does, -D GPT_NOTIFICATION_%u=NAME "
                     "(channels 0..%d), or give it with its rate as --isr NAME@HZ (docs/firmware.md, \"Timer "
                     "interrupts\")", (unsigned)Channel, (unsigned)Channel, GPT_NOTIFIED - 1);
        spinner_fail(text);
    }
    if (!is_one_shot(Channel)) arm(Channel);
    else if (g.ch[Channel].every) (void)period_of(Channel);  /* its interrupt notifies from now on */
}

void Gpt_DisableNotification(Gpt_ChannelType Channel) {
    g.ch[Channel].notify = 0U;
    if (!is_one_shot(Channel)) quiet(Channel);  /* a one-shot's interrupt stays: it sets it expired */
}
