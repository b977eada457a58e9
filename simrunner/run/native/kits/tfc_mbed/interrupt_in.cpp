/* mbed's InterruptIn on the FRDM-KL25Z of the mbed kit (simrunner drive main.cpp --kit tfc-mbed;
 * include/InterruptIn.h): a pin's rising and falling edges call the program's handlers. Our own
 * code, on spinner.h.
 * - which pins: the KL25Z's pins interrupt on ports A and D only (KL25 Sub-Family Reference
 *   Manual, KL25P80M48SF0RM, ch. 3, interrupt channel assignments: IRQ 30 port A, IRQ 31 port D,
 *   no other port; mbed's KL25Z gpio_irq_api.c stops with "gpio_irq only supported on port A and
 *   D"): an InterruptIn on another port ends the run at the program's first call to it;
 * - what is on a pin: --param encoder_PTxN=W puts channel A of wheel W's encoder (0..3: FL, FR,
 *   RL, RR; the car file's [encoders]) on pin PTxN, encoder_b_PTxN=W its channel B,
 *   encoder_z_PTxN=W its index channel Z. The car's counter gives the wheel's position: counting x4
 *   (the default) in quarter lines, both channels' levels (the sequence 00 01 11 10 of (A, B)
 *   counting up, as QEI.h's state); x2 in half lines, channel A's; x1 and single in lines: each
 *   line is a rise and a fall of channel A (its level between them is not known: it reads 0). The
 *   index is high once a revolution, at the wheel's angle at the start (count 0 and every lines x
 *   counts-a-line after), for one count of the counter: at x4 the quarter line where A and B are
 *   both low, as an incremental encoder's gated index (US Digital EM2 datasheet, "Encoding
 *   characteristics": "The index output goes high once per revolution, coincident with the low
 *   states of channels A and B, nominally 1/4 of one cycle (90 °e)", Po 40..135 °e); at x2 the half
 *   line where A is low (180 °e), at x1 the whole line (360 °e); QEI.h's getRevolutions() counts its
 *   rises (../sensors.cpp). A one-channel counter (single) counts without direction: no index.
 *   Any other pin keeps its level (DigitalIn's --param digital_PTxN): it gives no edges;
 * - when: at each tick of the kit's 1-kHz clock, before the Tickers due then, the handlers of the
 *   edges of the millisecond gone run in the order they fell (wheel by wheel, FL to RR; the pins
 *   of one edge in the order their InterruptIns were made), each with the pin's level at its
 *   edge; no time passes in them (they are interrupts);
 * - disable_irq()/enable_irq(): the port's interrupt (the NVIC's PORTA or PORTD, as mbed's KL25Z
 *   code does: every InterruptIn of the port); an edge meanwhile sets the pin's flag, which calls
 *   its handler once at the first tick after enable_irq() (mbed's handler clears the flag). */
#include <stdio.h>
#include <string.h>

#include "spinner.h"
#include "tfc_mbed_sim.h"

#define MAX_IRQS 32
#define NUM_PINS (5 * 32)  /* ports A..E, 32 pins each */
#define PORT_A 0
#define PORT_D 3
#define NC_PIN ((int)0xFFFFFFFF)

enum { UNKNOWN = 0, FREE, ENCODER, BAD };
enum { CHANNEL_A = 0, CHANNEL_B, CHANNEL_Z };

static struct {
    struct { int state, wheel, channel; } pin[NUM_PINS];  /* what --param puts on each pin */
    char why[NUM_PINS][240];      /* a BAD pin's reason */
    int tracked[4], seen[4];      /* a wheel whose pins are read; its count sampled once */
    long long count[4];           /* its count as the edges have got to */
    int per_line[4];              /* its counter's counts a line (4, 2, 1; 0: single) */
    long long per_rev[4];         /* its counter's counts a revolution (lines x counts a line) */
    int disabled[5];              /* a port's interrupt disabled (disable_irq) */
    struct tfc_mbed_irq *irq[MAX_IRQS];  /* in the order they were made */
    int n_irq, hooked;
    int at;                       /* the index a dispatch loop is at (detach moves it back) */
} s;

static int port_of(int pin) { return (pin >> 12) & 7; }
static int index_of(int pin) { return pin == NC_PIN || port_of(pin) > 4 ? -1 : port_of(pin) * 32 + ((pin >> 2) & 31); }

/* A channel's level at count c of a counter counting m a line. */
static int level_at(int m, int channel, long long c) {
    int q = (int)(c & 3);
    if (m == 4) return channel ? (q == 1 || q == 2) : q >= 2;
    return m == 2 ? (int)(c & 1) : 0;
}

/* A pin's level on wheel w at count c: channel A's or B's, or the index's (high at counts that are
 * whole revolutions from the start: one count of the counter a revolution). */
