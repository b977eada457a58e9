/* spinner.h - the thesis's Spinner API (Appendix A.2) in C, for `simrunner drive ctrl.c`.
 *
 * Compile a controller by hand with `cc $(simrunner cflags) ...`; `simrunner drive` does it
 * for you. The program's own `int main(...)` is the entry point; it runs in the simulator's
 * process (a child process with --isolate or as a prebuilt .so: docs/c_controllers.md) and
 * every call below talks to the simulated car in lockstep: simulated
 * time passes only inside the calls that wait (get_image, get_speed, get_position,
 * get_time, sleep - and usleep/sleep/nanosleep, which wait in simulated time too).
 *
 * Units without norm functions (the defaults): speed in m/s, steering angle in radians
 * (bicycle-equivalent, positive = left), time in s, position in m. Give the car's own
 * units with spinner_configure (e.g. servo -512..512, direction swapped, duty in %).
 *
 * Image: row 0 = farthest from the car, column 0 = the car's left; gray levels 0..255.
 * When the run is over (laps done, time limit, off track) the next waiting call ends the
 * program (exit status 0: stdio is flushed).
 */
#ifndef NXPCUP_SPINNER_H
#define NXPCUP_SPINNER_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A norm function: (speed, angle) in the controller's units -> simulator units (thesis
 * A.2: speed first, angle second; a function may use only one). diff_norm takes the
 * already normalised (speed_mps, steer_rad) and returns the yaw rate in rad/s. */
typedef double (*spinner_norm_fn)(double speed, double angle);

/* Replace the given norm functions (NULL keeps the current one; the defaults are identity
 * and diff = v * sin(delta) / wheelbase, thesis eq. 5.2/5.3).
 *   speed_norm(speed, angle)      -> m/s           (commands)
 *   speed_denorm(speed_mps, angle)-> speed         (spinner_get_speed)
 *   turn_norm(speed, angle)       -> rad, + = left (commands)
 *   diff_norm(speed_mps, steer_rad) -> rad/s       (rear differential) */
void spinner_configure(spinner_norm_fn speed_norm, spinner_norm_fn speed_denorm,
                       spinner_norm_fn turn_norm, spinner_norm_fn diff_norm);

/* Commands: stored, they act from the next physics step (no time passes). */
void spinner_set_servo(double angle);              /* speed = last spinner_set_speed value */
void spinner_set_servo_at(double angle, double speed);
void spinner_set_speed(double speed);              /* angle = last spinner_set_servo value */
void spinner_set_speed_at(double speed, double angle);
void spinner_set_speed_and_servo(double speed, double angle);
/* The left and right rear motors' duty -1..1 (the car file's drive.command = "duty"; a
 * speed-commanded car takes their mean as a share of its top speed). Steering commands keep
 * them, a speed command ends them. */
void spinner_set_motors(float left, float right);

/* Camera: wait for the next frame. line = -1: the whole image (height x width bytes, row
 * after row); line = 0..height-1: that row only (width bytes). add_noise != 0 adds the
 * camera noise (seeded by the run). `buf` must hold `size` >= the bytes returned; returns
 * the number of bytes written. */
size_t spinner_get_image(int line, int add_noise, uint8_t *buf, size_t size);

/* The camera's latest frame - the last frame boundary passed - without waiting (no simulated time
 * passes; allowed in an interrupt handler): returns its index (frames count from 0, the start)
 * and, when it is newer than `after_frame`, writes its image (row `line`, or all for -1) into
 * `buf` and its size into `*written` (else 0). For a camera read-out that runs beside the
 * program, as a kit's camera interrupt does: spinner_get_image waits for the next frame. */
long long spinner_latest_image(int line, int add_noise, long long after_frame, uint8_t *buf, size_t size,
                               size_t *written);
int spinner_image_width(void);     /* pixels (128 on the default car) */
int spinner_image_height(void);    /* rows */
int spinner_line_row(void);        /* the row that plays the real line camera (60) */

/* Camera exposure (integration) time in seconds; no time passes. A linescan camera's frames
 * are then exposure + read-out apart (from the frame in progress on), an area camera keeps
 * its frame rate, the ideal camera ignores it (docs/camera.md). Out of range: an error. */
void spinner_set_exposure(double seconds);
/* The exposure from the next frame on, as a timer's period register written while the timer runs
 * loads at its next expiry (a kit's: the KL25's PIT LDVAL, TPM MOD): the frame in progress keeps
 * its period and its exposure, the one after it is integrated over `seconds` (a linescan camera's:
 * and lasts that long). Several calls before that frame's end: the last wins; spinner_set_exposure
 * drops a value still waiting. No time passes; allowed in an interrupt handler (docs/camera.md). */
