/* The line follower of examples/line_follower.py, in C: one camera line, both black edges.
 *
 * Run it:  simrunner drive examples/line_follower.c [--track ...] [--video run.mp4]
 *
 * Each frame it reads one image row (the line camera, spinner_line_row()), finds the white
 * lane between the dark edge lines, steers towards the lane's middle (PD on the pixel
 * error) and slows down while steering hard. Where only one edge is in view it places the
 * middle half a lane width (learned while both edges are seen) from that edge; where the
 * whole row is white (a crossroads) it goes straight on; where nothing white is seen (line
 * lost) it keeps its last estimate (lane_tracker.h). The arithmetic is the Python
 * example's, step for step: the run log is the same, number for number.
 *
 * Light (as the Python example): auto exposure keeps the line bright but unclipped (0.5 to
 * 30 ms; not in the first SKIP_FRAMES frames); --param threshold=0 cuts each row half-way between its darkest and
 * brightest pixel instead of at the fixed 128.
 *
 * Units: the Spinner defaults (m/s, radians, + = left). The gains are per half image width.
 */
#include <math.h>
#include <stdio.h>
#include <stdint.h>
#include "spinner.h"
#include "lane_tracker.h"

#define V_MAX_MPS 2.8        /* on straights */
#define V_MIN_MPS 1.5        /* at full steering */
#define KP 0.8               /* rad of steering per half-image of lateral error */
#define KD 0.9               /* rad per half-image of error change per frame */
#define STEER_LIMIT_RAD 0.40
#define SPEED_FILTER 0.25    /* low-pass factor of the speed command per frame */
#define MAX_WIDTH 1024
#define EXPOSURE_MIN_S 0.0005  /* auto exposure limits */
#define EXPOSURE_MAX_S 0.030
#define PEAK_LOW 100           /* brightest pixel: too dim, clipped */
#define PEAK_HIGH 255
#define SKIP_FRAMES 3          /* frames after power-up not used for the exposure */

/* Auto exposure: shorter when the brightest pixel clips, longer when it is dim. */
static double next_exposure(double exposure_s, int peak) {
    double factor;
    if (peak >= PEAK_HIGH) factor = 0.8;
    else if (peak < PEAK_LOW) factor = 1.25;
    else return exposure_s;
    return fmin(fmax(exposure_s * factor, EXPOSURE_MIN_S), EXPOSURE_MAX_S);
}

int main(void) {
    int w = spinner_image_width();
    uint8_t row[MAX_WIDTH];
    struct lane lane = lane_start(w);
    double prev_err = 0.0, speed = V_MIN_MPS;
    int threshold = (int)spinner_param("threshold", WHITE);
    double exposure = spinner_get_exposure();
    int frames = 0;
    for (;;) {
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        lane.white = threshold == 0 ? row_threshold(row, w) : threshold;
        double err = lane_error(&lane, row, w);
        int peak = 0;
        for (int i = 0; i < w; i++) if (row[i] > peak) peak = row[i];
        frames++;
        double next = frames > SKIP_FRAMES ? next_exposure(exposure, peak) : exposure;
        if (next != exposure) {
            spinner_set_exposure(next);
            exposure = next;
        }
        if (lane.at_crossing) prev_err = err;  /* no derivative kick when the estimate resets */
        double steer = fmin(fmax(-KP * err - KD * (err - prev_err), -STEER_LIMIT_RAD), STEER_LIMIT_RAD);
        prev_err = err;
        double target = V_MAX_MPS - (V_MAX_MPS - V_MIN_MPS) * fmin(1.0, fabs(steer) / (0.6 * STEER_LIMIT_RAD));
        speed += target > speed ? SPEED_FILTER * (target - speed) : (target - speed);
        spinner_set_speed_and_servo(speed, steer);
        if (spinner_recording()) {  /* debug text for the video (formatting costs time) */
            char edges[64], cmd[64], l[16], r[16];
            if (lane.seen)  /* as Python prints the tuple lane.edges */
                snprintf(edges, sizeof edges, "edges (%s, %s)  lane %.0f px", lane_px_text(lane.left, l),
                         lane_px_text(lane.right, r), lane.lane_px);
            else
                snprintf(edges, sizeof edges, "edges None  lane %.0f px", lane.lane_px);
            snprintf(cmd, sizeof cmd, "steer %+.3f rad  speed %.2f m/s", steer, speed);
            const char *lines[] = {edges, cmd};
            spinner_add_text(lines, 2);
        }
    }
}
