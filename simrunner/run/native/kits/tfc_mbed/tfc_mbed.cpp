/* The mbed FRDM-TFC library and the part of mbed a team's program uses, on the simulated car
 * (simrunner drive main.cpp --kit tfc-mbed; include/mbed.h, include/TFC.h). Our own code, on
 * spinner.h; the mapping of the board onto the car is the TFC kit's (../tfc/tfc.c):
 * - time: a 1 kHz timer interrupt of the kit (spinner_every) keeps the simulated time, has the
 *   sensors sampled (sensors.cpp) and InterruptIn's edges of the millisecond gone handled
 *   (interrupt_in.cpp), then runs the program's Ticker/Timeout handlers that fell due (in due order);
 *   main() lets time pass in wait*(), sleep(), __WFI() and in reads of the board (poll());
 * - TPM1, the servo timer, and the camera: on the board the library's TPM1 overflow interrupt
 *   (TFC.cpp, TPM1_IRQHandler) raises SI, starting the read-out of the integration gone while the
 *   next integrates, every servo frame (SERVO_DEFAULT_PERIOD, 10 ms), and its ADC interrupt fills
 *   the image. Here the camera is TPM1: the simulator's line camera, free-running at the servo
 *   frame (its frame period is the servo frame), gives a frame at each overflow; the kit's 1 kHz
 *   interrupt finds a new one there (spinner_latest_image, which never waits) and does what the
 *   overflow does (tpm1_overflow: MOD and the servos' CnV load, TPM1_IRQHandler's CnV writes and
 *   TFC_ServoTicker++), reads it into the working buffer, swaps the ping-pong buffers and increments
 *   TFC_LineScanImageReady, before the Tickers due then: main() runs on between two images and a
 *   Ticker handler sees each image;
 * - servo 0 steers (at TPM1's overflows, as the servo's pulse does), H-bridge A and B are the left
 *   and right rear motors' duties, the pots, DIP switch, buttons and battery read --param values,
 *   the LEDs are kept, serial output prints. */
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "spinner.h"
#include "mbed.h"
#include "TFC.h"

/* The kit's clock: 1 ms (mbed's wait_ms and Ticker users' usual grain; the default physics step,
 * 2 ms, takes it at every step). */
#define CLOCK_PERIOD_S 1e-3
/* A loop that reads the board without waiting (`while (!TFC_LineScanImageReady) {}`,
 * `while (t.read_ms() < 20) {}`, `while (TFC_Ticker[3] < 100) {}`) waits on the board for the
 * interrupts; here time passes only in calls. After this many reads since main() last waited,
 * each further read takes READ_TIME_S, as a short wait (a physics step, and a due image, once
 * they add up to one): a loop that reads several things a pass still sees each image arrive. */
#define POLLS_BEFORE_TIME 64
#define READ_TIME_S 1e-4
#define MAX_EVENTS 64
#define NUM_TICKERS 16  /* >= a program's NUM_TFC_TICKERS */
/* TPM1's counter clock: TFC_InitServos selects MCGPLLCLK/2 (48 MHz, SystemCoreClock on the
 * FRDM-KL25Z) and the prescaler 2^6 (FTM1_CLK_PRESCALE 6): 750 kHz. Its counter has 16 bits (KL25
 * Sub-Family Reference Manual, KL25P80M48SF0RM, 31.4.3): past MOD it counts on to 0xFFFF and
 * round to 0, 65536 counts, without an overflow. */
#define TPM1_COUNT_HZ 750e3
#define TPM1_ROUND_S (65536 / TPM1_COUNT_HZ)
/* TFC.cpp's TFC_InitServos: TPM1->MOD = (SystemCoreClock / (1 << FTM1_CLK_PRESCALE)) * _ServoPeriod,
 * a uint32_t (48e6 / 64 = 750000) times a float, in float, converted to the 32-bit register; its MOD
 * field has 16 bits (KL25 RM 31.3.3 MOD: bits 15-0, the rest reserved), so a period above 87.38 ms
 * keeps the low 16 bits of the count (100 ms: 75000 -> 9464, a 12.62 ms frame). The counter counts 0 ..
 * MOD: a period of MOD + 1 counts (RM 31.4.3.1 up counting: "(MOD + 0x0001) x period of the TPM
 * counter clock"), 10 ms -> MOD 7500 -> 10.00133 ms. */
static uint16_t tpm1_mod_of(double period_s) {
    float counts = (float)(48000000u / (1u << 6)) * (float)period_s;
    uint32_t mod = counts <= 0.0f ? 0u : (counts >= 4294967040.0f ? 0xFFFFFFFFu : (uint32_t)counts);
    return (uint16_t)(mod & 0xFFFFu);
}
/* The frame MOD gives; the kit's camera takes 1 ms .. 1 s (a MOD under 749, a period under 1 ms,
 * runs 1 ms frames: not emulated). */
