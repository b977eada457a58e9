/* A line-following firmware for the NXP Cup S32K144 kit, written against the kit's drivers
 * (servo.h, hbridge.h, linear_camera.h, display.h) in the style of NXP's
 * Nxp_Cup_Linear_Camera_S32K144 sample: the drivers initialised with the sample's channels,
 * then a loop around the blocking LinearCameraGetFrame. It builds unchanged for the car (in the
 * sample's S32 Design Studio project, beside its src/ drivers) and for the simulator:
 *
 *   simrunner drive examples/firmware/s32k144/main.c --kit s32k144 [--track ...]
 *
 * The logic is examples/line_follower.py's (its lane tracker and PD steering) in the kit's
 * units: a pixel is 0 .. 99 (the driver's 8-bit ADC count x 25 / 64); the lane is the white run
 * between the two dark lines; one line in view: the lane's middle half a lane width from it;
 * all white (a crossing): straight on; nothing white (lost): the last estimate. Steer() takes
 * -100 (full left) .. 100 (full right), HbridgeSetSpeed() 0 .. 100 % duty. */
#include "display.h"      /* the sample's includes, as its main.c has them */
#include "receiver.h"
#include "CDD_I2c.h"
#include "esc.h"
#include "servo.h"
#include "linear_camera.h"
#include "main_functions.h"
#include "hbridge.h"
#include "Mcal.h"
#include "pixy2.h"
#include <math.h>

#define BUFFER_SIZE 128
#define WHITE 50               /* 0..99: the grey 128 of line_follower.py, x 25 / 64 */
#define KP 0.8f                /* rad of steering per half image of error */
#define KD 0.9f
#define STEER_LIMIT_RAD 0.40f  /* the servo's calibrated full travel (Steer +-100) */
#define MAX_SPEED_MPS 3.1f     /* full duty (HbridgeSetSpeed(100)) */
#define V_MIN_MPS 1.5f         /* at full steering */
#define V_MAX_MPS 2.8f         /* on straights */

static float Centre = BUFFER_SIZE / 2.0f;   /* the lane's middle (pixels) */
static float LanePx = BUFFER_SIZE;          /* the lane's width, learned where both lines show */

static int IsWhite(const uint8 *Values, int i) { return Values[i] > WHITE; }

/* The white run containing the last middle (or the nearest one): its first and last pixel, -1
 * where it reaches the image's border (that line is not in view); 0 when nothing is white. */
static int LaneEdges(const uint8 *Values, int *Left, int *Right) {
    int g = (int)Centre;
    if (g < 0) g = 0;
    if (g > BUFFER_SIZE - 1) g = BUFFER_SIZE - 1;
    if (!IsWhite(Values, g)) {
        int r = g, l = g;
        while (r < BUFFER_SIZE && !IsWhite(Values, r)) r++;
        while (l >= 0 && !IsWhite(Values, l)) l--;
        if (r >= BUFFER_SIZE && l < 0) return 0;
        g = (l < 0 || (r < BUFFER_SIZE && r - g <= g - l)) ? r : l;
    }
    int a = g, b = g;
    while (a > 0 && IsWhite(Values, a - 1)) a--;
    while (b < BUFFER_SIZE - 1 && IsWhite(Values, b + 1)) b++;
    *Left = a > 0 ? a : -1;
    *Right = b < BUFFER_SIZE - 1 ? b : -1;
    return 1;
}

/* The lane's offset from the image's middle, -1 .. 1 (+ = lane to the right). */
static float LaneError(const uint8 *Values) {
    int Left, Right;
    if (LaneEdges(Values, &Left, &Right)) {
        if (Left >= 0 && Right >= 0) {
            LanePx = 0.9f * LanePx + 0.1f * (Right - Left);
            Centre = 0.5f * (Left + Right);
        } else if (Left >= 0) {
            Centre = Left + 0.5f * LanePx;
        } else if (Right >= 0) {
            Centre = Right - 0.5f * LanePx;
        } else {
            Centre = BUFFER_SIZE / 2.0f;                 /* all white: a crossing */
        }
    }
    return (Centre - BUFFER_SIZE / 2.0f) / (BUFFER_SIZE / 2.0f);
}

int main(void) {
    LinearCameraFrame FrameBuffer;
    DriversInit();
    ServoInit(1U, 3300U, 1700U, 2500U);          /* PWM channel, full right, full left, centre */
    HbridgeInit(2U, 3U, 32U, 33U, 6U, 64U);      /* motor PWM channels, direction pins */
    DisplayInit(0U, STD_ON);
    LinearCameraInit(4U, 1U, 0U, 97U);           /* clock PWM, shutter GPT, ADC group, shutter pin */

    float Speed = V_MIN_MPS, LastError = 0.0f;
    for (;;) {
        LinearCameraGetFrame(&FrameBuffer);
        float Error = LaneError(FrameBuffer.Values);
        float SteerRad = -KP * Error - KD * (Error - LastError);   /* + = left */
        LastError = Error;
        SteerRad = fmaxf(-STEER_LIMIT_RAD, fminf(STEER_LIMIT_RAD, SteerRad));
        float Target = V_MAX_MPS - (V_MAX_MPS - V_MIN_MPS) * fminf(1.0f, fabsf(SteerRad) / (0.6f * STEER_LIMIT_RAD));
        Speed += Target > Speed ? 0.25f * (Target - Speed) : Target - Speed;
        Steer((int)lroundf(-100.0f * SteerRad / STEER_LIMIT_RAD));  /* Steer(+) is right */
        HbridgeSetSpeed((int)lroundf(100.0f * Speed / MAX_SPEED_MPS));

        DisplayClear();
        DisplayText(0U, "lane", 4U, 0U);
        DisplayValue(0U, (int)Centre, 4U, 5U);
        DisplayValue(0U, HbridgeGetSpeed(), 4U, 11U);
        DisplayGraph(1U, FrameBuffer.Values, 128U, 3U);
        DisplayRefresh();
    }
}
