/* The FRDM-KL25Z's sensors of the mbed kit (simrunner drive main.cpp --kit tfc-mbed): QEI.h (Aaron
 * Berk's quadrature encoder interface) on the car file's [encoders], MMA8451Q.h (the board's
 * accelerometer) on its [imu]. Our own code, on spinner.h; include/QEI.h and include/MMA8451Q.h
 * cite the libraries.
 * - when: on the board QEI counts in its pins' interrupts and MMA8451Q reads its registers over
 *   I2C, both without waiting; here the kit's clock interrupt (1 kHz, ../tfc_mbed.cpp) reads the
 *   wheels and the accelerometer at each tick once a QEI or an MMA8451Q exists, and a read returns
 *   the latest sample (a read of the board: a loop of reads lets time pass, as the kit's polls).
 *   The first read in main() before any tick lets one physics step pass (the tick then samples);
 *   inside a handler a read takes the state then;
 * - which wheel: the n-th QEI constructed reads the n-th wheel with an encoder (FL, FR, RL, RR
 *   order: on rear encoders the first QEI is RL, the second RR), unless --param qei_PTxN=W names
 *   the wheel (0..3: SPINNER_WHEEL_FL..RR) for the QEI whose channel A is on pin PTxN;
 * - counts: the car's counter counts m per line (x4: 4, x2: 2, x1: 1); a QEI decoding x (X2: 2,
 *   X4: 4) per line counts floor(count x / m): exact when m >= x (counting = "x4", the default),
 *   else in steps of x / m. A single channel (counting = "single") cannot be decoded by QEI. */
#include <math.h>
#include <stdio.h>

#include "spinner.h"
#include "tfc_mbed_sim.h"

#define MAX_QEI 16
/* One g: standard gravity, 9.80665 m/s^2 (3rd CGPM, 1901; BIPM, The International System of Units,
 * 9th ed., 2019). */
#define STANDARD_GRAVITY_MPS2 9.80665
/* MMA8451Q datasheet (NXP, rev. 10.3), Table 1: at +-2 g (the range the library leaves: it only
 * writes CTRL_REG1 = 0x01) the 14-bit output counts 4096 per g, -8192 .. 8191. */
#define COUNTS_PER_G 4096.0
#define COUNTS_MAX 8191
#define COUNTS_MIN (-8192)

static struct {
    int on;                           /* sampling at the ticks */
    int wheel_used[4], imu_used;      /* what the ticks read */
    double wheel_t_s[4], accel_t_s;   /* when each was last read (-1: never) */
    long long raw[4];                 /* each wheel's count then */
    double accel_mps2[3];
    struct tfc_mbed_qei *qei[MAX_QEI];
    int n_qei, n_made;
} s = {0, {0}, 0, {-1.0, -1.0, -1.0, -1.0}, -1.0, {0}, {0}, {0}, 0, 0};