static double tpm1_frame_of(uint16_t mod) {
    double s = ((double)mod + 1.0) / TPM1_COUNT_HZ;
    return s < 1e-3 ? 1e-3 : (s > 1.0 ? 1.0 : s);
}

volatile uint16_t LineScanImage0Buffer[2][128], LineScanImage1Buffer[2][128];
volatile uint16_t *TFC_LineScanImage0 = LineScanImage0Buffer[1];
volatile uint16_t *TFC_LineScanImage1 = LineScanImage1Buffer[1];
volatile uint16_t *LineScanImage0WorkingBuffer = LineScanImage0Buffer[0];
volatile uint16_t *LineScanImage1WorkingBuffer = LineScanImage1Buffer[0];
volatile uint8_t LineScanWorkingBuffer;
volatile uint16_t PotADC_Value[2];
volatile uint16_t BatSenseADC_Value;

static volatile uint8_t image_ready;
/* TFC_ServoTicker: the library's variable, which its TPM1 interrupt increments and a program may
 * write (`TFC_ServoTicker = 0;`): from then it counts on from the value written. */
static volatile uint32_t servo_ticker;
static volatile uint32_t tickers[NUM_TICKERS];

static struct {
    int started;
    double now_s;            /* simulated time as the clock last read it */
    double wait_until_s;     /* main()'s own time: where its waits and reads have got to */
    double pass_end_s;       /* the time when the last of them ended */
    /* TPM1 (the servo frame; the camera's frame) */
    double servo_frame_s;    /* the period MOD gives (TFC_InitServos): the camera's frame */
    double next_frame_s;     /* MOD written while TPM1 counts (TFC_SetLineScanExposureTime): its
                              * write buffer, loaded at the next overflow (0: none) */
    uint16_t mod, next_mod;  /* TPM1's MOD in force, and the one in its write buffer */
    double servo_period_s;   /* TFC_InitServos' ServoPeriod (_ServoPeriod): the duty's denominator */
    double overflow_s;       /* TPM1's last overflow (the read-out of the latest image), or its start */
    int library_servos;      /* the library's TPM1 interrupt writes the servos' CnV: once the program
                              * queues positions (TFC_SetServo, ...) or calls TFC_InitServos (not for
                              * TFC_Init alone: a PwmOut's pulse on the pin then holds) */
    uint16_t servo_queued;   /* QueuedServo0Val (or 1's: tfc_servo_channel): TFC_SetServo's counts */
    float servo_cnv;         /* the channel's CnV as written (as a position): loads at the next overflow */
    float servo;             /* CnV in force: the pulse the servo steers by (-1..1) */
    long long frame;         /* the camera frame read out last */
    double pulse_min_s, pulse_max_s;  /* TFC_InitServos' range of positions -1..1 */
    double servo_rad, servo_offset_rad;
    int servo_channel;
    int in_isr;
    unsigned polls;
    int hbridge;
    float duty_a, duty_b;
    int leds[4];
    struct tfc_mbed_event *events[MAX_EVENTS];
    int n_events;
    void (*sample)(void);   /* the sensors' read at each tick (tfc_mbed_on_tick) */
    void (*edges)(void);    /* InterruptIn's edges at each tick (tfc_mbed_on_edges) */
    int unpowered, unpowered_warned;  /* duties set with the H-bridge disabled: since unpowered_s */
    double unpowered_s;
    const void *duty_call;  /* where the program last called TFC_SetMotorPWM (its return address) */
    int motor_pwm_on;       /* TFC_Init or TFC_InitMotorPWM has clocked TPM0 (TFC_SetMotorPWM) */
    int adc_on;             /* TFC_Init or TFC_InitADC_System has run: TPM1's overflows start conversions */
    int adc_converted;      /* the pots and the battery converted once (TFC_ReadPot ...) */
    int early_pot_warned, early_battery_warned;  /* a read before that was warned */
} k;

