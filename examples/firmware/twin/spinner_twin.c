/* The TFC firmware (examples/firmware/main.c) through the Spinner API: the same logic (lane.h)
 * and the same timing, written out as the simulator's TFC library (--kit tfc) has it - a main
 * loop pass is one physics step (TFC_Task), the camera's latest frame is read once a new one is there,
 * the start waits for button 0 (pressed at --param button0_at, 0.1 s). Its run log equals the
 * firmware's, row for row (tests/test_kit_tfc.py): the kit adds nothing but the library's API.
 *
 *   simrunner drive examples/firmware/twin/spinner_twin.c */
#include <limits.h>

#include "spinner.h"
#include "../lane.h"

#define DEFAULT_EXPOSURE_US 50000  /* the TFC library's exposure until the firmware sets its own (TFC_Config.h) */
#define IMAGE_SIZE_PX 128

static double exposure_s = DEFAULT_EXPOSURE_US * 1e-6;
static long long frame;                 /* the camera frame read out last */
static uint16_t image[IMAGE_SIZE_PX];   /* 12-bit counts, as LineScanImage0 */

/* One pass of the library: a physics step; the camera's latest frame once a new one is there. */
static int camera_pass(void) {
    spinner_get_time();
    uint8_t row[IMAGE_SIZE_PX];
    size_t n = 0;
    long long latest = spinner_latest_image(spinner_line_row(), 1, frame, row, sizeof row, &n);
    if (n == 0) return 0;
    frame = latest;
    for (size_t i = 0; i < IMAGE_SIZE_PX; i++) image[i] = (uint16_t)((i < n ? row[i] : 0) << 4);
    return 1;
}

int main(void) {
    double servo_rad = spinner_param("tfc_servo_rad", 0.40);            /* the servo's travel */
    double servo_offset_rad = spinner_param("tfc_servo_offset_rad", 0.0);  /* and its trim */
    spinner_camera_free_running();      /* (the library's PIT: one image an exposure) */
    spinner_set_exposure(exposure_s);
    spinner_get_time();                 /* (TFC_Init reads the time: its tickers start there) */
    uint8_t row[IMAGE_SIZE_PX];         /* the first image: the frame after TFC_Init's */
    frame = spinner_latest_image(spinner_line_row(), 0, LLONG_MAX, row, sizeof row, NULL);
    spinner_set_servo(servo_offset_rad);
    spinner_set_motors(0.0f, 0.0f);
    double start_s = spinner_param("button0_at", 0.1);
    while (spinner_get_time() < start_s) camera_pass();   /* the start button */
    exposure_s = EXPOSURE_US * 1e-6;
    spinner_set_exposure_next_frame(exposure_s);  /* (the library's LDVAL0: loads as the frame in progress ends) */
    float v_max = ((int)spinner_param("dip", 0.0) & 0x01) ? 3.0f : V_MAX_MPS;
    for (;;) {
        if (!camera_pass()) continue;
        float steer, speed;
        lane_control(image, v_max, &steer, &speed);
        float position = steer / STEER_LIMIT_RAD, duty = speed / MAX_SPEED_MPS;
        spinner_set_servo(position * servo_rad + servo_offset_rad);
        spinner_set_motors(duty, duty);
    }
}
