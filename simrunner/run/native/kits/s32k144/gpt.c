/* The RTD's Gpt channels on the simulated car (the simulator's S32K144 kit; include/Gpt.h;
 * docs/firmware.md, "The S32K144 kit" and "Timer interrupts").
 *
 * A channel counts simulated time in ticks of the kit's Gpt clock, --param s32k_gpt_tick_hz
 * (default 8 MHz: the channel tick frequency github.com/michalfrohlich/NXP-Cup-EXPO's
 * src/timebase.c notes for its sample-based configuration, "GPT channel 2 is configured in
 * ConfigTools at 8 MHz tick frequency"), from Gpt_StartTimer, wrapping at its target (a continuous
 * channel). Its notification is the function the kit's Gpt configuration names for it (below):
 * once the channel runs and its notification is enabled, it is called every target ticks of
 * simulated time (spinner_every), until Gpt_StopTimer or Gpt_DisableNotification. A notification
 * that --isr (or spinner_every) already runs is left to that: its rate is --isr's. */
#include <stdio.h>

#include "spinner.h"
#include "Gpt.h"

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

static void notify(int ch);
#define FIRE(n) static void fire##n(void) { notify(n); }
FIRE(0) FIRE(1) FIRE(2) FIRE(3) FIRE(4) FIRE(5) FIRE(6) FIRE(7)

static const struct {
    void (*fn)(void);       /* the notification, NULL when the program defines none */
    const char *name;       /* its name in the configuration (NULL: none configured) */
    void (*fire)(void);     /* the kit's function spinner_every calls */
} config[GPT_NOTIFIED] = {
    {N0, fire0}, {N1, fire1}, {N2, fire2}, {N3, fire3}, {N4, fire4}, {N5, fire5}, {N6, fire6}, {N7, fire7},
};

static struct {
    double tick_hz;
    int inited;
    int own;                /* notifications the kit runs (spinner_every) */
    struct { double start_s; Gpt_ValueType target; uint8 running, notify, every; } ch[NUM_GPT];
} g;

static void init(void) {
    if (g.inited) return;
    g.inited = 1;
    g.tick_hz = spinner_param("s32k_gpt_tick_hz", 8e6);
}

static void notify(int ch) { config[ch].fn(); }

static void quiet(Gpt_ChannelType c) {
    if (c < GPT_NOTIFIED && g.ch[c].every) {
        spinner_stop_every(config[c].fire);
        g.ch[c].every = 0;
        g.own--;
    }
}

/* Start or stop the channel's notification calls as its state says (a start: from now). */
static void arm(Gpt_ChannelType c) {
    quiet(c);
    if (!g.ch[c].running || !g.ch[c].notify || g.ch[c].target == 0U) return;
    if (c >= GPT_NOTIFIED || config[c].fn == NULL || spinner_has_every(config[c].fn)) return;
    double period_s = g.ch[c].target / g.tick_hz;
    if (period_s < 1e-5) {
        char text[300];
        snprintf(text, sizeof text, "Gpt channel %u: a period of %u ticks at %.6g Hz (--param s32k_gpt_tick_hz) "
                 "is shorter than the simulator's 10 us (a 100 kHz timer)", (unsigned)c, (unsigned)g.ch[c].target,
                 g.tick_hz);
        spinner_fail(text);
    }
    spinner_every(period_s, config[c].fire);
    g.ch[c].every = 1;
    g.own++;
}

void Gpt_StartTimer(Gpt_ChannelType Channel, Gpt_ValueType Value) {
    init();
    g.ch[Channel].start_s = spinner_get_time();
    g.ch[Channel].target = Value;
    g.ch[Channel].running = 1U;
    arm(Channel);
}

void Gpt_StopTimer(Gpt_ChannelType Channel) {
    g.ch[Channel].running = 0U;
    quiet(Channel);
}

Gpt_ValueType Gpt_GetTimeElapsed(Gpt_ChannelType Channel) {
    init();
    double now = spinner_get_time();  /* a physics step passes, as OsIf_GetMilliseconds */
    if (!g.ch[Channel].running) return 0U;
    uint64_t n = (uint64_t)((now - g.ch[Channel].start_s) * g.tick_hz + 1e-6);
    return g.ch[Channel].target > 0U ? (Gpt_ValueType)(n % g.ch[Channel].target) : 0U;
}

Gpt_ValueType Gpt_GetTimeRemaining(Gpt_ChannelType Channel) {
    Gpt_ValueType elapsed = Gpt_GetTimeElapsed(Channel);
    return g.ch[Channel].running ? g.ch[Channel].target - elapsed : 0U;
}

void Gpt_EnableNotification(Gpt_ChannelType Channel) {
    init();
    g.ch[Channel].notify = 1U;
    void (*fn)(void) = Channel < GPT_NOTIFIED ? config[Channel].fn : NULL;
    if (fn == NULL && spinner_interrupts() - g.own <= 0) {  /* nothing the kit or --isr calls */
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
    arm(Channel);
}

void Gpt_DisableNotification(Gpt_ChannelType Channel) {
    g.ch[Channel].notify = 0U;
    quiet(Channel);
}
