/* The FRDM-TFC library on the simulated car (simrunner drive FIRMWARE.c --kit tfc).
 *
 * The team's sources build unchanged against include/TFC/ (the library's headers, same names
 * and functions) and this file, which talks to the simulator through spinner.h:
 * - time: TFC_Task() (called in the team's main loop) and TFC_Delay_mS() let simulated time
 *   pass (one physics step per call, or the delay); the SysTick tickers TFC_Ticker[] count its
 *   milliseconds; the PIT-driven camera read-out becomes: at each such pass, a camera frame newer
 *   than the last one read (one an exposure) is read without waiting (spinner_latest_image) into
 *   LineScanImage0/1 and LineScanImageReady is set to 1, so the main loop runs on between two
 *   images as on the board; a loop that only polls the board (the ready flag, the
 *   tickers, buttons, switches, pots: poll()) lets time pass too, as the interrupts would;
 * - servo 0 steers (position x tfc_servo_rad + tfc_servo_offset_rad), motors A and B are the
 *   left and right rear motors' duties (spinner_set_motors) while the H-bridge is enabled;
 * - the potentiometers, DIP switches, buttons and battery read --param values;
 * - the LEDs are kept (and shown in the debug video's text); the serial terminal prints;
 * - a timer interrupt of the firmware's own runs from its registers (timers.c).
 * docs/firmware.md, lists what is emulated and what is not. */
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "spinner.h"
#include "TFC/TFC.h"

/* The library's globals (FRDM-TFC TFC_LineScanCamera.c: the images are the second half of
 * double buffers; here the simulator fills that half and never swaps). TFC_Ticker and
 * LineScanImageReady are reached through tfc_sim_tickers() and tfc_sim_image_ready(). */
#define TFC_SIM_TICKERS 16  /* >= any project's NUM_TFC_TICKERS (TFC_Config.h) */
static volatile uint32_t tickers[TFC_SIM_TICKERS];
static volatile uint8_t image_ready;
volatile uint16_t LineScanImage0Buffer[2][128], LineScanImage1Buffer[2][128];
volatile uint16_t *LineScanImage0 = LineScanImage0Buffer[1];
volatile uint16_t *LineScanImage1 = LineScanImage1Buffer[1];
volatile uint16_t *LineScanImage0WorkingBuffer = LineScanImage0Buffer[0];
volatile uint16_t *LineScanImage1WorkingBuffer = LineScanImage1Buffer[0];
volatile uint8_t LineScanWorkingBuffer;
ByteQueue SDA_SERIAL_OUTGOING_QUEUE, SDA_SERIAL_INCOMING_QUEUE;

static struct {
    int inited;
    double ms_counted;      /* simulated ms already added to the tickers */
    double exposure_s;      /* the exposure last written (TFC_SetLineScanExposureTime: PIT_LDVAL0) */
    double floor_s;         /* the shortest the frame after the next one read can be (camera_service) */
    long long frame;        /* the camera frame read out last */
    double looked_s;        /* when the camera was last asked for a new frame */
    double next_look_s;     /* no new frame before then (camera_service) */
    int hbridge;            /* H-bridge enabled */
    float duty_a, duty_b;   /* motor duties */
    float servo;            /* servo 0 position */
    int leds[4];
    double servo_rad, servo_offset_rad;
    unsigned polls;         /* reads of the board since simulated time last passed */
    uint32_t tick_pending;  /* a SysTick fell due while interrupts were disabled */
    double unpowered_s;     /* since when duties are set with the H-bridge disabled (-1: not so) */
    int unpowered_warned;
    int masked_poll_warned; /* the warning of a poll with interrupts disabled was given */
    const void *duty_call;  /* where the program last called TFC_SetMotorPWM (its return address) */
    int motor_pwm_on;       /* TFC_Init or TFC_InitMotorPWM has clocked TPM0 (TFC_SetMotorPWM) */
    int servos_on;          /* TFC_Init or TFC_InitServos has clocked TPM1 (TFC_SetServo...) */
    double adc_first_s;     /* the ADC's first conversion: the first PIT0 interrupt after TFC_InitADCs */
    int adc_on;             /* TFC_InitADCs has run (TFC_Init calls it) */
    int early_pot_warned, early_battery_warned;  /* a read before that first conversion was warned */
} tfc = {.unpowered_s = -1.0};

