/* tfc_mbed_sim.h: the hooks between the simulator's mbed + FRDM-TFC kit headers (mbed.h, TFC.h)
 * and its implementation (../tfc_mbed.cpp, on spinner.h). Not part of either library's API.
 *
 * Time: the kit keeps simulated time with a 1 kHz timer interrupt of its own (spinner_every),
 * started at the first call into the kit: it reads the time, takes a new camera frame as TPM1's
 * overflow (the servo's pulse, TFC_ServoTicker) and its image, runs the InterruptIn handlers of the
 * edges since the last tick and the program's Ticker/Timeout handlers that fell due (mbed's
 * us_ticker interrupt). main() lets time
 * pass in wait*(), sleep(), __WFI() and, as on the board where interrupts change what it reads,
 * in reads of the board (tfc_mbed_poll: the camera flag, the tickers, Timer reads, pots,
 * switches, buttons, DigitalIn, AnalogIn) once it has read it many times without waiting. */
#ifndef TFC_MBED_SIM_H
#define TFC_MBED_SIM_H
#include <stdint.h>

void tfc_mbed_start(void);        /* the kit's set-up (idempotent), the clock first */
void tfc_mbed_poll(void);         /* one read of the board */
double tfc_mbed_now_s(void);      /* simulated time, s (no time passes) */
void tfc_mbed_wait_s(double s, const char *what);  /* wait*(): let s of simulated time pass */
void tfc_mbed_idle(void);         /* sleep(), __WFI(): one physics step */
int tfc_mbed_in_isr(void);        /* 1 inside a Ticker/Timeout handler or an --isr one */
int tfc_mbed_started(void);       /* 0 before the kit's first call (globals' constructors) */
[[noreturn]] void tfc_mbed_not_emulated(const char *what, const char *why);
/* the interrupt mask (PRIMASK: spinner_disable_interrupts; the kit's clock interrupt is held too)
 * and mbed's counted critical sections on it (mbed_critical.c) */
extern "C" void spinner_disable_interrupts(void);  /* spinner.h */
extern "C" void spinner_enable_interrupts(void);
void tfc_mbed_irq_mask(int disable);
int tfc_mbed_irq_masked(void);
void tfc_mbed_critical_enter(void);
void tfc_mbed_critical_exit(void);
int tfc_mbed_in_critical(void);

/* the board's pins as the kit maps them (mbed's KL25Z PinName values) */
void tfc_mbed_digital_write(int pin, int value);
int tfc_mbed_digital_read(int pin);
float tfc_mbed_analog_read(int pin);
void tfc_mbed_pwm_write(int pin, float duty, float period_s);

/* mbed's Ticker/Timeout: an event the kit's clock runs (its handler: fn(arg)) */
struct tfc_mbed_event {
    void (*fn)(void *arg);
    void *arg;
    double period_s;   /* 0 for a Timeout */
    double next_s;     /* due time, s */
    int active;
};
void tfc_mbed_event_attach(struct tfc_mbed_event *ev, double delay_s, int repeat, const char *what);
void tfc_mbed_event_detach(struct tfc_mbed_event *ev);

/* The kit's clock calls sample() at each tick, before the program's handlers (../sensors.cpp sets
 * it: the encoders and the accelerometer are read at the tick, as the board's interrupts and I2C
 * reads would, and a read returns the latest sample). */
void tfc_mbed_on_tick(void (*sample)(void));

/* QEI.h (Aaron Berk's quadrature encoder interface) and MMA8451Q.h: each object's state, kept by
 * ../sensors.cpp */