static long long floor_div(long long a, long long b) {
    long long q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

/* The wheel's count in pulses of x per line (counts per line m of the car's counter). */
static long long pulses_of(long long raw, int x, int m) { return floor_div(raw * x, m); }

/* The index channel's rising edges as a count moves from `from` to `to` (either way): the index is
 * high at the counts that are whole revolutions (`per_rev` counts) from the start, one count wide
 * (../interrupt_in.cpp, --param encoder_z_PTxN), and rises as the count comes to one: forwards at
 * k per_rev in (from, to], backwards in [to, from). The library's index handler counts each rise,
 * whichever way the wheel turns (QEI.cpp: index(): revolutions_++). */
static long long index_rises(long long from, long long to, long long per_rev) {
    return to >= from ? floor_div(to, per_rev) - floor_div(from, per_rev)
                      : floor_div(from - 1, per_rev) - floor_div(to - 1, per_rev);
}

static int counts_per_line(int wheel) {
    int m = 0;
    spinner_encoder_lines(wheel, &m);
    return m;
}

/* A QEI's wheel: by --param qei_PTxN, else the n-th fitted wheel; the reason when it has none. */
static void resolve(struct tfc_mbed_qei *q) {
    static char why[MAX_QEI][300];
    static const char *names[4] = {"FL", "FR", "RL", "RR"};
    if (q->wheel >= 0 || q->error) return;
    char *msg = why[q->ordinal % MAX_QEI];
    char param[32];
    snprintf(param, sizeof param, "qei_PT%c%d", 'A' + ((q->pin_a >> 12) & 7), (q->pin_a >> 2) & 31);
    int fitted[4], n = 0;
    for (int w = 0; w < 4; w++) if (spinner_encoder_lines(w, NULL) > 0) fitted[n++] = w;
    double named = spinner_param(param, -1.0);
    int wheel = named >= 0 ? (int)named : (q->ordinal < n ? fitted[q->ordinal] : -1);
    if (n == 0) {
        snprintf(msg, 300, "the car has no wheel encoders: add [encoders] to the car file (docs/car.md) "
                 "for QEI to count");
    } else if (named >= 0 && (named != wheel || wheel > 3 || spinner_encoder_lines(wheel, NULL) == 0)) {
        snprintf(msg, 300, "--param %s=%g: expected a wheel with an encoder (0..3: FL, FR, RL, RR; this car "
                 "has %d)", param, named, n);
    } else if (wheel < 0) {
        snprintf(msg, 300, "QEI number %d (channel A %s): the car has %d wheel encoders, one a QEI in the "
                 "order they are constructed; name its wheel with --param %s=0..3", q->ordinal + 1,
                 param + 4, n, param);
    } else if (counts_per_line(wheel) == 0) {
        snprintf(msg, 300, "the car's encoder on %s is a single channel (encoders.counting = \"single\"): "
                 "QEI decodes two channels in quadrature", names[wheel]);
    } else {
        q->wheel = wheel;
        s.wheel_used[wheel] = 1;
        return;
    }
    q->error = msg;
}

static void read_wheel(int w) {
    s.raw[w] = spinner_get_encoder(w);
    s.wheel_t_s[w] = tfc_mbed_now_s();
}

static void read_accel(void) {
    spinner_get_accel(&s.accel_mps2[0], &s.accel_mps2[1], &s.accel_mps2[2]);
    s.accel_t_s = tfc_mbed_now_s();
}

/* At each tick of the kit's clock: the samples, and the index channels' edges since the last. */
static void on_tick(void) {
    for (int i = 0; i < s.n_qei; i++) resolve(s.qei[i]);
    for (int w = 0; w < 4; w++) if (s.wheel_used[w]) read_wheel(w);
    if (s.imu_used) read_accel();
    for (int i = 0; i < s.n_qei; i++) {
        struct tfc_mbed_qei *q = s.qei[i];
        if (q->wheel < 0 || !q->counting) continue;  /* (one being constructed in main(): from its count) */
        long long raw = s.raw[q->wheel];
        long long line = (long long)spinner_encoder_lines(q->wheel, NULL) * counts_per_line(q->wheel);
        if (q->has_index) q->revolutions += (int)index_rises(q->last_raw, raw, line);
        q->last_raw = raw;
    }
}

static void start_sampling(void) {
    if (!s.on) {
        s.on = 1;
        tfc_mbed_on_tick(on_tick);
    }
}

/* A sample taken at *t_s, as of now: a read of the board in main() (the first there lets physics
 * steps pass until a tick has read it); inside a handler, read now if the tick has not. */
static void fresh(double *t_s, int wheel) {
    if (tfc_mbed_in_isr()) {
        if (*t_s != tfc_mbed_now_s()) wheel >= 0 ? read_wheel(wheel) : read_accel();
        return;
    }
    tfc_mbed_poll();
    while (*t_s < 0) tfc_mbed_idle();
}

/* q, reading its wheel, with the wheel's count as of now (s.raw); the run ends at the program's
 * call when it has no wheel. */
static struct tfc_mbed_qei *usable(struct tfc_mbed_qei *q, const char *what) {
    tfc_mbed_start();
    resolve(q);
    if (q->error) {
        char msg[400];
        snprintf(msg, sizeof msg, "%s: %s", what, q->error);
        spinner_fail(msg);
    }
    fresh(&s.wheel_t_s[q->wheel], q->wheel);
    return q;
}

void tfc_mbed_qei_attach(struct tfc_mbed_qei *q, int pin_a, int has_index, int x) {
    *q = tfc_mbed_qei{};
    q->pin_a = pin_a, q->has_index = has_index, q->x = x, q->wheel = -1, q->ordinal = s.n_made++;
    if (s.n_qei == MAX_QEI) spinner_fail("QEI: more than 16 at once");
    s.qei[s.n_qei++] = q;
    start_sampling();
    if (!tfc_mbed_started()) {  /* a global: it counts from the start (0) */
        q->counting = 1;
        return;
    }
    /* constructed in main() or a handler: from the count now. Until it is set the ticks leave it be:
     * one runs in main()'s wait for the wheel's first sample, or (--mcu-time) in its --param's read,
     * and counted the index channel's rises from the wheel's count 0, the run's start. */
    usable(q, "QEI::QEI");
    q->base = pulses_of(s.raw[q->wheel], q->x, counts_per_line(q->wheel));
    q->last_raw = s.raw[q->wheel];
    q->counting = 1;
}

void tfc_mbed_qei_detach(struct tfc_mbed_qei *q) {
    for (int i = 0; i < s.n_qei; i++) {
        if (s.qei[i] != q) continue;
        s.qei[i] = s.qei[--s.n_qei];
        return;
    }
}

int tfc_mbed_qei_pulses(struct tfc_mbed_qei *q, const char *what) {
    usable(q, what);
    return (int)(pulses_of(s.raw[q->wheel], q->x, counts_per_line(q->wheel)) - q->base + q->offset);
}

int tfc_mbed_qei_revolutions(struct tfc_mbed_qei *q, const char *what) {
    usable(q, what);
    return q->revolutions;
}

/* Channels A (bit 1) and B (bit 0) now: the library's X4 sequence 00 01 11 10 counts up. */
int tfc_mbed_qei_state(struct tfc_mbed_qei *q, const char *what) {
    static const int gray[4] = {0x0, 0x1, 0x3, 0x2};
    usable(q, what);
    long long quarter = pulses_of(s.raw[q->wheel], 4, counts_per_line(q->wheel));
    return gray[(int)(quarter - 4 * floor_div(quarter, 4))];
}

void tfc_mbed_qei_set(struct tfc_mbed_qei *q, int pulses, int revolutions, const char *what) {
    usable(q, what);
    q->base = pulses_of(s.raw[q->wheel], q->x, counts_per_line(q->wheel));
    q->offset = pulses;
    if (revolutions >= 0) q->revolutions = revolutions;
}

void tfc_mbed_mma_attach(void) {
    start_sampling();
}

int tfc_mbed_mma_counts(int axis, const char *what) {
    tfc_mbed_start();
    if (!spinner_has_imu()) {
        char msg[300];
        snprintf(msg, sizeof msg, "%s: the car has no IMU: add [imu] to the car file (docs/car.md); the "
                 "board's accelerometer reads its accelerometer", what);
        spinner_fail(msg);
    }
    s.imu_used = 1;
    fresh(&s.accel_t_s, -1);
    double counts = round(s.accel_mps2[axis] / STANDARD_GRAVITY_MPS2 * COUNTS_PER_G);
    return (int)(counts > COUNTS_MAX ? COUNTS_MAX : counts < COUNTS_MIN ? COUNTS_MIN : counts);
}