/* The library's TFC_SetMotorPWM writes TPM0's channels from TPM0_MOD, and TPM0's clock gate
 * (SIM_SCGC6 TPM0) is opened by TFC_InitMotorPWM (TFC_Init calls it): before it, the access is a
 * bus error on the board (a Kinetis peripheral whose clock is gated off answers none: NXP community
 * thread 460069, a hard fault on a PIT access so), and the program stops in its HardFault handler. */
static void motor_pwm_check(void) {
    if (!tfc.motor_pwm_on)
        spinner_fail("TFC_SetMotorPWM() before TFC_Init() (or TFC_InitMotorPWM()): on the board the library's write "
                     "reads TPM0_MOD while TPM0's clock is still gated off (TFC_InitMotorPWM opens it, SIM_SCGC6), a "
                     "bus error that stops the board in its HardFault handler; call TFC_Init() first");
}

/* The same for the servos: the library's TFC_SetServoDutyCycle (TFC_SetServo calls it) writes
 * TPM1_C0V = TPM1_MOD * DutyCycle, TPM1's clock opened by TFC_InitServos (TFC_Init calls it). */
static void servo_check(const char *call) {
    if (tfc.servos_on) return;
    char text[400];
    snprintf(text, sizeof text, "%s() before TFC_Init() (or TFC_InitServos()): on the board the library's "
             "write reads TPM1_MOD while TPM1's clock is still gated off (TFC_InitServos opens it, SIM_SCGC6), a "
             "bus error that stops the board in its HardFault handler; call TFC_Init() first", call);
    spinner_fail(text);
}

/* A loop that polls the board without calling the library (`while (!LineScanImageReady);`,
 * `while (TFC_Ticker[0] < 20);`, `while (!TFC_PUSH_BUTTON_0_PRESSED);`) waits on the board for
 * the interrupts or a person; here time passes only in calls. So after this many reads without
 * a call that lets time pass, each further read lets one physics step pass (and runs the
 * interrupts' work). A main loop that calls TFC_Task() reads far fewer between two calls, so its
 * timing is the same as without (the example firmware's twin test holds it to the step). */
#define POLLS_BEFORE_TIME 64

void tfc_sim_timers_init(void);  /* timers.c: the TPM clock as the library selects it */
void tfc_sim_timers_library_pit(void);  /* timers.c: the PIT as the library's TFC_InitADCs leaves it */

