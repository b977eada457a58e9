/* The line follower written in the real car's units (thesis 3.3 and Appendix A.2), in C.
 *
 * Run it:  simrunner drive examples/real_car_units.c
 *
 * The faculty team's car takes servo values -512..512 with the direction swapped (positive
 * = right) and a motor duty in percent; the simulator speaks radians (+ = left) and m/s.
 * The norm functions translate (C function pointers given to spinner_configure), so the
 * control code stays what runs on the car. Same algorithm and numbers as
 * examples/real_car_units.py; the lane tracking is lane_tracker.h (shared with
 * line_follower.c, found beside this file).
 */
#include <math.h>
#include <stdio.h>
#include "spinner.h"
#include "lane_tracker.h"

#define STEER_LIMIT_RAD 0.40
#define MAX_SPEED_MPS 3.1
#define KP 1024.0                     /* servo units per half image (= 0.8 and 0.9 rad) */
#define KD 1152.0
#define DUTY_MAX 90.0                 /* percent (= 2.8 and 1.5 m/s) */
#define DUTY_MIN 48.0

static double turn_norm(double speed, double angle) { (void)speed; return -angle / 512 * STEER_LIMIT_RAD; }
static double speed_norm(double speed, double angle) { (void)angle; return speed / 100 * MAX_SPEED_MPS; }
static double speed_denorm(double v, double angle) { (void)angle; return v / MAX_SPEED_MPS * 100; }

int main(void) {
    spinner_configure(speed_norm, speed_denorm, turn_norm, NULL);
    int w = spinner_image_width();
    uint8_t row[1024];
    struct lane lane = lane_start(w);
    double prev_err = 0.0;
    for (;;) {
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        double err = lane_error(&lane, row, w);  /* + = lane to the right */
        if (lane.at_crossing) prev_err = err;
        double servo = fmax(-512, fmin(512, KP * err + KD * (err - prev_err)));  /* + = right here */
        prev_err = err;
        double duty = DUTY_MAX - (DUTY_MAX - DUTY_MIN) * fmin(1.0, fabs(servo) / (0.6 * 512));
        spinner_set_speed_and_servo(duty, servo);
        char l1[48], l2[64];
        snprintf(l1, sizeof l1, "servo %+.0f", servo);
        snprintf(l2, sizeof l2, "duty %.0f %%  speed %.0f %%", duty, spinner_get_speed());
        const char *lines[] = {l1, l2};
        spinner_add_text(lines, 2);
    }
}
