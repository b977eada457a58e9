/* The NXP Cup S32K144 kit's drivers on the simulated car (simrunner drive FIRMWARE.c --kit s32k144).
 *
 * The team's sources build unchanged against include/ (the kit's driver headers: servo.h,
 * hbridge.h, esc.h, linear_camera.h, display.h, main_functions.h, and the few RTD headers
 * they name) and this file, which talks to the simulator through spinner.h. The API (names,
 * signatures, units, ranges) is that of NXP's Nxp_Cup_Linear_Camera_S32K144 sample as
 * published in github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * documented in github.com/NXPHoverGames/GitBook-NXPCup
 * (2024-fall-2025-nxp-cup-bare-metal-drivers/drivers-description-and-usage/); the code is ours.
 *
 * The drivers act as the kit's do, through the PWM and DIO layer below them: a PWM channel's
 * duty (0 .. 0x8000) and a DIO pin's level are kept, and the channels the drivers' Init calls
 * named act on the car:
 * - the servo channel steers (calibrated by ServoInit: Med straight, Max full right, Min full
 *   left; full = --param s32k_servo_rad, + s32k_servo_offset_rad);
 * - the H-bridge's two motor channels are the left and right rear motors' duties, their sign
 *   from the direction pins (spinner_set_motors); the ESC's channel drives both, its pulse set by
 *   the sample driver's state machine at each period of the ESC's PWM, taken as a car ESC takes it
 *   (esc.h: the brake of a brake-capable ESC is duty 0);
 * - LinearCameraGetFrame waits for the camera's next image of its line row;
 * - Pixy2GetVectors (PixyGetVectors) reads the simulator's Pixy2 (pixy2_line.h);
 * - the display's text and graph go to the debug video; OsIf's clocks count simulated time;
 *   the Gpt channels and their notifications are gpt.c's, the Adc groups (a team's own analog inputs,
 *   their values from --param s32k_adc_<n>) adc.c's;
 * - the board's buttons SW2 and SW3 and constant input levels are DIO channels --param names
 *   (s32k_sw2, s32k_sw3, s32k_pin_N: read_buttons, pin_of); a loop polling one lets time pass.
 * docs/firmware.md, "The S32K144 kit", lists what is emulated and what is not. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "spinner.h"
#include "servo.h"
#include "hbridge.h"
#include "esc.h"
#include "linear_camera.h"
#include "display.h"
#include "main_functions.h"
#include "pixy2.h"
#include "receiver.h"
#include "OsIf.h"
#include "sim_poll.h"
#include "Gpt.h"
#include "pixy2_line.h"

#define NUM_PWM 256
#define NUM_DIO 256
#define DUTY_FULL 0x8000

enum role { NONE, SERVO, MOTOR1, MOTOR2, ESC };

/* What drives a DIO channel: nothing (the program: it reads what it last wrote), a constant level
 * (--param s32k_pin_N), or one of the board's buttons (--param s32k_sw2, s32k_sw3). PIN_UNSEEN: its
 * --param not looked up yet (at the channel's first read or write). */
enum pin { PIN_UNSEEN, PIN_OUTPUT, PIN_LOW, PIN_HIGH, PIN_SW2, PIN_SW3 };
#define MAX_PRESSES 8  /* a button's presses: s32k_swN_at, s32k_swN_at_2 .. _8 */

static struct {
    uint16 pwm[NUM_PWM];          /* each PWM channel's duty, 0 .. 0x8000 */
    uint8 dio[NUM_DIO];           /* each DIO channel's level */
    uint8 role[NUM_PWM];          /* what a PWM channel drives on the car (enum role) */
    uint8 params_read;
    uint8 buttons_read;             /* read_buttons done (at the first Dio call) */
    double servo_rad, servo_offset_rad;
    double osif_hz;
    uint32 osif_dummy;              /* OSIF_COUNTER_DUMMY: one count a call, as the RTD's */
    double pin_polled_at;           /* Dio_ReadChannel's polls at one simulated time, no write between */
    long pin_polls;
    SimPoll input_poll;             /* reads of input pins (--param) at one simulated time (sim_poll.h) */
    uint8 pin[NUM_DIO];             /* what drives each DIO channel (enum pin), from --param */
    int sw_channel[2];              /* SW2's and SW3's Dio channels (-1: not given) */
    double sw_at[2][MAX_PRESSES];   /* their presses (s; < 0: none), in order, each BUTTON_HELD_S long */
    int sw_pressed_level[2];        /* the level a pressed button reads (STD_HIGH on the EVB) */
    Servo servo;
    Hbridge hbridge;
    Esc esc;                        /* the driver's state, as the sample's EscInstance */
    double esc_hz;                  /* the ESC PWM's period edges a second (--param s32k_esc_hz) */
    uint8 esc_running;              /* the state machine's timer set up (EscInit) */
    uint8 esc_braking;              /* the car's ESC: forward pulses seen since its last stop pulse */
    char screen[CharacterRows][CharacterColumns];
    uint8 graph[128];
    uint16 graph_len;
} k;

