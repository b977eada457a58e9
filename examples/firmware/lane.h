/* The control logic of examples/firmware/main.c, the team's own module: the lane tracker and
 * the PD steering of examples/line_follower.py, in C. The TFC firmware (main.c) and its Spinner
 * twin (twin/spinner_twin.c) include it, so both drive by the same lines of code. */
#ifndef LANE_H
#define LANE_H
#include <math.h>
#include <stdint.h>

#define EXPOSURE_US 19500      /* line camera exposure: about 50 images a second */
#define IMAGE_SIZE 128
#define WHITE 128              /* grey (8-bit) above this is the white lane */
#define KP 0.8f                /* rad of steering per half image of error */
#define KD 0.9f
#define STEER_LIMIT_RAD 0.40f  /* the servo's full travel (TFC_SetServo +-1) */
#define MAX_SPEED_MPS 3.1f     /* full duty */
#define V_MIN_MPS 1.5f         /* at full steering */
#define V_MAX_MPS 2.8f         /* on straights (DIP 1: 3.0) */

static float centre = IMAGE_SIZE / 2.0f;   /* the lane's middle (pixels) */
static float lane_px = IMAGE_SIZE;         /* the lane's width, learned where both lines show */

static int is_white(volatile uint16_t *image, int i) { return (image[i] >> 4) > WHITE; }

/* The white run containing the last middle (or the nearest one): its first and last pixel, -1
 * where it reaches the image's border (that line is not in view); 0 when nothing is white. */
static int lane_edges(volatile uint16_t *image, int *left, int *right) {
    int g = (int)centre;
    if (g < 0) g = 0;
    if (g > IMAGE_SIZE - 1) g = IMAGE_SIZE - 1;
    if (!is_white(image, g)) {
        int r = g, l = g;
        while (r < IMAGE_SIZE && !is_white(image, r)) r++;
        while (l >= 0 && !is_white(image, l)) l--;
        if (r >= IMAGE_SIZE && l < 0) return 0;
        g = (l < 0 || (r < IMAGE_SIZE && r - g <= g - l)) ? r : l;
    }
    int a = g, b = g;
    while (a > 0 && is_white(image, a - 1)) a--;
    while (b < IMAGE_SIZE - 1 && is_white(image, b + 1)) b++;
    *left = a > 0 ? a : -1;
    *right = b < IMAGE_SIZE - 1 ? b : -1;
    return 1;
}

static float lane_error(volatile uint16_t *image) {
    int left, right;
    if (lane_edges(image, &left, &right)) {
        if (left >= 0 && right >= 0) {
            lane_px = 0.9f * lane_px + 0.1f * (right - left);
            centre = 0.5f * (left + right);
        } else if (left >= 0) {
            centre = left + 0.5f * lane_px;
        } else if (right >= 0) {
            centre = right - 0.5f * lane_px;
        } else {
            centre = IMAGE_SIZE / 2.0f;                 /* all white: a crossing */
        }
    }
    return (centre - IMAGE_SIZE / 2.0f) / (IMAGE_SIZE / 2.0f);  /* + = lane to the right */
}

/* One camera image's commands: the steering (rad, + = left) and the speed (m/s) to set. */
static float last_error = 0.0f, speed = V_MIN_MPS;

static void lane_control(volatile uint16_t *image, float v_max, float *steer_rad, float *speed_mps) {
    float error = lane_error(image);
    float steer = -KP * error - KD * (error - last_error);
    last_error = error;
    if (steer > STEER_LIMIT_RAD) steer = STEER_LIMIT_RAD;
    if (steer < -STEER_LIMIT_RAD) steer = -STEER_LIMIT_RAD;
    float target = v_max - (v_max - V_MIN_MPS) * fminf(1.0f, fabsf(steer) / (0.6f * STEER_LIMIT_RAD));
    speed += target > speed ? 0.25f * (target - speed) : target - speed;
    *steer_rad = steer;
    *speed_mps = speed;
}
#endif
