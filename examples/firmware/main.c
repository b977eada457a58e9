/* A line-following firmware for the FRDM-KL25Z + FRDM-TFC kit, written against the TFC library
 * as NXP Cup teams write theirs (the TFC demo's main loop: TFC_Task() every pass, the tickers
 * and LineScanImageReady as the timing). It builds unchanged for the car and for the simulator:
 *
 *   simrunner drive examples/firmware/main.c --kit tfc [--param dip=1] [--track ...]
 *
 * The logic (lane.h) is examples/line_follower.py's (its lane tracker and PD steering), in C: the camera
 * image is 12-bit (LineScanImage0, >> 4 gives the grey); the lane is the white run between the
 * two dark lines; one line in view: the lane's middle half a lane width from it; all white (a
 * crossing): straight on; nothing white (lost): the last estimate. Start: button 0 (the
 * simulator presses it at 0.1 s). DIP switch 1 on: a faster top speed. */
#include "derivative.h"
#include "TFC\TFC.h"

#include "lane.h"

int main(void) {
    TFC_Init();
    while (!TFC_PUSH_BUTTON_0_PRESSED) TFC_Task();      /* wait for the start button */
    TFC_SetLineScanExposureTime(EXPOSURE_US);
    TFC_SetBatteryLED_Level(1);
    TFC_HBRIDGE_ENABLE;
    float v_max = (TFC_GetDIP_Switch() & 0x01) ? 3.0f : V_MAX_MPS;
    for (;;) {
        TFC_Task();                                       /* keep the library running */
        if (LineScanImageReady != 1) continue;
        LineScanImageReady = 0;
        float steer, speed;
        lane_control(LineScanImage0, v_max, &steer, &speed);
        TFC_SetServo(0, steer / STEER_LIMIT_RAD);
        TFC_SetMotorPWM(speed / MAX_SPEED_MPS, speed / MAX_SPEED_MPS);
    }
}
