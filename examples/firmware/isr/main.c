/* The line-following firmware of ../main.c with its control in a timer interrupt, as teams that
 * run their control loop in the PIT's interrupt handler write it: main() sets the kit up and
 * idles; PIT_IRQHandler() steers from the newest camera image, 100 times a second.
 *
 *   simrunner drive examples/firmware/isr/main.c -I examples/firmware --kit tfc --isr PIT_IRQHandler@100
 *
 * On the car the PIT's set-up (its load value for 100 Hz, its interrupt enabled) sets the rate;
 * in the simulator --isr does (docs/c_controllers.md, Timer interrupts). __WFI() lets the
 * board's interrupts run: the SysTick, the camera's read-out into LineScanImage0, this handler. */
#include "derivative.h"
#include "TFC\TFC.h"

#include "lane.h"

static float v_max = V_MAX_MPS;

void PIT_IRQHandler(void) {
    if (LineScanImageReady != 1) return;                 /* no new image since the last pass */
    LineScanImageReady = 0;
    float steer, speed;
    lane_control(LineScanImage0, v_max, &steer, &speed);
    TFC_SetServo(0, steer / STEER_LIMIT_RAD);
    TFC_SetMotorPWM(speed / MAX_SPEED_MPS, speed / MAX_SPEED_MPS);
}

int main(void) {
    TFC_Init();
    while (!TFC_PUSH_BUTTON_0_PRESSED) TFC_Task();      /* wait for the start button */
    TFC_SetLineScanExposureTime(EXPOSURE_US);
    TFC_HBRIDGE_ENABLE;
    if (TFC_GetDIP_Switch() & 0x01) v_max = 3.0f;
    for (;;) __WFI();                                     /* the work is the interrupt's */
}