static double clampf(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

static void send_commands(void) {
    spinner_set_servo(tfc.servo * tfc.servo_rad + tfc.servo_offset_rad);
    spinner_set_motors(tfc.hbridge ? tfc.duty_a : 0.0f, tfc.hbridge ? tfc.duty_b : 0.0f);
}

/* Duties set while the H-bridge is disabled move nothing, on the board too: the library's TFC_Init
 * (TFC.c) ends with TFC_HBRIDGE_DISABLE and TFC_SetMotorPWM(0,0), and TFC_HBRIDGE_ENABLE (EN, PTE21,
 * TFC_BoardSupport.h) is the program's to write. Held so for UNPOWERED_WARN_S of simulated time, the
 * run gets a warning saying so, as a car that stands still says nothing of why. */
#define UNPOWERED_WARN_S 1.0
static void check_unpowered(double now_s) {
    if (tfc.hbridge || (tfc.duty_a == 0.0f && tfc.duty_b == 0.0f)) {
        tfc.unpowered_s = -1.0;
        return;
    }
    if (tfc.unpowered_s < 0.0) tfc.unpowered_s = now_s;
    if (tfc.unpowered_warned || now_s - tfc.unpowered_s < UNPOWERED_WARN_S) return;
    tfc.unpowered_warned = 1;
    char text[300];
    snprintf(text, sizeof text, "TFC_SetMotorPWM(%.2f, %.2f) with the H-bridge disabled for %.1f s: the motors "
             "stay off, on the board too (TFC_Init() disables it): enable it with TFC_HBRIDGE_ENABLE",
             tfc.duty_a, tfc.duty_b, now_s - tfc.unpowered_s);
    spinner_warn_at(text, tfc.duty_call);
}

/* The SysTick interrupt's tickers at `now_s` (one count a millisecond). While interrupts are
 * disabled (__disable_irq, DisableInterrupts) SysTick cannot run: its ticks are lost but one, which
 * is pending and counts at the first look after they are enabled again (ARMv6-M: pending is a state,
 * not a count; docs/firmware.md, Critical sections). */
static void count_ticks(double now_s) {  /* (the library: SysTick_Handler counts TFC_Ticker[] and DelayTimerTick) */
    check_unpowered(now_s);
    double whole = floor(now_s * 1000.0 - tfc.ms_counted + 1e-6);  /* SysTicks fallen due since */
    if (whole < 1.0) whole = 0.0;
    tfc.ms_counted += whole;
    if (spinner_interrupts_disabled()) {
        if (whole > 0.0) tfc.tick_pending = 1;
        return;
    }
    uint32_t add = (uint32_t)whole + tfc.tick_pending;
    tfc.tick_pending = 0;
    if (add)
        for (int i = 0; i < TFC_SIM_TICKERS; i++) tickers[i] += add;
}

/* The PIT interrupt's camera read-out (at `now`): the camera's latest frame once a new one is there
 * (one an exposure: the camera's frame period is the exposure), without waiting - on the board the
 * read-out runs beside the main loop, which goes on between two images. A frame found at a pass
 * was not there at the pass before (`looked_s`), so the next one is not due before one period
 * after that: the passes until then do not ask. That period is the exposure written last before
 * the frame found ended (a new LDVAL loads at the PIT's expiry: TFC_SetLineScanExposureTime),
 * which is no shorter than floor_s: the one written last before the frame read before, or one
 * written since (a value written after the frame's end only makes the passes ask sooner). */
static void camera_service(double now) {
    if (now < tfc.next_look_s || spinner_interrupts_disabled()) return;  /* (masked: no read-out) */
    uint8_t row[TFC_LINESCAN_IMAGE_SIZE];
    size_t n = 0;
    long long frame = spinner_latest_image(spinner_line_row(), 1, tfc.frame, row, sizeof row, &n);
    if (n == 0) {
        tfc.looked_s = now;
        return;
    }
    tfc.frame = frame;
    tfc.next_look_s = tfc.looked_s + tfc.floor_s - 1e-9;
    tfc.floor_s = tfc.exposure_s;
    tfc.looked_s = now;
    for (size_t i = 0; i < TFC_LINESCAN_IMAGE_SIZE; i++) {
        uint16_t v = (uint16_t)((i < n ? row[i] : 0) << 4);  /* 8-bit grey -> 12-bit counts */
        LineScanImage0[i] = v;
        LineScanImage1[i] = v;
    }
    image_ready = 1;
}

static void ensure_init(void);

/* One read of the board's state (see POLLS_BEFORE_TIME); in an interrupt handler (--isr) the
 * state at its time (the tickers counted to it), and no time passes there. */
static void poll(void) {
    ensure_init();
    if (spinner_in_interrupt()) {
        count_ticks(spinner_get_time());
        return;
    }
    if (++tfc.polls <= POLLS_BEFORE_TIME) return;
    if (!tfc.masked_poll_warned && spinner_interrupts_disabled() && (tfc.masked_poll_warned = 1))
        spinner_warn("the program polls the board (TFC_Ticker, LineScanImageReady, a button, ...) with "
                     "interrupts disabled: the SysTick and camera interrupts that change them cannot run, "
                     "so on the board such a loop never ends; enable them first (__enable_irq())");
    double now = spinner_get_time();  /* one physics step, as TFC_Task() */
    count_ticks(now);
    camera_service(now);
}

volatile uint8_t *tfc_sim_image_ready(void) {
    poll();
    /* An image is there for the program: its polling starts over. (`LineScanImageReady = 0`
     * comes here too - C cannot tell a write from a read -, and it must not fetch the next
     * image before the program has read this one: a `while (!LineScanImageReady);` loop saw
     * every second image.) */
    if (image_ready) tfc.polls = 0;
    return &image_ready;
}

volatile uint32_t (*tfc_sim_tickers(void))[NUM_TFC_TICKERS] {
    poll();
    return (volatile uint32_t (*)[NUM_TFC_TICKERS])&tickers;
}

/* The kit's own start (the first library call: ensure_init); TFC_Init adds what the library's
 * initialisation leaves in the registers a program reads (TFC_InitADCs). */
static void kit_init(void) {
    if (tfc.inited) return;
    tfc.inited = 1;
    tfc.servo_rad = spinner_param("tfc_servo_rad", 0.40);
    tfc.servo_offset_rad = spinner_param("tfc_servo_offset_rad", 0.0);
    tfc.exposure_s = tfc.floor_s = TFC_DEFAULT_LINESCAN_EXPOSURE_TIME_uS * 1e-6;
    /* The library's SI pulses come from PIT0, free-running at the exposure (TFC_LineScanCamera.c:
     * TFC_SetLineScanExposureTime writes PIT_LDVAL0; each PIT0 interrupt pulses SI and starts the
     * ADC read-out of the previous integration while the next integrates - TSL1401: integration
     * runs from one SI to the next): one image an exposure, each ready a read-out after its SI.
     * TFC_InitADCs writes LDVAL0 before it enables the timer: the first period is that one. */
    spinner_camera_free_running();
    spinner_set_exposure(tfc.exposure_s);
    tfc.ms_counted = floor(spinner_get_time() * 1000.0);
    uint8_t row[TFC_LINESCAN_IMAGE_SIZE];  /* the first image: the frame after TFC_Init's */
    tfc.frame = spinner_latest_image(spinner_line_row(), 0, LLONG_MAX, row, sizeof row, NULL);
    tfc_sim_timers_init();
    send_commands();
}

void TFC_Init(void) {  /* (the library's: InitClock, ..., TFC_InitServos, TFC_InitMotorPWM, TFC_InitADCs, ...) */
    tfc.motor_pwm_on = tfc.servos_on = 1;
    kit_init();
    TFC_InitADCs();
}

static void ensure_init(void) {
    if (!tfc.inited) kit_init();
}

void TFC_Task(void) {
    ensure_init();
    tfc.polls = 0;
    double now = spinner_get_time();  /* the main loop's pass: a physics step of simulated time */
    count_ticks(now);
    camera_service(now);
}

void tfc_sim_wfi(void) { TFC_Task(); }  /* __WFI() (derivative.h) */

void TFC_Delay_mS(unsigned int TicksIn_mS) {
    ensure_init();
    if (spinner_in_interrupt()) {  /* no time passes in a handler: the delay would never end */
        char text[200];
        snprintf(text, sizeof text, "TFC_Delay_mS(%u) inside an interrupt handler: no simulated time "
                 "passes there, so the delay would never end; wait in the main loop", TicksIn_mS);
        spinner_fail(text);
    }
    if (spinner_interrupts_disabled() && TicksIn_mS > 0) {  /* the library waits for SysTick_Handler to count DelayTimerTick up to it */
        char text[240];
        snprintf(text, sizeof text, "TFC_Delay_mS(%u) with interrupts disabled: the library's delay counts "
                 "SysTick interrupts, which cannot run then, so on the board it never returns; enable "
                 "them first (__enable_irq())", TicksIn_mS);
        spinner_fail(text);
    }
    tfc.polls = 0;
    double until = spinner_get_time() + TicksIn_mS * 1e-3;
    for (double now = spinner_get_time(); now < until - 1e-9; now = spinner_get_time()) {
        count_ticks(now);
        camera_service(now);
    }
}

void TFC_InitSysTick(void) {}
void InitClock(void) {}
void TFC_InitGPIO(void) {}
void TFC_InitServos(void) { tfc.servos_on = 1; }
void TFC_InitMotorPWM(void) { tfc.motor_pwm_on = 1; }
void TFC_InitADCs(void) {  /* the pots', battery's and camera's ADC: its PIT (timers.c) */
    ensure_init();
    tfc_sim_timers_library_pit();
    if (!tfc.adc_on) {  /* (the library writes LDVAL0 with its default exposure, then enables PIT0) */
        tfc.adc_on = 1;
        tfc.adc_first_s = spinner_now_uncharged() + TFC_DEFAULT_LINESCAN_EXPOSURE_TIME_uS * 1e-6;
    }
}
void TFC_InitLineScanCamera(void) {}
void TFC_InitUARTs(void) {}
void TFC_UART_Process(void) {}
void TFC_InitTerminal(void) {}
void TFC_ProcessTerminal(void) {}

void TFC_SetServo(uint8_t ServoNumber, float Position) {
    servo_check("TFC_SetServo");
    if (ServoNumber != 0) return;  /* servo 1: nothing on the simulated car */
    tfc.servo = (float)clampf(Position, -1.0, 1.0);
    send_commands();
}

void TFC_SetServoDutyCycle(uint8_t ServoNumber, float DutyCycle) {
    servo_check("TFC_SetServoDutyCycle");
    /* a 1.0 .. 2.0 ms pulse of the 20 ms frame is the servo's travel -1 .. 1 */
    double mid = 0.5 * (SERVO_MIN_DUTY_CYCLE + SERVO_MAX_DUTY_CYCLE);
    double half = 0.5 * (SERVO_MAX_DUTY_CYCLE - SERVO_MIN_DUTY_CYCLE);
    TFC_SetServo(ServoNumber, (float)((DutyCycle - mid) / half));
}

void TFC_SetMotorPWM(float MotorA, float MotorB) {
    tfc.duty_call = __builtin_return_address(0);
    motor_pwm_check();
    tfc.duty_a = (float)clampf(MotorA, -1.0, 1.0);
    tfc.duty_b = (float)clampf(MotorB, -1.0, 1.0);
    send_commands();
}

void tfc_sim_hbridge(int on) {
    tfc.hbridge = on != 0;
    send_commands();
}

void tfc_sim_led(int led, int on) {
    if (led < 0 || led > 3) return;
    tfc.leds[led] = on < 0 ? !tfc.leds[led] : on != 0;
}

void TFC_SetBatteryLED_Level(uint8_t BattLevel) {
    for (int i = 0; i < 4; i++) tfc.leds[i] = i < BattLevel;
}

int tfc_sim_button(int button) {
    poll();
    char name[16];
    snprintf(name, sizeof name, "button%d", button);
    if (spinner_param(name, 0.0) != 0.0) return 1;
    if (button == 0) {  /* a start press: button 0 held 0.2 s from button0_at */
        double at = spinner_param("button0_at", 0.1), now = spinner_get_time();
        return now >= at && now < at + 0.2;
    }
    return 0;
}

uint8_t TFC_GetDIP_Switch(void) {
    poll();
    return (uint8_t)((int)spinner_param("dip", 0.0) & 0x0F);
}

/* The pots and the battery are read by the library's ADC interrupts, not by TFC_ReadPot: FRDM-TFC
 * TFC_ADC.c, TFC_InitADCs enables PIT0 ("The pump will be primed with the PIT interrupt"); each
 * PIT_IRQHandler starts the conversions (pot 0, pot 1, the battery, then the camera's pixels) and
 * ADC0_IRQHandler stores them in PotADC_Value[] and BatSenseADC_Value, which the read functions
 * scale. Until the first PIT0 interrupt, one exposure after TFC_InitADCs (TFC_Init calls it), those
 * counts are still 0 - and stay 0 without TFC_Init -, so the library returns 1.0 for a pot and 0 V for
 * the battery: here too, with a warning at the program's first such read. The counts are 12-bit
 * (ADC_MAX_CODE 4095): TFC_ReadPot = 1 - count / 2047.5, in the library's arithmetic. */
#define TFC_ADC_MAX_CODE 4095.0
static int adc_converted(const char *read, int *warned, const void *call) {
    double now = spinner_now_uncharged();  /* (a look: no time passes) */
    if (tfc.adc_on && now >= tfc.adc_first_s - 1e-9) return 1;
    if (!*warned) {
        *warned = 1;
        char text[400];
        if (tfc.adc_on)
            snprintf(text, sizeof text, "%s at t = %.3f s, before the ADC's first conversion (%.3f s: the first PIT0 "
                     "interrupt, one exposure after TFC_Init): its count is still 0, so the library returns %s, "
                     "on the board too; read it once the first image is in (LineScanImageReady)",
                     read, now, tfc.adc_first_s, strcmp(read, "TFC_ReadBatteryVoltage()") ? "1.0" : "0 V");
        else
            snprintf(text, sizeof text, "%s before TFC_Init(): the ADC that reads it runs from TFC_Init (TFC_InitADCs), so "
                     "its count is 0 and the library returns %s, on the board too; call TFC_Init() first", read,
                     strcmp(read, "TFC_ReadBatteryVoltage()") ? "1.0" : "0 V");
        spinner_warn_at(text, call);
    }
    return 0;
}

float TFC_ReadPot(uint8_t Channel) {
    const void *call = __builtin_return_address(0);
    poll();
    char read[40];
    snprintf(read, sizeof read, "TFC_ReadPot(%d)", Channel);
    uint16_t count = 0;  /* PotADC_Value[]: the pot's position -1..1 at counts 4095..0 */
    if (adc_converted(read, &tfc.early_pot_warned, call))
        count = (uint16_t)lround((1.0 - clampf(spinner_param(Channel == 0 ? "pot0" : "pot1", 0.0), -1.0, 1.0))
                                 * TFC_ADC_MAX_CODE / 2.0);
    return (float)(((float)count / -((float)TFC_ADC_MAX_CODE / 2.0)) + 1.0);
}

/* The library returns the battery sense input, not the battery's voltage: FRDM-TFC TFC_ADC.c,
 * `return (((float)BatSenseADC_Value/(float)(ADC_MAX_CODE)) * 3.0);// * ((47000.0+10000.0)/10000.0);`
 * - the shield's divider (47k over 10k) is the commented-out factor; and its 3.0 V is not the ADC's
 * full scale, which is the FRDM-KL25Z's 3.3 V supply (VREFH; "0 v or 3.3 v give 0 and close to
 * 65535", os.mbed.com/questions/75223): the library reads sense x 3.0 / 3.3 (1.15 at 7.2 V), the
 * 12-bit count (ADC_MAX_CODE 4095) as the library converts it; as the mbed kit's. */
#define TFC_ADC_FULL_SCALE_V 3.3
float TFC_ReadBatteryVoltage(void) {
    const void *call = __builtin_return_address(0);
    ensure_init();
    if (!adc_converted("TFC_ReadBatteryVoltage()", &tfc.early_battery_warned, call)) return 0.0f;
    double sense_v = clampf(spinner_param("battery_v", 7.2) * 10000.0 / 57000.0, 0.0, TFC_ADC_FULL_SCALE_V);
    return (float)(round(sense_v / TFC_ADC_FULL_SCALE_V * TFC_ADC_MAX_CODE) / TFC_ADC_MAX_CODE * 3.0);
}

/* The library writes PIT_LDVAL0 (TFC_LineScanCamera.c) while PIT0 runs: the KL25 loads a new LDVAL
 * at the timer's next expiry, it does not restart the period (KL25 Sub-Family Reference Manual,
 * KL25P80M48SF0RM, PIT chapter 32, the Timer Load Value Register PIT_LDVALn, field TSV: "Writing a
 * new value to this register will not restart the timer; instead the value will be loaded after
 * the timer expires"). So the frame in progress ends on the old period and keeps its exposure (its
 * brightness); the next SI starts an integration of the new exposure, one period long. LDVAL is one
 * register: of several writes in a frame the last loads. The simulator loads it at the camera's
 * next frame boundary (spinner_set_exposure_next_frame), whatever the program does meanwhile -
 * also when it calls the kit no more in that frame, in a handler (--isr) or with --mcu-time. */
void TFC_SetLineScanExposureTime(uint32_t TimeIn_uS) {
    tfc.exposure_s = clampf(TimeIn_uS * 1e-6, 1e-5, 1.0);
    if (tfc.exposure_s < tfc.floor_s) tfc.floor_s = tfc.exposure_s;
    spinner_set_exposure_next_frame(tfc.exposure_s);
}

void InitByteQueue(ByteQueue *BQ, uint16_t Size, uint8_t *Storage) {
    BQ->ReadPtr = BQ->WritePtr = 0, BQ->QueueSize = Size, BQ->QueueStorage = Storage;
}
uint16_t BytesInQueue(ByteQueue *BQ) { (void)BQ; return 0; }
int16_t ByteEnqueue(ByteQueue *BQ, uint8_t Val) { (void)BQ; putchar(Val); return 0; }
int16_t ByteDequeue(ByteQueue *BQ, uint8_t *Val) { (void)BQ; (void)Val; return -1; }

uint32_t Qprintf(ByteQueue *BQ, const char *FormatString, ...) {
    (void)BQ;
    va_list ap;
    va_start(ap, FormatString);
    int n = vprintf(FormatString, ap);
    va_end(ap);
    return n < 0 ? 0 : (uint32_t)n;
}
