/* The line follower of examples/line_follower.py, in C: one camera line, both black edges.
 *
 * Run it:  simrunner drive examples/line_follower.c [--track ...] [--video run.mp4]
 *
 * Each frame it reads one image row (the line camera, spinner_line_row()), finds the white
 * lane between the dark edge lines, steers towards the lane's middle (PD on the pixel
 * error) and slows down while steering hard. Where only one edge is in view it places the
 * middle half a lane width (learned while both edges are seen) from that edge; where the
 * whole row is white (a crossroads) it goes straight on; where nothing white is seen (line
 * lost) it keeps its last estimate. The arithmetic is the Python example's, step for step.
 *
 * Units: the Spinner defaults (m/s, radians, + = left). The gains are per half image width.
 */
#include <math.h>
#include <stdint.h>
#include "spinner.h"

#define V_MAX_MPS 2.8        /* on straights */
#define V_MIN_MPS 1.5        /* at full steering */
#define KP 0.8               /* rad of steering per half-image of lateral error */
#define KD 0.9               /* rad per half-image of error change per frame */
#define STEER_LIMIT_RAD 0.40
#define WHITE 128            /* gray threshold: lane is white (~235), edges/floor dark */
#define SPEED_FILTER 0.25    /* low-pass factor of the speed command per frame */
#define MAX_WIDTH 1024

/* The white lane run containing `guess` (else the nearest): *left / *right are its first
 * and last columns, -1 where the run reaches the image border (that edge not in view).
 * Returns 0 if no pixel is white (line lost). */
static int lane_edges(const uint8_t *row, int w, double guess, int *left, int *right) {
    int g = (int)guess;
    g = g < 0 ? 0 : g > w - 1 ? w - 1 : g;
    if (row[g] <= WHITE) {
        int r = -1, l = -1;
        for (int i = g; i < w; i++) if (row[i] > WHITE) { r = i; break; }
        for (int i = g - 1; i >= 0; i--) if (row[i] > WHITE) { l = i; break; }
        if (r < 0 && l < 0) return 0;
        g = (l < 0 || (r >= 0 && r - g <= g - l)) ? r : l;
    }
    int a = -1, b = -1;
    for (int i = g - 1; i >= 0; i--) if (row[i] <= WHITE) { a = i; break; }
    for (int i = g; i < w; i++) if (row[i] <= WHITE) { b = i; break; }
    *left = a >= 0 ? a + 1 : -1;
    *right = b >= 0 ? b - 1 : -1;
    return 1;
}

struct lane {           /* the lane middle in one image row, remembered between frames */
    double half, centre, lane_px;
    int left, right, seen, at_crossing;
};

/* Lateral error in half-image units, + = the lane middle is right of the car. */
static double lane_error(struct lane *t, const uint8_t *row, int w) {
    t->seen = lane_edges(row, w, t->centre, &t->left, &t->right);
    if (!t->seen) t->left = t->right = -1;
    t->at_crossing = t->seen && t->left < 0 && t->right < 0;
    if (t->left >= 0 && t->right >= 0) {
        t->lane_px = 0.9 * t->lane_px + 0.1 * (t->right - t->left);
        t->centre = 0.5 * (t->left + t->right);
    } else if (t->left >= 0) {
        t->centre = t->left + 0.5 * t->lane_px;
    } else if (t->right >= 0) {
        t->centre = t->right - 0.5 * t->lane_px;
    } else if (t->at_crossing) {
        t->centre = t->half;
    }
    return (t->centre - t->half) / t->half;
}

int main(void) {
    int w = spinner_image_width();
    uint8_t row[MAX_WIDTH];
    struct lane lane = {w / 2.0, w / 2.0, (double)w, -1, -1, 0, 0};
    double prev_err = 0.0, speed = V_MIN_MPS;
    for (;;) {
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        double err = lane_error(&lane, row, w);
        if (lane.at_crossing) prev_err = err;  /* no derivative kick when the estimate resets */
        double steer = fmin(fmax(-KP * err - KD * (err - prev_err), -STEER_LIMIT_RAD), STEER_LIMIT_RAD);
        prev_err = err;
        double target = V_MAX_MPS - (V_MAX_MPS - V_MIN_MPS) * fmin(1.0, fabs(steer) / (0.6 * STEER_LIMIT_RAD));
        speed += target > speed ? SPEED_FILTER * (target - speed) : (target - speed);
        spinner_set_speed_and_servo(speed, steer);
        if (spinner_recording()) {  /* debug text for the video (formatting costs time) */
            spinner_add_textf("edges (%d, %d)  lane %.0f px", lane.left, lane.right, lane.lane_px);
            spinner_add_textf("steer %+.3f rad  speed %.2f m/s", steer, speed);
        }
    }
}
