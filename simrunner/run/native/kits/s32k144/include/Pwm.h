/* Pwm.h of the simulator's S32K144 kit: the RTD PWM driver's channel type and
 * Pwm_SetDutyCycle, the call the kit's servo, H-bridge and ESC drivers make. A duty cycle is
 * 0 .. 0x8000 (100 %), as in AUTOSAR's PWM driver.
 *
 * On the simulated car a channel acts through the role the kit's drivers gave it: the servo
 * channel of ServoInit steers, the motor channels of HbridgeInit set the rear motors' duty
 * (their direction from the Dio pins), the ESC channel of EscInit sets both; other channels
 * are kept and do nothing (simrunner/run/native/kits/s32k144/s32k144.c). */
#ifndef NXPCUP_SIM_PWM_H
#define NXPCUP_SIM_PWM_H
#include "Std_Types.h"

typedef uint8 Pwm_ChannelType;
typedef uint16 Pwm_PeriodType;
typedef enum { PWM_RISING_EDGE = 1, PWM_FALLING_EDGE = 2, PWM_BOTH_EDGES = 3 } Pwm_EdgeNotificationType;
#define PWM_DUTY_100_PERCENT 0x8000U
#ifdef __cplusplus
extern "C" {
#endif

void Pwm_SetDutyCycle(Pwm_ChannelType ChannelNumber, uint16 DutyCycle);
#ifdef __cplusplus
}
#endif
#endif