void spinner_set_exposure_next_frame(double seconds);
double spinner_get_exposure(void);  /* the exposure in force */
/* The camera's SI pulses come from a free-running timer (a kit's board driver that reads each
 * image out while the next integrates, as the FRDM-TFC library's PIT): a linescan camera's
 * frames are then one exposure apart, not exposure + read-out (from the frame in progress on);
 * each is still integrated over the exposure ending read-out before it. A kit calls it at its
 * init; no time passes (docs/camera.md). */
void spinner_camera_free_running(void);

/* Sensors: each lets one physics step pass (so polling loops make progress). */
double spinner_get_speed(void);    /* through speed_denorm, with the last angle */
void spinner_get_position(double *x_m, double *y_m, double *z_m);  /* world, rear axle */
double spinner_get_time(void);     /* simulated s */
/* The simulated time now (s), no physics step: a read of a clock (a library showing a running
 * timer's count, a busy wait on it). Without --mcu-time no time passes in it: the time of the
 * program's last call, asked once after each call that lets time pass; in a handler its time. With
 * --mcu-time a read in main() is charged as any call is (the code's time since its previous charged
 * call passes first: a loop polling the time ends), each read a round trip. */
double spinner_now(void);
/* The time of the program's last charged call (s), or in a handler its time, without a charge even
 * with --mcu-time: for a kit's bookkeeping of its emulated registers (its look before a wait, the
 * time a timer it starts counts from), which has no time of its own in the program's. Without
 * --mcu-time the same as spinner_now. */
double spinner_now_uncharged(void);
/* Range sensor NAME of the car file ([range_sensors.NAME]): metres to the nearest object on the
 * track, INFINITY when none is in range (docs/events.md). An unknown name is an error. */
double spinner_get_distance(const char *name);
/* Lidar NAME (kind = "lidar"): its scan, one reading per ray (m, INFINITY where nothing is in
 * range), and the rays' directions (rad, car frame, + = left of ahead; no time passes). Both
 * copy at most max_rays values and return the lidar's number of rays (at most 4096). */
int spinner_get_scan(const char *name, double *ranges_m, int max_rays);
int spinner_get_scan_angles(const char *name, double *angles_rad, int max_rays);
/* Wheel encoder counts since the start (the car file's [encoders]; signed for quadrature
 * decoding), and the IMU's gyroscope (rad/s) and accelerometer (m/s^2, at rest +9.81 up) along
 * the car's x (ahead), y (left), z (up) axes ([imu]). A wheel without an encoder, or a car
 * without an IMU, is an error. Any pointer may be NULL. */
enum { SPINNER_WHEEL_FL = 0, SPINNER_WHEEL_FR = 1, SPINNER_WHEEL_RL = 2, SPINNER_WHEEL_RR = 3 };
long long spinner_get_encoder(int wheel);
void spinner_get_gyro(double *x_radps, double *y_radps, double *z_radps);
void spinner_get_accel(double *x_mps2, double *y_mps2, double *z_mps2);
/* What the car file fits, for libraries that convert (no time passes): the lines per revolution
 * of the encoder on `wheel` and, in *counts_per_line (may be NULL), how spinner_get_encoder counts
 * them: 4, 2, 1 (quadrature x4, x2, x1) or 0 (one channel, "single"); 0 and 0 for a wheel
 * without one. spinner_has_imu(): 1 when the car has an [imu]. */
int spinner_encoder_lines(int wheel, int *counts_per_line);
int spinner_has_imu(void);

/* Let `seconds` of simulated time pass (ceil(seconds / dt) steps, at least one). */
void spinner_sleep(double seconds);

/* A timer interrupt: call handler() every period_s of simulated time from now (at least 1e-5 s).
 * It interrupts main() inside its next waiting call (the code between calls takes no time
 * unless --mcu-time); inside the handler no time passes: reads give the state then, commands
 * act from the next physics step, a wait (camera frame, sleep) is an error. Up to 32 handlers,
 * due together in the order set up. Firmware with its own ISR: simrunner drive --isr NAME@HZ. */
void spinner_every(double period_s, void (*handler)(void));
/* Stop every timer interrupt that calls handler (set up by spinner_every or --isr): from now on
 * it is not called (one due at this step neither). */