static int level_of(int w, int channel, long long c) {
    return channel == CHANNEL_Z ? c % s.per_rev[w] == 0 : level_at(s.per_line[w], channel, c);
}

static void on_edges(void);

static void hook(void) {
    if (!s.hooked) {
        s.hooked = 1;
        tfc_mbed_on_edges(on_edges);
    }
}

/* What --param puts on pin i (PTxN): a wheel's encoder channel, nothing, or a reason it cannot. */
static void resolve(int i) {
    static const char *names[4] = {"FL", "FR", "RL", "RR"};
    static const char *counting[5] = {"single", "x1", "x2", "?", "x4"};
    if (s.pin[i].state != UNKNOWN) return;
    static const char *prefix[3] = {"encoder_", "encoder_b_", "encoder_z_"};
    char names_of[3][32], fitted[16] = "";
    double given[3];
    int channel = -1, other = -1, n = 0, m = 0;
    for (int k = 0; k < 3; k++) {  /* channel A, B, Z */
        snprintf(names_of[k], sizeof names_of[k], "%sPT%c%d", prefix[k], 'A' + i / 32, i % 32);
        given[k] = spinner_param(names_of[k], -1.0);
        if (given[k] < 0) continue;
        if (channel < 0) channel = k;
        else if (other < 0) other = k;
    }
    if (channel < 0) {
        s.pin[i].state = FREE;
        return;
    }
    const char *name = names_of[channel];
    double w = given[channel];
    for (int k = 0; k < 4; k++) {
        if (spinner_encoder_lines(k, NULL) == 0) continue;
        strcat(strcat(fitted, n++ ? " " : ""), names[k]);
    }
    int lines = w <= 3 && w == (int)w ? spinner_encoder_lines((int)w, &m) : 0;
    char *why = s.why[i];
    if (other >= 0)
        snprintf(why, sizeof s.why[i], "--param %s and %s: a pin carries one channel", name, names_of[other]);
    else if (n == 0)
        snprintf(why, sizeof s.why[i], "--param %s: the car has no wheel encoders: add [encoders] to the car "
                 "file (docs/car.md)", name);
    else if (lines == 0)
        snprintf(why, sizeof s.why[i], "--param %s=%g: expected a wheel with an encoder (0..3: FL, FR, RL, RR; "
                 "this car has them on %s)", name, w, fitted);
    else if (channel == CHANNEL_B && m != 4)
        snprintf(why, sizeof s.why[i], "--param %s: channel B's edges need the car's counter to count both "
                 "channels (encoders.counting = \"x4\"; this car's: \"%s\")", name, counting[m]);
    else if (channel == CHANNEL_Z && m == 0)
        snprintf(why, sizeof s.why[i], "--param %s: the index channel needs the wheel's angle, which a "
                 "one-channel counter does not keep (encoders.counting = \"single\" counts without "
                 "direction): count \"x4\", \"x2\" or \"x1\"", name);
    else {
        s.pin[i].state = ENCODER, s.pin[i].wheel = (int)w, s.pin[i].channel = channel;
        s.tracked[(int)w] = 1, s.per_line[(int)w] = m, s.per_rev[(int)w] = (long long)lines * (m ? m : 1);
        hook();
        return;
    }
    s.pin[i].state = BAD;
}

/* Call q's handler of this edge, or set its flag while its port's interrupt is disabled. */
static void edge(struct tfc_mbed_irq *q, int rising) {
    if (!(rising ? q->on_rise : q->on_fall)) return;
    if (s.disabled[port_of(q->pin)]) q->pending = 1;
    else q->call(q->obj, rising);
}

/* Wheel w's count moves to c one count at a time; each move's edges go to the pins on w. */
static void move(int w, long long c) {
    int m = s.per_line[w];
    while (s.count[w] != c) {
        long long before = s.count[w];
        s.count[w] += c > before ? 1 : -1;
        for (s.at = 0; s.at < s.n_irq; s.at++) {
            struct tfc_mbed_irq *q = s.irq[s.at];
            int i = index_of(q->pin);
            if (i < 0 || s.pin[i].state != ENCODER || s.pin[i].wheel != w) continue;
            /* channel A counted a line at a time: a rise and a fall (not if the rise's handler deleted it) */
            if (m < 2 && s.pin[i].channel == CHANNEL_A) {
                edge(q, 1);
                if (s.at >= 0 && s.irq[s.at] == q) edge(q, 0);
                continue;
            }
            int was = level_of(w, s.pin[i].channel, before), now = level_of(w, s.pin[i].channel, s.count[w]);
            if (was != now) edge(q, now);
        }
    }
}

static void sample(int w) {
    long long c = spinner_get_encoder(w);
    if (!s.seen[w]) {
        s.seen[w] = 1;
        s.count[w] = c;  /* the first sample: the levels from here, no edges */
        return;
    }
    move(w, c);
}