static double clamp(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* A kit function the simulator does not emulate: the run ends here as controller_error, naming
 * it and why, with the backtrace to the calling file:line. */
__attribute__((noreturn)) static void not_emulated(const char *name, const char *why) {
    char message[512];
    snprintf(message, sizeof message, "%s: not emulated by the simulator's S32K144 kit: %s "
             "(docs/firmware.md, \"The S32K144 kit\")", name, why);
    spinner_fail(message);
}

#define BENCH_TEST "the drivers' bench test loops for ever on the bench"
#define NO_RECEIVER "the simulator has no remote control"
#define NOT_GIVEN -1e300  /* spinner_param's default: the --param was not given */

__attribute__((noreturn)) static void bad_param(const char *name, double value, const char *expected) {
    char text[400];
    snprintf(text, sizeof text, "--param %s=%g: expected %s (docs/firmware.md, \"The S32K144 kit\")", name, value,
             expected);
    spinner_fail(text);
}

/* The S32K144EVB's user buttons SW2 (PTC12) and SW3 (PTC13) on the Dio channels --param s32k_sw2 and
 * s32k_sw3 say (a team's generated DioConf_DioChannel_... value: the kit cannot know it). A button reads
 * STD_HIGH while pressed and STD_LOW released: on the EVB a pressed button drives its pin high (NXP's
 * S32K144 cookbook examples, AN5413 "Hello World": "If Pad Data Input = 1 (BTN0 [SW2] pushed)"; NuttX's
 * s32k144evb board_buttons() reads a set pin as pressed). A board of the team's own that wires its
 * button to ground with a pull-up reads the other way: --param s32k_sw2_pressed_level=0 (sw3's alike)
 * makes the pressed level STD_LOW, the released one STD_HIGH. Each is pressed for BUTTON_HELD_S at
 * --param s32k_sw2_at (default 0.1 s, as --kit tfc's start press of button 0) / s32k_sw3_at (not
 * pressed unless given), and again at s32k_sw2_at_2, _at_3, ... (up to MAX_PRESSES; numbers, not a
 * list: batch's comma is a sweep), each after the one before it has been released. */
#define BUTTON_HELD_S 0.2

static void read_presses(int b, int given) {
    static const char *const at_names[2] = {"s32k_sw2_at", "s32k_sw3_at"};
    char name[40], expected[160];
    for (int i = 0; i < MAX_PRESSES; i++) k.sw_at[b][i] = -1.0;
    double at = spinner_param(at_names[b], NOT_GIVEN);
    if (!given && at != NOT_GIVEN)
        bad_param(at_names[b], at, b == 0 ? "the button's Dio channel too: --param s32k_sw2=N"
                                          : "the button's Dio channel too: --param s32k_sw3=N");
    if (!given) return;
    if (at != NOT_GIVEN && !(at >= 0.0)) bad_param(at_names[b], at, "the simulated time of the press, in s (0 or more)");
    k.sw_at[b][0] = at != NOT_GIVEN ? at : (b == 0 ? 0.1 : -1.0);
    for (int i = 1; i < MAX_PRESSES; i++) {
        snprintf(name, sizeof name, "%s_%d", at_names[b], i + 1);
        double next = spinner_param(name, NOT_GIVEN);
        if (next == NOT_GIVEN) return;
        if (k.sw_at[b][i - 1] < 0.0) bad_param(name, next, "the presses before it given too (s32k_sw3_at, _at_2, ...)");
        snprintf(expected, sizeof expected, "a press after the one before it is released: %g s or later (%s, held %g s)",
                 k.sw_at[b][i - 1] + BUTTON_HELD_S, i == 1 ? at_names[b] : "the press before", BUTTON_HELD_S);
        if (!(next >= k.sw_at[b][i - 1] + BUTTON_HELD_S - 1e-9)) bad_param(name, next, expected);
        k.sw_at[b][i] = next;
    }
    snprintf(name, sizeof name, "%s_%d", at_names[b], MAX_PRESSES + 1);
    double more = spinner_param(name, NOT_GIVEN);
    if (more != NOT_GIVEN) bad_param(name, more, "at most 8 presses of a button (s32k_swN_at, _at_2 .. _at_8)");
}

static void read_buttons(void) {
    static const char *const names[2] = {"s32k_sw2", "s32k_sw3"};
    static const char *const level_names[2] = {"s32k_sw2_pressed_level", "s32k_sw3_pressed_level"};
    double channel[2];
    for (int b = 0; b < 2; b++) {
        channel[b] = spinner_param(names[b], NOT_GIVEN);
        k.sw_pressed_level[b] = STD_HIGH;
        /* (read for a button given only: one without its channel is a --param never read, which the run
         * warns of, naming those read) */
        double level = channel[b] == NOT_GIVEN ? NOT_GIVEN : spinner_param(level_names[b], NOT_GIVEN);
        if (channel[b] != NOT_GIVEN &&
            !(channel[b] >= 0.0 && channel[b] < NUM_DIO && channel[b] == (double)(int)channel[b]))
            bad_param(names[b], channel[b], b == 0 ? "the Dio channel of the board's button SW2 (PTC12): a whole number "
                      "0..255, your configuration's DioConf_DioChannel_... value" : "the Dio channel of the board's "
                      "button SW3 (PTC13): a whole number 0..255, your configuration's DioConf_DioChannel_... value");
        if (level != NOT_GIVEN && level != 0.0 && level != 1.0)
            bad_param(level_names[b], level, "0 or 1: the level the pin reads while the button is pressed (1, STD_HIGH: "
                      "the EVB's; 0, STD_LOW: a button to ground with a pull-up)");
        if (level != NOT_GIVEN) k.sw_pressed_level[b] = level == 1.0 ? STD_HIGH : STD_LOW;
        read_presses(b, channel[b] != NOT_GIVEN);
    }
    if (channel[0] != NOT_GIVEN && channel[0] == channel[1])
        bad_param("s32k_sw3", channel[1], "a Dio channel other than SW2's (--param s32k_sw2)");
    for (int b = 0; b < 2; b++) k.sw_channel[b] = channel[b] == NOT_GIVEN ? -1 : (int)channel[b];
}

static void read_params(void) {
    if (k.params_read) return;
    k.params_read = 1;
    k.servo_rad = spinner_param("s32k_servo_rad", 0.40);
    k.servo_offset_rad = spinner_param("s32k_servo_offset_rad", 0.0);
    k.osif_hz = spinner_param("s32k_osif_hz", 48e6);  /* the default: OsIf.h says whose */
    k.esc_hz = spinner_param("s32k_esc_hz", 50.0);    /* the default: esc.h says whose */
}

/* What drives channel c: at its first read or write, a button's channel (read_buttons) or --param
 * s32k_pin_<c> (0 or 1: a constant level, a mode switch's), else the program. */
static enum pin pin_of(Dio_ChannelType c) {
    read_params();
    if (!k.buttons_read) k.buttons_read = 1U, read_buttons();  /* at the first Dio call: a bad value ends the
                                                                * run there; a firmware using no pin reads none */
    if (c >= NUM_DIO) return PIN_OUTPUT;
    if (k.pin[c] != PIN_UNSEEN) return (enum pin)k.pin[c];
    char name[32];
    snprintf(name, sizeof name, "s32k_pin_%u", (unsigned)c);
    double level = spinner_param(name, NOT_GIVEN);
    int sw = c == k.sw_channel[0] ? 0 : (c == k.sw_channel[1] ? 1 : -1);
    if (sw >= 0 && level != NOT_GIVEN)
        bad_param(name, level, sw == 0 ? "no level for SW2's channel (--param s32k_sw2)"
                                       : "no level for SW3's channel (--param s32k_sw3)");
    if (level != NOT_GIVEN && level != 0.0 && level != 1.0)
        bad_param(name, level, "0 or 1: the level the input pin reads (STD_LOW, STD_HIGH)");
    k.pin[c] = (uint8)(sw >= 0 ? PIN_SW2 + sw : (level == NOT_GIVEN ? PIN_OUTPUT : (level == 1.0 ? PIN_HIGH : PIN_LOW)));
    return (enum pin)k.pin[c];
}

/* An input pin's level at simulated time now. */
static Dio_LevelType input_level(enum pin p, double now) {
    if (p == PIN_LOW || p == PIN_HIGH) return p == PIN_HIGH ? STD_HIGH : STD_LOW;
    int b = p == PIN_SW2 ? 0 : 1, pressed = 0;
    for (int i = 0; i < MAX_PRESSES && k.sw_at[b][i] >= 0.0; i++) {
        double at = k.sw_at[b][i];
        if (now >= at - 1e-9 && now < at + BUTTON_HELD_S - 1e-9) pressed = 1;
    }
    return (Dio_LevelType)(pressed ? k.sw_pressed_level[b] : !k.sw_pressed_level[b]);
}

/* -1 .. 1 of a pulse between its calibrated ends (+ towards hi, - towards lo), 0 at mid. The ends
 * may lie either side of mid: a mirrored servo's ServoInit passes Max < Med < Min, and the sample's
 * Steer still goes from Med towards Max for + and towards Min for - (src/servo.c: Med + Direction *
 * (Max - Med) / 100, Med - Direction * (Min - Med) / 100). */
static double position(uint16 duty, uint16 lo, uint16 mid, uint16 hi) {
    double d = (double)duty - mid, to_hi = (double)hi - mid, to_lo = (double)lo - mid;
    if (to_hi != 0.0 && d * to_hi > 0.0) return clamp(d / to_hi, 0.0, 1.0);
    if (to_lo != 0.0 && d * to_lo > 0.0) return -clamp(d / to_lo, 0.0, 1.0);
    return 0.0;
}

static double motor_duty(Pwm_ChannelType channel, Dio_ChannelType fwd, Dio_ChannelType bwd) {
    int f = fwd < NUM_DIO && k.dio[fwd] != STD_LOW, b = bwd < NUM_DIO && k.dio[bwd] != STD_LOW;
    double duty = clamp((double)k.pwm[channel] / DUTY_FULL, 0.0, 1.0);
    return f == b ? 0.0 : (f ? duty : -duty);
}

/* The car's commands from the channels' state (after any PWM or DIO change). */
static void apply(Pwm_ChannelType changed) {
    read_params();
    enum role r = changed < NUM_PWM ? k.role[changed] : NONE;
    if (r == SERVO) {
        Servo *s = &k.servo;  /* Max = full right: minus, as + is left in the simulator */
        double pos = position(k.pwm[s->ServoPwmChannel], s->MinDutyCycle, s->MedDutyCycle, s->MaxDutyCycle);
        spinner_set_servo(-pos * k.servo_rad + k.servo_offset_rad);
    } else if (r == MOTOR1 || r == MOTOR2) {
        Hbridge *h = &k.hbridge;
        spinner_set_motors((float)motor_duty(h->Motor1_Speed, h->Motor1_Forward, h->Motor1_Backward),
                           (float)motor_duty(h->Motor2_Speed, h->Motor2_Forward, h->Motor2_Backward));
    } else if (r == ESC) {
        double d = position(k.pwm[k.esc.Channel], k.esc.MinDutyCycle, k.esc.MedDutyCycle, k.esc.MaxDutyCycle);
#if ESC_HAS_BRAKE == STD_ON
        /* a car ESC in forward/reverse-with-brake mode: below the stop pulse after forward ones it
         * brakes (duty 0: a "brake" H-bridge car's motors shorted), until a stop pulse arms reverse */
        if (d > 0.0) k.esc_braking = 1U;
        else if (d == 0.0) k.esc_braking = 0U;
        else if (k.esc_braking) d = 0.0;
#endif
        spinner_set_motors((float)d, (float)d);
    }
}

/* ---- the RTD layer the drivers stand on ---- */

void Pwm_SetDutyCycle(Pwm_ChannelType ChannelNumber, uint16 DutyCycle) {
    k.pwm[ChannelNumber] = DutyCycle > DUTY_FULL ? DUTY_FULL : DutyCycle;
    apply(ChannelNumber);
}

/* A write to an input pin (--param s32k_sw2, s32k_sw3, s32k_pin_N) is ignored, as the Dio driver does
 * on a channel configured as an input (AUTOSAR SWS_Dio_00029, 00079: no influence on the output nor
 * on the next read). */
void Dio_WriteChannel(Dio_ChannelType ChannelId, Dio_LevelType Level) {
    k.pin_polls = 0;  /* a write between reads: the program drives its pins (bit-banging) */
    if (ChannelId >= NUM_DIO || pin_of(ChannelId) != PIN_OUTPUT) return;
    k.dio[ChannelId] = Level;
    Hbridge *h = &k.hbridge;  /* a direction pin of the H-bridge: the motors' sign changes */
    if (k.role[h->Motor1_Speed] == MOTOR1 && (ChannelId == h->Motor1_Forward || ChannelId == h->Motor1_Backward ||
                                              ChannelId == h->Motor2_Forward || ChannelId == h->Motor2_Backward))
        apply(h->Motor1_Speed);
}

/* A loop polling a pin nothing drives (no --param names it: a sensor's echo, a button not given) reads
 * again and again at one simulated time, with no write between: a loop that never ends (a start-button
 * wait); the run ends at its line, saying why, rather than as stalled after the wall-time limit.
 * An input pin's reads let no time pass, but after SIM_POLLS_FREE reads at one time (writes
 * between or not) each lets one physics step pass, as gpt.c's reads and the TFC kit's polls do: on
 * the board a person presses the button meanwhile. So `while (Dio_ReadChannel(SW2) == STD_LOW);` ends
 * at the press, within a physics step. In an interrupt handler no time passes. */
#define PIN_POLLS 100000

Dio_LevelType Dio_ReadChannel(Dio_ChannelType ChannelId) {
    enum pin p = pin_of(ChannelId);
    if (p != PIN_OUTPUT) {
        return input_level(p, sim_poll_time(&k.input_poll));
    }
    if (!spinner_in_interrupt()) {
        double now = spinner_now();
        if (now != k.pin_polled_at) k.pin_polled_at = now, k.pin_polls = 0;
        else if (++k.pin_polls >= PIN_POLLS) {
            char text[500];
            snprintf(text, sizeof text, "Dio_ReadChannel(%u): read %d times with no write and no simulated time "
                     "passing: a loop waiting for the pin never ends - the simulator drives no pin but the inputs "
                     "--param names (s32k_sw2, s32k_sw3: the board's buttons; s32k_pin_%u=0/1: a constant level), "
                     "one reads what was last written to it (docs/firmware.md, \"The S32K144 kit\")",
                     (unsigned)ChannelId, PIN_POLLS, (unsigned)ChannelId);
            spinner_fail(text);
        }
    }
    return ChannelId < NUM_DIO ? k.dio[ChannelId] : STD_LOW;
}

/* An input pin's flip writes nothing and returns its level (AUTOSAR SWS_Dio_00192, 00193). */
Dio_LevelType Dio_FlipChannel(Dio_ChannelType ChannelId) {
    Dio_LevelType now = Dio_ReadChannel(ChannelId);
    if (pin_of(ChannelId) != PIN_OUTPUT) return now;
    Dio_LevelType level = now == STD_LOW ? STD_HIGH : STD_LOW;
    Dio_WriteChannel(ChannelId, level);
    return level;
}

uint32 OsIf_GetMilliseconds(void) { return (uint32)(spinner_get_time() * 1000.0 + 1e-6); }

void OsIf_TimeDelay(const uint32 delayMs) { spinner_sleep(delayMs * 1e-3); }

volatile int s32k_sim_suspend_nesting;        /* OsIf.h's nested Suspend/ResumeAllInterrupts */
volatile uint32 s32k_sim_suspend_primask;

void OsIf_Init(const void *Config) { (void)Config; read_params(); }

/* simulated seconds as ticks of hz, modulo 2^32 as a 32-bit counter wraps */
static uint32 ticks(double seconds, double hz) { return (uint32)(uint64_t)(seconds * hz + 1e-6); }

uint32 OsIf_GetCounter(OsIf_CounterType SelectedCounter) {
    read_params();
    if (SelectedCounter == OSIF_COUNTER_DUMMY) return ++k.osif_dummy;
    return ticks(spinner_get_time(), k.osif_hz);
}

uint32 OsIf_GetElapsed(uint32 *const CurrentRef, OsIf_CounterType SelectedCounter) {
    uint32 now = OsIf_GetCounter(SelectedCounter), elapsed = now - *CurrentRef;  /* wraps as the RTD's */
    *CurrentRef = now;
    return elapsed;
}

void OsIf_SetTimerFrequency(uint32 Freq, OsIf_CounterType SelectedCounter) {
    read_params();
    if (SelectedCounter != OSIF_COUNTER_DUMMY) k.osif_hz = Freq;
}

uint32 OsIf_MicrosToTicks(uint32 Micros, OsIf_CounterType SelectedCounter) {
    read_params();
    if (SelectedCounter == OSIF_COUNTER_DUMMY) return Micros;
    return (uint32)((uint64_t)Micros * (uint64_t)k.osif_hz / 1000000U);
}

/* ---- servo.h ---- */

void ServoInit(Pwm_ChannelType ServoPwmChannel, uint16 MaxDutyCycle, uint16 MinDutyCycle, uint16 MedDutyCycle) {
    k.servo = (Servo){ServoPwmChannel, MinDutyCycle, MaxDutyCycle, MedDutyCycle};
    k.role[ServoPwmChannel] = SERVO;
    Pwm_SetDutyCycle(ServoPwmChannel, MedDutyCycle);
}

void Steer(int Direction) {
    Servo *s = &k.servo;
    int d = Direction > 100 ? 100 : (Direction < -100 ? -100 : Direction);
    int span = d > 0 ? s->MaxDutyCycle - s->MedDutyCycle : s->MedDutyCycle - s->MinDutyCycle;
    Pwm_SetDutyCycle(s->ServoPwmChannel, (uint16)(s->MedDutyCycle + d * span / 100));
}

void SteerLeft(void) { Pwm_SetDutyCycle(k.servo.ServoPwmChannel, k.servo.MinDutyCycle); }
void SteerRight(void) { Pwm_SetDutyCycle(k.servo.ServoPwmChannel, k.servo.MaxDutyCycle); }
void SteerStraight(void) { Pwm_SetDutyCycle(k.servo.ServoPwmChannel, k.servo.MedDutyCycle); }

/* ---- hbridge.h ---- */

void HbridgeInit(Pwm_ChannelType Motor1_Speed, Pwm_ChannelType Motor2_Speed, Dio_ChannelType Motor1_Forward,
                 Dio_ChannelType Motor1_Backward, Dio_ChannelType Motor2_Forward, Dio_ChannelType Motor2_Backward) {
    k.hbridge = (Hbridge){Motor1_Speed, Motor2_Speed, Motor1_Forward, Motor1_Backward, Motor2_Forward,
                          Motor2_Backward, 0U, 0};
    k.role[Motor1_Speed] = MOTOR1;
    k.role[Motor2_Speed] = MOTOR2;
    apply(Motor1_Speed);  /* idle: whatever the channels hold (0 after reset) */
}

void HbridgeSetSpeed(int Speed) {
    Hbridge *h = &k.hbridge;
    h->Speed = Speed;
    if (h->Brake != 0U) return;
    int s = Speed > 100 ? 100 : (Speed < -100 ? -100 : Speed);
    Dio_LevelType fwd = s >= 0 ? STD_HIGH : STD_LOW, bwd = s >= 0 ? STD_LOW : STD_HIGH;
    uint16 duty = (uint16)((uint32)abs(s) * DUTY_FULL / 100U);
    Dio_WriteChannel(h->Motor1_Forward, fwd);
    Dio_WriteChannel(h->Motor1_Backward, bwd);
    Dio_WriteChannel(h->Motor2_Forward, fwd);
    Dio_WriteChannel(h->Motor2_Backward, bwd);
    Pwm_SetDutyCycle(h->Motor1_Speed, duty);
    Pwm_SetDutyCycle(h->Motor2_Speed, duty);
}

void HbridgeSetBrake(uint8 Brake) {
    Hbridge *h = &k.hbridge;
    if (Brake == 0U) {
        h->Brake = 0U;
        HbridgeSetSpeed(h->Speed);
        return;
    }
    h->Brake = 1U;
    Dio_WriteChannel(h->Motor1_Forward, STD_LOW);
    Dio_WriteChannel(h->Motor1_Backward, STD_LOW);
    Dio_WriteChannel(h->Motor2_Forward, STD_LOW);
    Dio_WriteChannel(h->Motor2_Backward, STD_LOW);
    Pwm_SetDutyCycle(h->Motor1_Speed, DUTY_FULL);
    Pwm_SetDutyCycle(h->Motor2_Speed, DUTY_FULL);
}

int HbridgeGetSpeed(void) { return k.hbridge.Speed; }
uint8 HbridgeGetBrake(void) { return k.hbridge.Brake; }

/* ---- esc.h ---- */

/* The driver's pulse for a speed command -100 .. 100, in the sample's integer steps. */
static void esc_pulse(int command) {
    int span = command >= 0 ? k.esc.MaxDutyCycle - k.esc.MedDutyCycle : k.esc.MedDutyCycle - k.esc.MinDutyCycle;
    Pwm_SetDutyCycle(k.esc.Channel, (uint16)(k.esc.MedDutyCycle + command * span / 100));
}

/* The state the driver's machine goes to from its state at a period's edge (the sample's src/esc.c,
 * Esc_Period_Finished): with ESC_HAS_BRAKE on, forward goes to reverse through Braking and Neutral. */
static enum EscStates esc_next(enum EscStates state, int speed, int brake) {
    switch (state) {
    case Forward:
#if ESC_HAS_BRAKE == STD_ON
        return brake || speed < 0 ? Braking : Forward;
#else
        return brake ? Braking : (speed < 0 ? Reverse : (speed == 0 ? Neutral : Forward));
#endif
    case Braking:
#if ESC_HAS_BRAKE == STD_ON
        return brake ? Braking : (speed > 0 ? Forward : Neutral);
#else
        return brake ? Neutral : (speed < 0 ? Reverse : (speed > 0 ? Forward : Neutral));
#endif
    case Neutral:
        return brake ? Braking : (speed < 0 ? Reverse : (speed > 0 ? Forward : Neutral));
    case Reverse:
        return brake ? Braking : (speed > 0 ? Forward : (speed == 0 ? Neutral : Reverse));
    }
    return Neutral;
}

/* The ESC channel's falling edge at the end of each PWM period: the state machine moves on and sets the
 * pulse of its state (Forward, Reverse: the speed; Braking: full reverse with a brake-capable ESC, the
 * opposite of the speed without; Neutral: the stop pulse). */
static void esc_period_finished(void) {
    Esc *e = &k.esc;
    if (e->State > Reverse) e->State = Neutral, e->Speed = 0, e->Brake = 0U;  /* the sample's safe values */
    e->State = esc_next(e->State, e->Speed, e->Brake != 0U);
    int command = 0;
    if (e->State == Forward || e->State == Reverse) command = e->Speed;
#if ESC_HAS_BRAKE == STD_ON
    else if (e->State == Braking) command = -100;
#else
    else if (e->State == Braking) command = -e->Speed;
#endif
    esc_pulse(command);
}

void EscInit(Pwm_ChannelType EscPwmChannel, uint16 MinDutyCycle, uint16 MedDutyCycle, uint16 MaxDutyCycle) {
    read_params();
    if (!(k.esc_hz > 0.0 && 1.0 / k.esc_hz >= 1e-5)) {
        char text[200];
        snprintf(text, sizeof text, "EscInit: --param s32k_esc_hz=%g: expected a PWM frequency above 0 and at most "
                 "100 kHz (the simulator's 10 us)", k.esc_hz);
        spinner_fail(text);
    }
    k.esc.Channel = EscPwmChannel, k.esc.MinDutyCycle = MinDutyCycle, k.esc.MedDutyCycle = MedDutyCycle;
    k.esc.MaxDutyCycle = MaxDutyCycle, k.esc.State = Neutral, k.esc.Speed = 0, k.esc.Brake = 0U;
    k.role[EscPwmChannel] = ESC;
    k.esc_braking = 0U;
    Pwm_SetDutyCycle(EscPwmChannel, MedDutyCycle);  /* the stop pulse arms the ESC */
    if (k.esc_running) spinner_stop_every(esc_period_finished);
    spinner_every(1.0 / k.esc_hz, esc_period_finished);  /* the channel's falling-edge notification */
    k.esc_running = 1U;
}

void EscSetSpeed(int Speed) { k.esc.Speed = Speed > 100 ? 100 : (Speed < -100 ? -100 : Speed); }

void EscSetBrake(uint8 Brake) { k.esc.Brake = Brake != 0U ? 1U : 0U; }

/* The kit's own timer interrupts that are no program's (gpt.c: a notification needs one of the program's). */
int s32k_sim_esc_timers(void) { return k.esc_running; }

/* ---- linear_camera.h ---- */

void LinearCameraInit(Pwm_ChannelType ClkPwmChannel, Gpt_ChannelType ShutterGptChannel, Adc_GroupType InputAdcGroup,
                      Dio_ChannelType ShutterDioChannel) {
    (void)ClkPwmChannel, (void)ShutterGptChannel, (void)InputAdcGroup, (void)ShutterDioChannel;
    /* (Frames stay exposure + read-out apart, no spinner_camera_free_running: the driver's
     * linear_camera.c - e.g. michalfrohlich/NXP-Cup-EXPO src/linear_camera.c - starts the shutter
     * Gpt channel one-shot after the read-out's last pixel clock, CameraClock ->
     * LinearCamera_ScheduleNextFrame: the next frame's timer starts only once one is read.) */
    double ms = spinner_param("s32k_exposure_ms", 0.0);
    if (ms > 0.0) spinner_set_exposure(ms * 1e-3);
}

void LinearCameraGetFrame(LinearCameraFrame *Frame) {
    int width = spinner_image_width();
    uint8_t row[width > 0 ? width : 1];
    size_t n = spinner_get_image(spinner_line_row(), 1, row, sizeof row);
    for (size_t i = 0; i < 128; i++) {  /* 128 pixels across the row (a wider camera's sampled) */
        size_t j = n > 0 ? i * n / 128 : 0;
        Frame->Values[i] = (uint8)(j < n ? row[j] * 25U / 64U : 0U);  /* 8-bit ADC x 25 / 64, as the driver */
    }
}

/* ---- display.h: the debug video's text column ---- */

void DisplayInit() { DisplayClear(); }
void RotateFontmap(void) {}
void DisplayVector(Vector VectorCoordinates) { (void)VectorCoordinates; }

void DisplayClear(void) {
    memset(k.screen, ' ', sizeof k.screen);
    k.graph_len = 0;
}

/* TextLength characters from TextOffset, as the sample's src/display.c draws them: those past the
 * string's end blank (its NUL is the font's blank glyph; the driver reads on past it, into memory
 * that is not the string's: the kit shows blanks), not what the screen held. */
void DisplayText(uint16 DisplayLine, const char *Text, uint16 TextLength, uint16 TextOffset) {
    if (DisplayLine >= CharacterRows) return;
    int ended = 0;
    for (uint16 i = 0; i < TextLength && TextOffset + i < CharacterColumns; i++) {
        ended = ended || Text[i] == '\0';
        k.screen[DisplayLine][TextOffset + i] = ended ? ' ' : Text[i];
    }
}

/* The number left-aligned at TextOffset, the rest of TextLength blank; a longer number's first
 * TextLength characters (the sample's src/display.c: its digits, then ' ' while i < TextLength). */
void DisplayValue(uint16 DisplayLine, int Value, uint16 TextLength, uint16 TextOffset) {
    char text[24];
    snprintf(text, sizeof text, "%d", Value);
    DisplayText(DisplayLine, text, TextLength, TextOffset);
}

void DisplayGraph(uint8 DisplayLine, uint8 Values[128], uint16 ValuesCount, uint8 LinesSpan) {
    (void)DisplayLine, (void)LinesSpan;
    k.graph_len = ValuesCount > 128 ? 128 : ValuesCount;
    for (uint16 i = 0; i < k.graph_len; i++) k.graph[i] = (uint8)(Values[i] > 100 ? 255 : Values[i] * 255 / 100);
}

void DisplayRefresh(void) {
    if (!spinner_recording()) return;
    char lines[CharacterRows][CharacterColumns + 1];
    const char *text[CharacterRows];
    for (unsigned r = 0; r < CharacterRows; r++) {
        memcpy(lines[r], k.screen[r], CharacterColumns);
        lines[r][CharacterColumns] = '\0';
        text[r] = lines[r];
    }
    spinner_add_text(text, CharacterRows);
    if (k.graph_len > 0) spinner_add_line(k.graph, 1, k.graph_len);
}

/* ---- main_functions.h ---- */

void DriversInit(void) { read_params(); }
void DisplayTest(void) { not_emulated("DisplayTest", BENCH_TEST); }
void ReceiverTest(void) { not_emulated("ReceiverTest", BENCH_TEST); }
void ServoTest(void) { not_emulated("ServoTest", BENCH_TEST); }
void LinearCameraTest(void) { not_emulated("LinearCameraTest", BENCH_TEST); }
void Pixy2Test(void) { not_emulated("Pixy2Test", BENCH_TEST); }
void HbridgeTest(void) { not_emulated("HbridgeTest", BENCH_TEST); }
void EscTest(void) { not_emulated("EscTest", BENCH_TEST); }

/* ---- pixy2.h: the kit's I2C Pixy2 driver on the simulator's Pixy2 ---- */

I2c_DataType PixyReceivedLinesBuffer[100U];  /* the driver's global I2C reply buffer */

/* The Pixy2's reply to the driver's request "all features, vectors only" (174 193 48 2 1 1),
 * as the I2C read of `receive_bytes` leaves it in PixyReceivedLinesBuffer (Pixy2 serial
 * protocol: sync 0xc1af, type 49 = LINE_RESPONSE_GET_FEATURES, payload length, 16-bit sum of
 * the payload; the payload a feature block: type LINE_VECTOR, length, 6 bytes a vector
 * x0 y0 x1 y1 index flags), then the vectors copied into `out` as the driver parses them. */
static void pixy2_vectors(DetectedVectors *out, unsigned receive_bytes) {
    pixy2_line_features f;
    int8_t got = pixy2_line_get_all_features(LINE_VECTOR, true, &f);  /* this frame, else the next */
    unsigned n = got > 0 ? f.numVectors : 0U, fit = (receive_bytes - 8U) / 6U;
    if (n > fit) n = fit;
    uint8 *b = PixyReceivedLinesBuffer;
    memset(b, 0, sizeof PixyReceivedLinesBuffer);
    unsigned len = n > 0U ? 2U + 6U * n : 0U, sum = 0U;
    b[0] = 175U, b[1] = 193U, b[2] = 49U, b[3] = (uint8)len;
    if (n > 0U) b[6] = LINE_VECTOR, b[7] = (uint8)(6U * n);
    out->NumberOfVectors = (uint8)n;
    for (unsigned i = 0; i < n; i++) {
        const pixy2_vector *v = &f.vectors[i];
        uint8 *d = &b[8U + 6U * i];
        d[0] = v->m_x0, d[1] = v->m_y0, d[2] = v->m_x1, d[3] = v->m_y1, d[4] = v->m_index, d[5] = v->m_flags;
        out->Vectors[i] = (Vector){v->m_x0, v->m_y0, v->m_x1, v->m_y1, v->m_index};
    }
    for (unsigned i = 6U; i < 6U + len; i++) sum += b[i];
    b[4] = (uint8)(sum & 0xFFU), b[5] = (uint8)(sum >> 8);
}

void Pixy2Init(I2c_AddressType PixyI2cAddress, uint8 PixyI2cChannel) {
    (void)PixyI2cAddress, (void)PixyI2cChannel;
    pixy2_init();  /* a car without a Pixy2 ends the run here, saying so */
}

void Pixy2SetLed(uint8 Red, uint8 Green, uint8 Blue) { (void)Red, (void)Green, (void)Blue; }
void PixySetLed(uint8 Red, uint8 Green, uint8 Blue) { (void)Red, (void)Green, (void)Blue; }

void Pixy2GetVectors(DetectedVectors *Vectors) { pixy2_vectors(Vectors, 100U); }

DetectedVectors PixyGetVectors(void) {  /* the earlier driver: a 50-byte read, its result by value */
    static DetectedVectors v;
    pixy2_vectors(&v, 50U);
    return v;
}

/* ---- receiver.h: not emulated ---- */

void ReceiverInit(Icu_ChannelType ReceiverIcuChannel, Gpt_ChannelType ReceiverGptChannel, uint16 ChannelMinTicks,
                  uint16 ChannelMedTicks, uint16 ChannelMaxTicks, uint16 OutsideChannelTicks) {
    (void)ReceiverIcuChannel, (void)ReceiverGptChannel, (void)ChannelMinTicks, (void)ChannelMedTicks;
    (void)ChannelMaxTicks, (void)OutsideChannelTicks;
    not_emulated("ReceiverInit", NO_RECEIVER);
}
int GetReceiverChannel(uint8 Channel) { (void)Channel; not_emulated("GetReceiverChannel", NO_RECEIVER); return 0; }
void ReceiverStateUpdate(Gpt_ValueType ReceiverPeriod) { (void)ReceiverPeriod; not_emulated("ReceiverStateUpdate", NO_RECEIVER); }
enum ReceiverStates GetReceiverState(void) { not_emulated("GetReceiverState", NO_RECEIVER); return BetweenChannels; }
