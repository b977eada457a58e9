/* The line-following firmware of ../main.c with its control in a timer interrupt, as teams that
 * run their control loop in a timer's interrupt handler write it: main() sets the kit and the
 * low-power timer (LPTMR0: 100 Hz from the 1 kHz LPO) up and idles; LPTimer_IRQHandler() steers
 * from the newest camera image. (The TFC library keeps the PIT for the camera's timing: the LPTMR
 * is free.)
 *
 *   simrunner drive examples/firmware/isr/main.c -I examples/firmware --kit tfc
 *
 * The simulator reads the LPTMR's set-up below as the board does (its clock, prescaler bypass and
 * compare value: 10 counts of 1 ms) and calls the handler at that rate (docs/firmware.md, Timer
 * interrupts); --isr LPTimer_IRQHandler@HZ would set another. __WFI() lets the board's
 * interrupts run: the SysTick, the camera's read-out into LineScanImage0, this handler. */
#include "derivative.h"
#include "TFC\TFC.h"

#include "lane.h"

static float v_max = V_MAX_MPS;

void LPTimer_IRQHandler(void) {
    LPTMR0_CSR |= LPTMR_CSR_TCF_MASK;                   /* clear the compare flag */
    if (LineScanImageReady != 1) return;                 /* no new image since the last pass */
    LineScanImageReady = 0;
    float steer, speed;
    lane_control(LineScanImage0, v_max, &steer, &speed);
    TFC_SetServo(0, steer / STEER_LIMIT_RAD);
    TFC_SetMotorPWM(speed / MAX_SPEED_MPS, speed / MAX_SPEED_MPS);
}

static void control_timer_init(void) {                  /* 100 Hz from the 1 kHz LPO clock */
    SIM_SCGC5 |= SIM_SCGC5_LPTMR_MASK;
    LPTMR0_CSR = 0;
    LPTMR0_PSR = LPTMR_PSR_PCS(1) | LPTMR_PSR_PBYP_MASK;
    LPTMR0_CMR = LPTMR_CMR_COMPARE(10 - 1);
    LPTMR0_CSR = LPTMR_CSR_TIE_MASK | LPTMR_CSR_TEN_MASK;
    NVIC_EnableIRQ(LPTimer_IRQn);
}

int main(void) {
    TFC_Init();
    while (!TFC_PUSH_BUTTON_0_PRESSED) TFC_Task();      /* wait for the start button */
    TFC_SetLineScanExposureTime(EXPOSURE_US);
    TFC_HBRIDGE_ENABLE;
    if (TFC_GetDIP_Switch() & 0x01) v_max = 3.0f;
    control_timer_init();
    for (;;) __WFI();                                     /* the work is the interrupt's */
}