static double clampd(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

[[noreturn]] void tfc_mbed_not_emulated(const char *what, const char *why) {
    char msg[400];
    snprintf(msg, sizeof msg, "%s: not emulated by the simulator's mbed FRDM-TFC kit (--kit tfc-mbed): %s", what, why);
    spinner_fail(msg);
}

static void send_servo(void) { spinner_set_servo(k.servo * k.servo_rad + k.servo_offset_rad); }

static void send_motors(void) { spinner_set_motors(k.hbridge ? k.duty_a : 0.0f, k.hbridge ? k.duty_b : 0.0f); }

/* The Ticker/Timeout handlers due at k.now_s, earliest first. */
static void run_due(void) {
    for (;;) {
        struct tfc_mbed_event *due = NULL;
        for (int i = 0; i < k.n_events; i++) {
            struct tfc_mbed_event *ev = k.events[i];
            if (ev->active && ev->next_s <= k.now_s + 1e-9 && (due == NULL || ev->next_s < due->next_s)) due = ev;
        }
        if (due == NULL) return;
        if (due->period_s > 0) due->next_s += due->period_s;
        else tfc_mbed_event_detach(due);  /* a Timeout: once (its handler may attach it again) */
        due->fn(due->arg);
    }
}

static void camera_service(void);
static uint16_t neutral_counts(void);

/* Duties set while the H-bridge is disabled move nothing, on the board too: the library's TFC_Init
 * (TFC.cpp: TFC_GPIO_Init ends with TFC_HBRIDGE_DISABLE), and TFC_HBRIDGE_ENABLE (PTE21) is the
 * program's to write. Held so for UNPOWERED_WARN_S of simulated time, the run gets a warning saying
 * so, as a car that stands still says nothing of why. */
#define UNPOWERED_WARN_S 1.0
static void check_unpowered(void) {
    if (k.hbridge || (k.duty_a == 0.0f && k.duty_b == 0.0f)) {
        k.unpowered = 0;
        return;
    }
    if (!k.unpowered) k.unpowered = 1, k.unpowered_s = k.now_s;
    if (k.unpowered_warned || k.now_s - k.unpowered_s < UNPOWERED_WARN_S) return;
    k.unpowered_warned = 1;
    char text[300];
    snprintf(text, sizeof text, "TFC_SetMotorPWM(%.2f, %.2f) with the H-bridge disabled for %.1f s: the motors "
             "stay off, on the board too (TFC_Init() disables it): enable it with TFC_HBRIDGE_ENABLE",
             k.duty_a, k.duty_b, k.now_s - k.unpowered_s);
    spinner_warn_at(text, k.duty_call);
}

static void clock_isr(void) {
    k.now_s = spinner_get_time();  /* inside an interrupt: no time passes */
    check_unpowered();
    k.in_isr = 1;
    camera_service();  /* TPM1's overflow and the image it read out */
    if (k.sample) k.sample();
    if (k.edges) k.edges();  /* the pins' edges of the millisecond gone, before the Tickers due */
    run_due();
    k.in_isr = 0;
}

/* TPM1 at the kit's start: as TFC_Init leaves it (TFC_InitServos' defaults: SERVO_DEFAULT_PERIOD,
 * the counter from 0 now, the servos' queued positions 0). */
static void start_tpm1(void) {
    k.pulse_min_s = SERVO_MIN_PULSE_WIDTH_DEFAULT, k.pulse_max_s = SERVO_MAX_PULSE_WIDTH_DEFAULT;
    k.servo_period_s = SERVO_DEFAULT_PERIOD;
    k.mod = tpm1_mod_of(SERVO_DEFAULT_PERIOD);
    k.servo_frame_s = tpm1_frame_of(k.mod);
    k.next_frame_s = 0.0, k.overflow_s = k.now_s;
    k.servo_queued = neutral_counts();
    k.servo_cnv = k.servo = 0.0f;
    servo_ticker = 0;
    /* TFC.cpp's TPM1_IRQHandler, at each overflow of the free-running servo timer, raises SI and
     * starts the ADC's read-out of the integration gone while the next integrates: one image a
     * servo frame, each ready a read-out after its SI (not a servo frame plus the read-out). */
    spinner_camera_free_running();
    spinner_set_exposure(k.servo_frame_s);
}

void tfc_mbed_start(void) {
    if (k.started) return;
    /* (a global object's constructor as the simulator's process loads the program: nothing can be
     * asked, the program runs in a child process instead, where this starts the kit; spinner.h) */
    if (!spinner_running()) return;
    k.started = 1;
    k.servo_rad = spinner_param("tfc_servo_rad", 0.40);
    k.servo_offset_rad = spinner_param("tfc_servo_offset_rad", 0.0);
    k.servo_channel = (int)spinner_param("tfc_servo_channel", 0.0);
    k.now_s = k.wait_until_s = k.pass_end_s = spinner_get_time();  /* main()'s own time starts now */
    start_tpm1();
    uint8_t row[128];  /* the first image: the frame after the start's */
    k.frame = spinner_latest_image(spinner_line_row(), 0, LLONG_MAX, row, sizeof row, NULL);
    spinner_every(CLOCK_PERIOD_S, clock_isr);
    send_servo();
    send_motors();
}

double tfc_mbed_now_s(void) {
    tfc_mbed_start();
    return k.now_s;
}

int tfc_mbed_in_isr(void) { return k.in_isr || spinner_in_interrupt(); }  /* a Ticker's, or --isr */

int tfc_mbed_started(void) { return k.started; }

void tfc_mbed_on_tick(void (*sample)(void)) { k.sample = sample; }

void tfc_mbed_on_edges(void (*edges)(void)) { k.edges = edges; }

/* The servo's position (-1 .. 1 of TFC_InitServos' pulses) a CnV of `counts` gives: its pulse is
 * counts / 750 kHz (edge-aligned PWM: high from the overflow to CnV, RM 31.4.6), so the position the
 * library asked for, truncated to whole counts by its QueuedServo0Val = TPM1->MOD * DutyCycle, and
 * shortened with MOD when a long period wrapped it (tpm1_mod_of); the car's servo stops at its ends. */
static float cnv_position(uint16_t counts) {
    double pulse_s = counts / TPM1_COUNT_HZ, span = k.pulse_max_s - k.pulse_min_s;
    return (float)clampd(span > 0 ? 2.0 * (pulse_s - k.pulse_min_s) / span - 1.0 : 0.0, -1.0, 1.0);
}

/* TPM1's overflow, the counter turning from MOD to 0, that started the read-out of the image just
 * come; one however many came while the kit's interrupt was held (masked: TPM1's NVIC pending bit,
 * one bit). First what the timer does at the overflow: MOD and the channels' CnV load what was
 * written to them since (KL25 RM 31.4.8.1 MOD, 31.4.8.2 CnV: with the counter running, in up
 * counting and edge-aligned PWM, "after [the register] was written and the TPM counter changes
 * from MOD to zero"), so the servo's pulse from this edge is the CnV TPM1_IRQHandler wrote at the
 * overflow before. Then that handler: each channel's CnV = its queued position (TFC_SetServo's
 * QueuedServo0Val, 1Val), loaded at the next overflow; TFC_ServoTicker++ (up to 0xFFFFFFFF). */
static void tpm1_overflow(void) {
    k.overflow_s = k.now_s;
    if (k.next_frame_s > 0.0) k.servo_frame_s = k.next_frame_s, k.next_frame_s = 0.0, k.mod = k.next_mod;
    if (k.servo != k.servo_cnv) {
        k.servo = k.servo_cnv;
        send_servo();
    }
    if (k.library_servos) k.servo_cnv = cnv_position(k.servo_queued);
    if (servo_ticker < 0xFFFFFFFFu) servo_ticker++;
    if (k.adc_on) k.adc_converted = 1;  /* (the handler then starts the pots', battery's conversions) */
}

/* The read-out: the camera's latest frame, once a new one is there (never waits). */
static void camera_service(void) {
    uint8_t row[128];
    size_t n = 0;
    long long frame = spinner_latest_image(spinner_line_row(), 1, k.frame, row, sizeof row, &n);
    if (n == 0) return;
    tpm1_overflow();
    k.frame = frame;
    for (size_t i = 0; i < 128; i++) {
        uint16_t v = (uint16_t)((i < n ? row[i] : 0) << 4);  /* 8-bit grey -> 12-bit counts */
        LineScanImage0WorkingBuffer[i] = v;
        LineScanImage1WorkingBuffer[i] = v;
    }
    int done = LineScanWorkingBuffer;  /* TFC.cpp's ADC0_IRQHandler: swap, then count */
    LineScanWorkingBuffer = !done;
    LineScanImage0WorkingBuffer = LineScanImage0Buffer[!done];
    LineScanImage1WorkingBuffer = LineScanImage1Buffer[!done];
    TFC_LineScanImage0 = LineScanImage0Buffer[done];
    TFC_LineScanImage1 = LineScanImage1Buffer[done];
    image_ready++;
}

/* One physics step of main() (the clock's interrupt runs in it; with interrupts disabled it is held,
 * and main()'s time is read here: a wait in a critical section ends, as mbed's on the us ticker's
 * counter). */
static void step(void) {
    double t = spinner_get_time();
    if (spinner_interrupts_disabled()) k.now_s = t;
}

/* The interrupt mask, and mbed's critical sections: counted, the outermost enter remembering whether
 * interrupts were enabled (mbed_critical.c, core_util_critical_section_enter/exit). */
static unsigned critical_depth;
static int critical_found_masked;

void tfc_mbed_irq_mask(int disable) {
    if (disable) spinner_disable_interrupts();
    else spinner_enable_interrupts();
}

int tfc_mbed_irq_masked(void) { return spinner_interrupts_disabled() != 0; }

void tfc_mbed_critical_enter(void) {
    int masked = spinner_interrupts_disabled();
    spinner_disable_interrupts();
    if (critical_depth++ == 0) critical_found_masked = masked;
}

void tfc_mbed_critical_exit(void) {
    if (critical_depth == 0) return;
    if (--critical_depth == 0 && !critical_found_masked) spinner_enable_interrupts();
}

int tfc_mbed_in_critical(void) { return critical_depth > 0; }

/* Let s pass from where main()'s own time has got to: short waits and reads add up to a step, and
 * the part of a step a wait did not need is used up by the next waits and reads - as long as no
 * other time passed in between (a sleep(), a sensor's first read): then main()'s time is now. */
static void pass(double s) {
    double base = k.now_s == k.pass_end_s ? k.wait_until_s : k.now_s;
    double until = base + s;
    k.wait_until_s = until;
    while (k.now_s < until - 1e-9) step();
    k.pass_end_s = k.now_s;
}

void tfc_mbed_poll(void) {
    tfc_mbed_start();
    if (tfc_mbed_in_isr()) return;
    if (++k.polls > POLLS_BEFORE_TIME) pass(READ_TIME_S);
}

void tfc_mbed_wait_s(double s, const char *what) {
    tfc_mbed_start();
    if (tfc_mbed_in_isr()) {
        char why[200];
        snprintf(why, sizeof why, "%s(...) inside a Ticker, Timeout or InterruptIn handler: no simulated "
                 "time passes in an interrupt; wait in main()", what);
        tfc_mbed_not_emulated(what, why);
    }
    k.polls = 0;
    if (!(s > 0)) {  /* wait(0): a step */
        step();
        return;
    }
    pass(s);  /* waits shorter than a physics step add up: twenty wait_us(100) take one 2-ms step */
}

void tfc_mbed_idle(void) {
    tfc_mbed_start();
    if (tfc_mbed_in_isr()) return;
    k.polls = 0;
    step();
}

void tfc_mbed_event_attach(struct tfc_mbed_event *ev, double delay_s, int repeat, const char *what) {
    tfc_mbed_start();
    if (!(delay_s >= 1e-6) || !isfinite(delay_s)) {
        char why[200];
        snprintf(why, sizeof why, "a time of %g s: expected at least 1 us (mbed's us ticker)", delay_s);
        tfc_mbed_not_emulated(what, why);
    }
    tfc_mbed_event_detach(ev);
    if (k.n_events == MAX_EVENTS) tfc_mbed_not_emulated(what, "more than 64 Tickers and Timeouts at once");
    ev->period_s = repeat ? delay_s : 0.0;
    ev->next_s = k.now_s + delay_s;
    ev->active = 1;
    k.events[k.n_events++] = ev;
}

void tfc_mbed_event_detach(struct tfc_mbed_event *ev) {
    ev->active = 0;
    for (int i = 0; i < k.n_events; i++) {
        if (k.events[i] != ev) continue;
        memmove(&k.events[i], &k.events[i + 1], (size_t)(k.n_events - i - 1) * sizeof k.events[0]);
        k.n_events--;
        return;
    }
}

/* ---- the board's pins (FRDM-TFC schematic, as TFC.h lists the library's resources) ---- */
static int param_button(int button) {
    char name[16];
    snprintf(name, sizeof name, "button%d", button);
    if (spinner_param(name, 0.0) != 0.0) return 1;
    if (button == 0) {  /* a start press: button 0 held 0.2 s from button0_at, as the TFC kit */
        double at = spinner_param("button0_at", 0.1);
        return k.now_s >= at && k.now_s < at + 0.2;
    }
    return 0;
}

static int pin_param(const char *kind, int pin, double fallback) {
    char name[32];
    snprintf(name, sizeof name, "%s_PT%c%d", kind, 'A' + ((pin >> 12) & 7), (pin >> 2) & 31);
    return (int)spinner_param(name, fallback);
}

/* A pin's level: kept (the LEDs), the H-bridge's enable sent. A write takes no time and asks the
 * simulator nothing before the kit has started: a global DigitalOut's constructor writes its pin
 * before main() (mbed's blinky, `DigitalOut myled(LED1);`; mbed's DigitalOut(pin, value) writes
 * the value at construction), when in the simulator's process the program's library is being
 * loaded and no run is there to ask; tfc_mbed_start sends the H-bridge's level. */
void tfc_mbed_digital_write(int pin, int value) {
    int led = pin == PTB8 ? 0 : pin == PTB9 ? 1 : pin == PTB10 ? 2 : pin == PTB11 ? 3 : -1;
    if (led >= 0) k.leds[led] = value < 0 ? !k.leds[led] : value != 0;
    if (pin == PTE21) {
        k.hbridge = value != 0;
        if (k.started) send_motors();
    }
}

int tfc_mbed_digital_read(int pin) {
    tfc_mbed_poll();
    if (pin == PTC13) return param_button(0);
    if (pin == PTC17) return param_button(1);
    if (pin >= PTE2 && pin <= PTE5) return (TFC_GetDIP_Switch() >> ((pin - PTE2) >> 2)) & 1;
    int level;
    if (tfc_mbed_encoder_pin(pin, &level)) return level;
    return pin_param("digital", pin, 0.0) != 0;
}

float tfc_mbed_analog_read(int pin) {
    tfc_mbed_poll();
    if (pin == PTB3 || pin == PTB2) {  /* the pots: ADC0_SE13 (pot 0), ADC0_SE12 (pot 1) */
        double pot = clampd(spinner_param(pin == PTB3 ? "pot0" : "pot1", 0.0), -1.0, 1.0);
        return (float)((1.0 - pot) / 2.0);  /* TFC_ReadPot = 1 - ADC / (4095 / 2) */
    }
    if (pin == PTE29)  /* the battery sense, 10k of 47k + 10k, of the ADC's 3.3 V (TFC_ReadBatteryVoltage) */
        return (float)clampd(spinner_param("battery_v", 7.2) * 10000.0 / 57000.0 / 3.3, 0.0, 1.0);
    char name[32];
    snprintf(name, sizeof name, "analog_PT%c%d", 'A' + ((pin >> 12) & 7), (pin >> 2) & 31);
    return (float)clampd(spinner_param(name, 0.0), 0.0, 1.0);
}

/* A PwmOut on the steering servo's pin: a servo pulse, 1.0 .. 2.0 ms is -1 .. 1, from the write (mbed's
 * PwmOut writes the channel's CnV itself, not the library's queue; with the library's TPM1 interrupt
 * on too, that interrupt's next CnV write replaces it, as on the board). */
void tfc_mbed_pwm_write(int pin, float duty, float period_s) {
    tfc_mbed_start();
    if (pin == (k.servo_channel ? PTB1 : PTB0)) {
        double pulse_s = duty * period_s;
        k.servo = k.servo_cnv = (float)clampd((pulse_s - 0.0015) / 0.0005, -1.0, 1.0);
        send_servo();
    }
}

/* ---- the FRDM-TFC library (TFC.h) ---- */
static void init_servos(double pulse_min_s, double pulse_max_s, double period_s);

/* TFC.cpp's TFC_Init: ..., TFC_InitServos(the defaults), then TFC_ServoTicker = 0 (the kit's start is
 * the first: TPM1 as it leaves it). */
void TFC_Init() {
    k.motor_pwm_on = 1;  /* (TFC.cpp's TFC_Init calls TFC_InitMotorPWM) */
    k.adc_on = 1;        /* (and TFC_InitADC_System) */
    int running = k.started;
    tfc_mbed_start();
    if (!k.started) return;
    if (running) init_servos(SERVO_MIN_PULSE_WIDTH_DEFAULT, SERVO_MAX_PULSE_WIDTH_DEFAULT, SERVO_DEFAULT_PERIOD);
    servo_ticker = 0;
}
void TFC_GPIO_Init() { tfc_mbed_start(); }
void TFC_InitADC_System() {
    k.adc_on = 1;
    tfc_mbed_start();
}
void TFC_InitLineScanCamera() { tfc_mbed_start(); }
void TFC_InitMotorPWM(float SwitchingFrequency) {
    (void)SwitchingFrequency;
    k.motor_pwm_on = 1;
    tfc_mbed_start();
}

/* TFC.cpp's TFC_InitServos. TPM1->SC = 0 stops the counter where it is (KL25 RM 31.4.1: writing CMOD
 * 0 "does not affect the TPM counter value"); MOD, written with the counter stopped, takes the new
 * period at once (31.4.8.1); the counter then counts on (CMOD 1). It writes neither CNT (a write of
 * which would reset the counter) nor TFC_ServoTicker (TFC_Init zeroes that, after it). So the frame
 * in progress ends as the counter reaches the new MOD: one new period after the last overflow; or,
 * the counter being past the new MOD already, after it has counted on to 0xFFFF and round (a 16-bit
 * counter, 31.4.3) and up to MOD: TPM1_ROUND_S (87.4 ms) more, one long frame (the camera
 * integrates from SI to SI). Its queued positions go to 0 (TFC_SetServo(0, 0.0) and (1, 0.0)); CnV
 * is not written. The camera follows: spinner_set_exposure ends the frame in progress one period
 * after its last boundary, TPM1's last overflow.
 * With --mcu-time each call lets main()'s code time pass first, with the kit's interrupt in it: an
 * overflow there, or the counter passing the new MOD, moves where the call finds the counter (on the
 * board that code ran before the call), so the period is set again from where it is. */
static void init_servos(double pulse_min_s, double pulse_max_s, double period_s) {
    uint16_t mod = tpm1_mod_of(period_s);
    double p = tpm1_frame_of(mod);
    int set = -1;  /* what the camera was given: 1 a frame round 0xFFFF, 0 one period */
    for (int tries = 0; tries < 4; tries++) {
        int past = k.now_s - k.overflow_s > p + 1e-9;  /* the counter past the new MOD */
        if (past == set) break;
        set = past;
        if (!past) {
            spinner_set_exposure(p);
        } else {
            spinner_set_exposure(fmin(TPM1_ROUND_S + p, 1.0));
            spinner_set_exposure_next_frame(p);
        }
    }
    k.pulse_min_s = pulse_min_s, k.pulse_max_s = pulse_max_s, k.servo_period_s = period_s;
    k.servo_frame_s = p, k.next_frame_s = 0.0, k.mod = mod;  /* (MOD written directly: none waits to load) */
    k.servo_queued = neutral_counts();  /* its TFC_SetServo(0, 0.0), (1, 0.0) */
}

/* TFC.cpp's TFC_SetServoDutyCycle: QueuedServo0Val (a uint16_t) = TPM1->MOD * DutyCycle, in float. */
static uint16_t queue_counts(float duty) {
    float counts = (float)k.mod * duty;
    return (uint16_t)(counts <= 0.0f ? 0u : (counts >= 65535.0f ? 65535u : (uint32_t)counts));
}

/* TFC.cpp's TFC_SetServo: ((Position + 1.0)/2) * (_ServoDutyCycleMax - _ServoDutyCycleMin) +
 * _ServoDutyCycleMin, the duty cycles being TFC_InitServos' pulses / its ServoPeriod (floats). */
static float servo_duty(float position) {
    float lo = (float)k.pulse_min_s / (float)k.servo_period_s, hi = (float)k.pulse_max_s / (float)k.servo_period_s;
    return (float)(((position + 1.0) / 2) * (hi - lo) + lo);
}

static uint16_t neutral_counts(void) { return queue_counts(servo_duty(0.0f)); }

void TFC_InitServos(float ServoPulseWidthMin, float ServoPulseWidthMax, float ServoPeriod) {
    tfc_mbed_start();
    if (!k.started) return;
    init_servos(ServoPulseWidthMin, ServoPulseWidthMax, ServoPeriod);
    k.library_servos = 1;
}

/* Not in the mbed library: its servo frame, the camera's period, is set by TFC_InitServos (above).
 * The kit adds the CodeWarrior library's name for the period as a write of TPM1's MOD while the
 * counter runs: the KL25 then updates MOD only as the counter changes from MOD to zero (31.4.8.1,
 * up counting), the overflow that ends the frame in progress. So that frame keeps its period and
 * its exposure (its brightness); the next one is integrated over the new frame and lasts it. One
 * register: of several calls in a frame the last loads. The simulator loads it at the camera's next
 * frame boundary (spinner_set_exposure_next_frame), the kit at the overflow it is (tpm1_overflow),
 * TFC_ServoTicker counting on across the change. The simulator first: with --mcu-time the call lets
 * main()'s code time pass, and an overflow in it comes before this write, which loads at the next. */
void TFC_SetLineScanExposureTime(uint32_t TimeIn_uS) {
    tfc_mbed_start();
    uint16_t mod = tpm1_mod_of(TimeIn_uS * 1e-6);  /* (as TFC_InitServos computes MOD) */
    double p = tpm1_frame_of(mod);
    spinner_set_exposure_next_frame(p);
    k.next_frame_s = p, k.next_mod = mod;
}

volatile uint8_t *tfc_mbed_image_ready(void) { return &image_ready; }

volatile uint32_t *tfc_mbed_servo_ticker(void) {
    tfc_mbed_poll();
    return &servo_ticker;
}

/* TFC_Ticker (TFC.h): the program's own definition declares this function; C++ names do not
 * carry the return type, so its length there may be any up to NUM_TICKERS. */
volatile uint32_t (*tfc_mbed_tickers())[NUM_TICKERS] {
    tfc_mbed_poll();
    return &tickers;
}

/* TFC.cpp's TFC_SetServoDutyCycle only queues the pulse (QueuedServo0Val, 1Val; a number but 1 is
 * servo 0): TPM1's interrupt writes it to the channel's CnV at the next overflow, which loads it at
 * the one after (tpm1_overflow). The servo steers by it from the second frame edge after the call:
 * one to two servo frames later. */
void TFC_SetServo(uint8_t ServoNumber, float Position) {
    tfc_mbed_start();
    k.library_servos = 1;
    TFC_SetServoDutyCycle(ServoNumber, servo_duty(Position));
}

void TFC_SetServoDutyCycle(uint8_t ServoNumber, float DutyCycle) {
    tfc_mbed_start();
    k.library_servos = 1;
    if ((ServoNumber == 1) != (k.servo_channel == 1)) return;  /* the other channel: nothing on the car */
    k.servo_queued = queue_counts(DutyCycle);
}

void TFC_SetMotorPWM(float MotorA, float MotorB) {
    k.duty_call = __builtin_return_address(0);
    /* TFC.cpp's writes TPM0->CONTROLS[n].CnV from TPM0->MOD: before TFC_InitMotorPWM opens TPM0's
     * clock gate (SIM_SCGC6) a bus error on the board, as --kit tfc says (tfc.c: motor_pwm_check) */
    if (!k.motor_pwm_on)
        spinner_fail("TFC_SetMotorPWM() before TFC_Init() (or TFC_InitMotorPWM()): on the board the library's write "
                     "reads TPM0->MOD while TPM0's clock is still gated off (TFC_InitMotorPWM opens it, SIM_SCGC6), a "
                     "bus error that stops the board in its HardFault handler; call TFC_Init() first");
    tfc_mbed_start();
    k.duty_a = (float)clampd(MotorA, -1.0, 1.0);
    k.duty_b = (float)clampd(MotorB, -1.0, 1.0);
    send_motors();
}

uint8_t TFC_GetDIP_Switch() {
    tfc_mbed_poll();
    return (uint8_t)((int)spinner_param("dip", 0.0) & 0x0F);
}

uint8_t TFC_ReadPushButton(uint8_t Index) {
    return Index == 0 ? TFC_PUSH_BUTTON_0_PRESSED : TFC_PUSH_BUTTON_1_PRESSED;
}

/* The pots and the battery are converted by the library's interrupts, not by the read functions:
 * TFC.cpp's TPM1_IRQHandler, at each servo frame, starts the ADC on pot 0 ("Prime the ADC pump"), and
 * ADC0_IRQHandler stores pot 0, pot 1 and the battery in PotADC_Value[], BatSenseADC_Value, which
 * TFC_ReadPot and TFC_ReadBatteryVoltage scale. Until TPM1's first overflow after TFC_Init (one servo
 * frame) those counts are 0 - and stay 0 without TFC_Init -, so the library returns 1.0 for a pot and
 * 0 V for the battery: here too, with a warning at the program's first such read. */
static int adc_converted(const char *read, int *warned, const void *call) {
    if (k.adc_converted) return 1;
    if (!*warned) {
        *warned = 1;
        int battery = strcmp(read, "TFC_ReadBatteryVoltage()") == 0;
        char text[400];
        if (k.adc_on)
            snprintf(text, sizeof text, "%s at t = %.3f s, before the ADC's first conversion (TPM1's first overflow, "
                     "one servo frame after TFC_Init): its count is still 0, so the library returns %s, on the board "
                     "too; read it once the first image is in (TFC_LineScanImageReady)", read, k.now_s,
                     battery ? "0 V" : "1.0");
        else
            snprintf(text, sizeof text, "%s before TFC_Init(): the ADC that reads it runs from TFC_Init, so its count is "
                     "0 and the library returns %s, on the board too; call TFC_Init() first", read,
                     battery ? "0 V" : "1.0");
        spinner_warn_at(text, call);
    }
    return 0;
}

float TFC_ReadPot(uint8_t Channel) {
    const void *call = __builtin_return_address(0);
    tfc_mbed_poll();
    char read[40];
    snprintf(read, sizeof read, "TFC_ReadPot(%d)", Channel);
    uint16_t count = 0;  /* the pot's position -1..1 at counts 4095..0 */
    if (adc_converted(read, &k.early_pot_warned, call))
        count = (uint16_t)lround((1.0 - clampd(spinner_param(Channel == 0 ? "pot0" : "pot1", 0.0), -1.0, 1.0))
                                 * ADC_MAX_CODE / 2.0);
    PotADC_Value[Channel == 0 ? 0 : 1] = count;
    return (float)(((float)count / -((float)ADC_MAX_CODE / 2.0)) + 1.0);  /* TFC.cpp's TFC_ReadPot */
}

float TFC_ReadBatteryVoltage() {
    const void *call = __builtin_return_address(0);
    tfc_mbed_start();  /* the sense divider: 10k of 47k + 10k (TFC.cpp's commented-out factor) */
    /* the ADC's full scale is the FRDM-KL25Z's 3.3 V (VREFH; os.mbed.com/questions/75223: 3.3 V reads
     * close to 65535); the library scales the count by 3.0 (V): it reads sense x 3.0 / 3.3 */
    double sense_v = clampd(spinner_param("battery_v", 7.2) * 10000.0 / 57000.0, 0.0, 3.3);
    BatSenseADC_Value = adc_converted("TFC_ReadBatteryVoltage()", &k.early_battery_warned, call)
        ? (uint16_t)lround(sense_v / 3.3 * ADC_MAX_CODE) : 0;
    return (float)((double)BatSenseADC_Value / ADC_MAX_CODE * 3.0);
}

void TFC_SetBatteryLED(uint8_t Value) {
    for (int i = 0; i < 4; i++) tfc_mbed_digital_write(PTB8 + 4 * i, (Value >> i) & 1);
}

void TFC_SetBatteryLED_Level(uint8_t BattLevel) {
    TFC_SetBatteryLED((uint8_t)(BattLevel > 4 ? 0 : (1 << BattLevel) - 1));
}