static int pin_level(int i) {
    int w = s.pin[i].wheel;
    if (!s.seen[w]) {
        if (tfc_mbed_in_isr()) sample(w);
        else while (!s.seen[w]) tfc_mbed_idle();  /* main(): the first tick that reads it */
    }
    return level_of(w, s.pin[i].channel, s.count[w]);
}

/* At each tick of the kit's clock: the flags of re-enabled ports, then the wheels' edges. */
static void on_edges(void) {
    for (s.at = 0; s.at < s.n_irq; s.at++) {
        struct tfc_mbed_irq *q = s.irq[s.at];
        if (!q->pending || s.disabled[port_of(q->pin)]) continue;
        q->pending = 0;
        int i = index_of(q->pin);
        int rising = q->on_rise && q->on_fall ? (s.pin[i].state == ENCODER && pin_level(i)) : q->on_rise;
        if (rising ? q->on_rise : q->on_fall) q->call(q->obj, rising);
    }
    for (int w = 0; w < 4; w++) if (s.tracked[w]) sample(w);
}

[[noreturn]] static void fail(const char *what, const char *why) {
    char msg[400];
    snprintf(msg, sizeof msg, "%s: %s", what, why);
    spinner_fail(msg);
}

/* q's pin as a program's call finds it: on a port that interrupts, its --param valid. */
static void check(struct tfc_mbed_irq *q, const char *what) {
    tfc_mbed_start();
    if (!tfc_mbed_started()) return;  /* (loaded before the run: spinner_running) */
    int i = index_of(q->pin);
    if (i < 0) return;  /* NC: no pin, no edges */
    if (port_of(q->pin) != PORT_A && port_of(q->pin) != PORT_D) {
        char why[240];
        snprintf(why, sizeof why, "PT%c%d: the KL25Z's pins interrupt on ports A and D only (mbed stops with "
                 "\"gpio_irq only supported on port A and D\"): use a pin of port A or D", 'A' + i / 32, i % 32);
        fail(what, why);
    }
    resolve(i);
    if (s.pin[i].state == BAD) fail(what, s.why[i]);
}

void tfc_mbed_irq_attach(struct tfc_mbed_irq *q, int pin) {
    q->pin = pin, q->on_rise = q->on_fall = q->pending = 0;
    if (s.n_irq == MAX_IRQS) spinner_fail("InterruptIn: more than 32 at once");
    s.irq[s.n_irq++] = q;
    if (index_of(pin) >= 0) s.disabled[port_of(pin)] = 0;  /* mbed's gpio_irq_init enables the port's */
    hook();
}

/* An InterruptIn destroyed (in a handler too): the others keep their order, the order they were made
 * in; a dispatch loop under way (s.at) goes on with the one after it, so none misses the edge. */
void tfc_mbed_irq_detach(struct tfc_mbed_irq *q) {
    for (int k = 0; k < s.n_irq; k++) {
        if (s.irq[k] != q) continue;
        memmove(&s.irq[k], &s.irq[k + 1], (size_t)(s.n_irq - k - 1) * sizeof s.irq[0]);
        s.n_irq--;
        if (k <= s.at) s.at--;
        return;
    }
}

void tfc_mbed_irq_set(struct tfc_mbed_irq *q, int on_rise, int on_fall, const char *what) {
    check(q, what);
    if (on_rise >= 0) q->on_rise = on_rise;
    if (on_fall >= 0) q->on_fall = on_fall;
    int i = index_of(q->pin);
    if (i >= 0 && s.pin[i].state == FREE && (on_rise > 0 || on_fall > 0)) {  /* once per pin */
        char text[300];
        snprintf(text, sizeof text, "InterruptIn on PT%c%d: its handler never runs: no --param "
                 "encoder_PT%c%d=W (or encoder_b_PT%c%d=W, encoder_z_PT%c%d=W) puts a wheel's encoder "
                 "channel on the pin (docs/firmware.md, --kit tfc-mbed)", 'A' + i / 32, i % 32, 'A' + i / 32,
                 i % 32, 'A' + i / 32, i % 32, 'A' + i / 32, i % 32);
        spinner_warn(text);
    }
}

void tfc_mbed_irq_enable(struct tfc_mbed_irq *q, int enable, const char *what) {
    check(q, what);
    if (index_of(q->pin) >= 0) s.disabled[port_of(q->pin)] = !enable;
}

int tfc_mbed_irq_read(struct tfc_mbed_irq *q, const char *what) {
    check(q, what);
    return index_of(q->pin) < 0 ? 0 : tfc_mbed_digital_read(q->pin);
}

int tfc_mbed_encoder_pin(int pin, int *level) {
    int i = index_of(pin);
    if (i < 0) return 0;
    resolve(i);
    if (s.pin[i].state == BAD) spinner_fail(s.why[i]);
    if (s.pin[i].state != ENCODER) return 0;
    *level = pin_level(i);
    return 1;
}
