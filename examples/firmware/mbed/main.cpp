/* A line-following program for the FRDM-KL25Z + FRDM-TFC kit written against mbed and its
 * FRDM-TFC library, as NXP Cup teams on mbed write theirs: a Serial terminal, the tickers the
 * CodeWarrior demo had (TFC_Ticker[], counted here by an mbed Ticker every millisecond), a main
 * loop that steers from each new camera image. It builds unchanged for the board
 * (mbed's online compiler or mbed-cli, with the FRDM-TFC library) and for the simulator:
 *
 *   simrunner drive examples/firmware/mbed/main.cpp --kit tfc-mbed [--param dip=1] [--track ...]
 *
 * The logic (../lane.h) is examples/line_follower.py's: the lane between the two dark lines,
 * PD steering, slower in turns. Start: button 0 (the simulator presses it at 0.1 s). DIP switch
 * 1 on: a faster top speed; DIP switch 4 on: the lane estimate printed on the terminal. */
#include "mbed.h"
#include "TFC.h"

#include "../lane.h"

#define NUM_TFC_TICKERS 4

Serial pc(USBTX, USBRX);
Ticker TFC_TickerObj;
volatile uint32_t TFC_Ticker[NUM_TFC_TICKERS];

void TFC_TickerUpdate() {
    for (int i = 0; i < NUM_TFC_TICKERS; i++) {
        if (TFC_Ticker[i] < 0xFFFFFFFF) TFC_Ticker[i]++;
    }
}

int main() {
    pc.baud(115200);
    TFC_TickerObj.attach_us(&TFC_TickerUpdate, 1000);   // 1 ms ticks
    TFC_Init();
    // The library reads the camera once a servo frame: a 19.5-ms frame is the exposure lane.h's
    // white threshold is set for (the default frame, 10 ms, gives half the light).
    TFC_InitServos(SERVO_MIN_PULSE_WIDTH_DEFAULT, SERVO_MAX_PULSE_WIDTH_DEFAULT, EXPOSURE_US * 1e-6f);
    while (!TFC_PUSH_BUTTON_0_PRESSED) {                 // wait for the start button
    }
    TFC_HBRIDGE_ENABLE;
    int level = 0;
    float v_max = TFC_DIP_SWITCH_0_ON ? 3.0f : V_MAX_MPS;
    bool verbose = TFC_DIP_SWITCH_3_ON;
    for (;;) {
        if (TFC_LineScanImageReady == 0) continue;        // no new image yet
        TFC_LineScanImageReady = 0;
        if (TFC_Ticker[1] >= 125) {                       // a pattern on the LEDs, 8 steps a second
            TFC_Ticker[1] = 0;
            level = (level + 1) % 5;
            TFC_SetBatteryLED_Level(level);
        }
        float steer, speed;
        lane_control(TFC_LineScanImage0, v_max, &steer, &speed);
        TFC_SetServo(0, steer / STEER_LIMIT_RAD);
        TFC_SetMotorPWM(speed / MAX_SPEED_MPS, speed / MAX_SPEED_MPS);
        if (verbose) pc.printf("lane centre %5.1f px, steer %+.3f rad, %.2f m/s\r\n", centre, steer, speed);
    }
}
