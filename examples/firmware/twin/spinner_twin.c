/* The TFC firmware (examples/firmware/main.c) through the Spinner API: the same logic (lane.h)
 * and the same timing, written out as the simulator's TFC library (--kit tfc) has it - a main
 * loop pass is one physics step (TFC_Task), the camera is read once its exposure has passed,
 * the start waits for button 0 (pressed at --param button0_at, 0.1 s). Its run log equals the
 * firmware's, row for row (tests/test_kit_tfc.py): the kit adds nothing but the library's API.
 *
 *   simrunner drive examples/firmware/twin/spinner_twin.c */
#include <math.h>

#include "spinner.h"
#include "../lane.h"

#define DEFAULT_EXPOSURE_US 50000  /* the TFC library's exposure until the firmware sets its own (TFC_Config.h) */
#define IMAGE_SIZE_PX 128

static double exposure_s = DEFAULT_EXPOSURE_US * 1e-6, last_image_s;
static uint16_t image[IMAGE_SIZE_PX];   /* 12-bit counts, as LineScanImage0 */

/* One pass of the library: a physics step; the camera's image once its exposure has passed. */
static int camera_pass(void) {
    double now = spinner_get_time();
    if (now - last_image_s < exposure_s - 0.0025) return 0;
    uint8_t row[IMAGE_SIZE_PX];
    size_t n = spinner_get_image(spinner_line_row(), 1, row, sizeof row);
    last_image_s = now;
    for (size_t i = 0; i < IMAGE_SIZE_PX; i++) image[i] = (uint16_t)((i < n ? row[i] : 0) << 4);
    return 1;
}

int main(void) {
    double servo_rad = spinner_param("tfc_servo_rad", 0.40);            /* the servo's travel */
    double servo_offset_rad = spinner_param("tfc_servo_offset_rad", 0.0);  /* and its trim */
    spinner_set_exposure(exposure_s);
    last_image_s = floor(spinner_get_time() * 1000.0) * 1e-3;
    spinner_set_servo(servo_offset_rad);
    spinner_set_motors(0.0f, 0.0f);
    double start_s = spinner_param("button0_at", 0.1);
    while (spinner_get_time() < start_s) camera_pass();   /* the start button */
    exposure_s = EXPOSURE_US * 1e-6;
    spinner_set_exposure(exposure_s);
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
