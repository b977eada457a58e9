/* esc.h of the simulator's S32K144 kit: the NXP Cup S32K144 kit's driver of a brushless
 * motor's ESC, the same names and signatures as in
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * EscInit(channel, MinDutyCycle, MedDutyCycle, MaxDutyCycle): the PWM duty cycles of full
 * reverse, stop and full forward (the sample's 1638, 2457, 3276 are the standard 1, 1.5 and
 * 2 ms pulses). EscSetSpeed(-100 .. 100) sets the pulse between them; EscSetBrake(non-zero)
 * holds the stop pulse until EscSetBrake(0) resumes the last speed.
 *
 * On the simulated car the ESC's pulse is a duty of both rear motors: (pulse - Med) / (Max -
 * Med) forwards, (pulse - Med) / (Med - Min) backwards (spinner_set_motors; docs/drive.md). */
#ifndef ESC_H
#define ESC_H
#ifdef __cplusplus
extern "C" {
#endif
#include "Pwm.h"

void EscInit(Pwm_ChannelType EscPwmChannel, uint16 MinDutyCycle, uint16 MedDutyCycle, uint16 MaxDutyCycle);
void EscSetSpeed(int Speed);
void EscSetBrake(uint8 Brake);

#ifdef __cplusplus
}
#endif
#endif