void spinner_stop_every(void (*handler)(void));
/* For kits that emulate a timer's interrupt enable behind the NVIC (the TFC kit's PIT, LPTMR0, TPM2):
 * stop handler as spinner_stop_every does, except that a call which fell due and has not run (held
 * by the mask, or due at this step after the running handler) keeps its NVIC pending bit and runs
 * once, when it would have - the pending bit outlives its source (ARMv6-M, ARM DDI 0419, B3.4 the
 * NVIC: a pending interrupt stays pending until taken or cleared). spinner_unpend_every clears it
 * (NVIC_ClearPendingIRQ). spinner_pend_every sets handler's pending bit (NVIC_SetPendingIRQ, or a
 * timer that expired while its IRQ was disabled in the NVIC, enabled again): it runs once, as a timer
 * interrupt's handler, when interrupts are unmasked and no handler runs - inside this call if they
 * are (from spinner_kit_before_wait: in the waiting call it precedes), else at
 * spinner_enable_interrupts or after the running handler; pending already, nothing changes (one
 * bit); spinner_unpend_every clears it. spinner_every_pending: non-zero when a call of handler fell
 * due and has not run - held by the mask, kept by a latched stop, or due at this step after the
 * running handler (its NVIC pending bit: NVIC_GetPendingIRQ); no time passes, and no round trip to
 * the simulator unless interrupts are masked or a handler runs. */
void spinner_stop_every_latched(void (*handler)(void));
void spinner_unpend_every(void (*handler)(void));
void spinner_pend_every(void (*handler)(void));
int spinner_every_pending(void (*handler)(void));
/* Non-zero when handler is set up as a timer interrupt (by spinner_every or --isr). */
int spinner_has_every(void (*handler)(void));
/* How many timer interrupt handlers are set up (--isr and spinner_every). */
int spinner_interrupts(void);
/* Non-zero inside an interrupt handler (where no simulated time passes): for library code that
 * lets time pass when main() polls it, and must not in a handler. */
int spinner_in_interrupt(void);
/* 0 while nothing can be asked: in a global object's constructor as the simulator's process loads
 * the program, before its run (the simulator then runs the program in a child process, where its
 * constructors run again with the run there); else 1. For kits whose objects' constructors call
 * them: ask nothing, and end nothing, then. */
int spinner_running(void);
/* Mask the timer interrupts, as __disable_irq() sets the Cortex-M's PRIMASK (the kits' __disable_irq,
 * DisableInterrupts, OsIf_SuspendAllInterrupts call it): a handler that falls due meanwhile is held
 * pending and runs once, however often it fell due, at spinner_enable_interrupts - at that time, no
 * time passing, in the order set up; one stopped meanwhile does not run. A flag, not a count: a
 * second disable changes nothing, one enable clears it. In a handler too: it stays masked after the
 * handler returns; an enable there lets the pending ones run after it. Interrupts left disabled for
 * 0.1 s with a handler held give the run a warning. No time passes in either call. */
void spinner_disable_interrupts(void);
void spinner_enable_interrupts(void);
/* Non-zero while spinner_disable_interrupts masks the timer interrupts (no time passes). */
int spinner_interrupts_disabled(void);

/* Debug video: text lines in the right column (one call = the lines of this frame). */
void spinner_add_text(const char *const *lines, int n);
void spinner_add_textf(const char *format, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;  /* one line, printf-style */
/* Debug video: a processed image line (rows x width bytes, rows >= 1), shown stretched. */
void spinner_add_line(const uint8_t *pixels, int rows, int width);
/* 1 when text added to the video/CSV is kept (a video or CSV is written): skip formatting
 * otherwise. */
int spinner_recording(void);

/* Add camera noise to an image in place (rows x width bytes). */
void spinner_add_noise(uint8_t *pixels, int rows, int width);

/* A run parameter (`simrunner drive ... --param NAME=VALUE`), or default_value. */
double spinner_param(const char *name, double default_value);

/* End the run as controller_error with `message` and the C backtrace (the calling file:line),
 * as a misused Spinner call does; for library code that meets a call it cannot serve. */
void spinner_fail(const char *message) __attribute__((noreturn));

/* A warning of the run (listed after it and in the summary's warnings, once per text, at the
 * innermost place in the program's own code the call came through: "main.c:12: TEXT"); the run
 * goes on. For library code that sees a set-up that will not do what its author meant. */
void spinner_warn(const char *message);
/* The same, said at `call`: a return address into the program's code that the library kept
 * (__builtin_return_address(0) in the function the program called; NULL: no place). */
void spinner_warn_at(const char *message, const void *call);

#ifdef __cplusplus
}
#endif
#endif /* NXPCUP_SPINNER_H */