struct tfc_mbed_qei {
    int pin_a, has_index, x;   /* channel A's pin, an index channel given, pulses per line: 2 or 4 */
    int ordinal;               /* the n-th QEI constructed (0, 1, ...) */
    int wheel;                 /* SPINNER_WHEEL_*; -1 before it is resolved */
    const char *error;         /* why it cannot read a wheel (reported at the program's call) */
    long long base;            /* pulses (in x) of the wheel's count when reset */
    long long offset;          /* setPulses(): the count then */
    long long last_raw;        /* the wheel's count at the last tick (the index channel's edges) */
    int counting;              /* its count set (at the start, or its construction): the ticks count
                                * its index channel's edges from then */
    int revolutions;
};
void tfc_mbed_qei_attach(struct tfc_mbed_qei *q, int pin_a, int has_index, int x);
void tfc_mbed_qei_detach(struct tfc_mbed_qei *q);
int tfc_mbed_qei_pulses(struct tfc_mbed_qei *q, const char *what);
int tfc_mbed_qei_revolutions(struct tfc_mbed_qei *q, const char *what);
int tfc_mbed_qei_state(struct tfc_mbed_qei *q, const char *what);
void tfc_mbed_qei_set(struct tfc_mbed_qei *q, int pulses, int revolutions, const char *what);
void tfc_mbed_mma_attach(void);
int tfc_mbed_mma_counts(int axis, const char *what);  /* axis 0..2: the library's 14-bit reading */

/* InterruptIn (mbed.h): a pin's edges call the program's handlers at the kit's ticks
 * (../interrupt_in.cpp). A pin given to a wheel's encoder by --param encoder_PTxN=W (channel A),
 * encoder_b_PTxN=W (channel B) or encoder_z_PTxN=W (the index) has that channel's level; other
 * pins keep theirs. */
struct tfc_mbed_irq {
    int pin;
    int on_rise, on_fall;      /* rise()/fall() attached a handler */
    int pending;               /* an edge that came while its port's interrupts were disabled */
    void (*call)(void *obj, int rising);  /* the InterruptIn's handlers */
    void *obj;
};
void tfc_mbed_irq_attach(struct tfc_mbed_irq *irq, int pin);
void tfc_mbed_irq_detach(struct tfc_mbed_irq *irq);
void tfc_mbed_irq_set(struct tfc_mbed_irq *irq, int on_rise, int on_fall, const char *what);
void tfc_mbed_irq_enable(struct tfc_mbed_irq *irq, int enable, const char *what);
int tfc_mbed_irq_read(struct tfc_mbed_irq *irq, const char *what);
/* 1 and the level in *level when --param binds `pin` to an encoder's channel (a read of the
 * board: DigitalIn reads it so), else 0 */
int tfc_mbed_encoder_pin(int pin, int *level);
/* The kit's clock calls edges() at each tick after the sensors' sample() (../interrupt_in.cpp). */
void tfc_mbed_on_edges(void (*edges)(void));

/* the FRDM-TFC library's globals whose reads poll (TFC.h's macros) */
volatile uint8_t *tfc_mbed_image_ready(void);   /* the flag itself: no poll */
/* TFC_LineScanImageReady: reading it polls, writing it does not (a poll may fetch an image,
 * which `TFC_LineScanImageReady = 0` would then drop: on the board the write is one store). */
struct tfc_mbed_ready_flag {
    operator uint8_t() const { tfc_mbed_poll(); return *tfc_mbed_image_ready(); }
    tfc_mbed_ready_flag &operator=(int v) { *tfc_mbed_image_ready() = (uint8_t)v; return *this; }
    tfc_mbed_ready_flag &operator+=(int v) { *tfc_mbed_image_ready() += (uint8_t)v; return *this; }
    tfc_mbed_ready_flag &operator-=(int v) { *tfc_mbed_image_ready() -= (uint8_t)v; return *this; }
    uint8_t operator++() { return ++*tfc_mbed_image_ready(); }
    uint8_t operator--() { return --*tfc_mbed_image_ready(); }
    uint8_t operator++(int) { return (*tfc_mbed_image_ready())++; }
    uint8_t operator--(int) { return (*tfc_mbed_image_ready())--; }
};
volatile uint32_t *tfc_mbed_servo_ticker(void);
#endif
