/* esc.h of the simulator's S32K144 kit: the NXP Cup S32K144 kit's driver of a brushless
 * motor's ESC, the same names and signatures as in
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * EscInit(channel, MinDutyCycle, MedDutyCycle, MaxDutyCycle): the PWM duty cycles of full
 * reverse, stop and full forward (the sample's 1638, 2457, 3276 of 0x8000 are the standard 1,
 * 1.5 and 2 ms pulses of a 20 ms frame); it sends the stop pulse (which arms the ESC) and starts
 * the driver's state machine. EscSetSpeed(-100 .. 100, clamped) and EscSetBrake(non-zero: 1)
 * only store the request: as the sample's src/esc.c, the state machine (Forward, Braking,
 * Neutral, Reverse) runs at the end of each period of the ESC's PWM - the channel's falling-edge
 * notification, Esc_Period_Finished in the sample's configuration - and only then sets the
 * pulse. So a change takes effect at the next period's edge, and a forward car reverses through
 * Braking and Neutral, one period each. The period: --param s32k_esc_hz (default 50 Hz, the
 * sample's configuration: FTM3's 8 MHz SIRCDIV1 clock / 4, a period of 40000 ticks = 20 ms,
 * the RC servo/ESC frame; generate/src/Ftm_Pwm_Ip_VS_0_PBcfg.c, Clock_Ip_VS_0_PBcfg.c), from
 * EscInit on.
 *
 * ESC_HAS_BRAKE (STD_ON unless given, as a team sets it in its copy: -D ESC_HAS_BRAKE=STD_OFF)
 * says which ESC the car has, and picks the driver's table, as in the sample: with a brake the
 * Braking state sends full reverse (-100), without one the opposite of the speed (-Speed).
 *
 * On the simulated car the pulse is a duty of both rear motors (spinner_set_motors; docs/drive.md):
 * (pulse - Med) / (Max - Med) forwards, (pulse - Med) / (Med - Min) backwards, as a car ESC takes
 * it. An ESC with a brake (ESC_HAS_BRAKE == STD_ON) runs in "forward/reverse with brake" mode: a
 * pulse below the stop pulse after a forward one brakes, and reverses only once a stop pulse has
 * been seen (the "double-click" of the Force RC EPIDEMIC ESC's instruction manual, p. 9, "Running
 * Mode": manualshive.com/en/manual/force-rc/epidemic/2317056?page=9). Such a brake is duty 0: on a duty
 * car with drive.hbridge = "brake" the motors are shorted (their back-EMF brakes), a speed car is
 * told 0 m/s; on a drive.hbridge = "coast" car duty 0 rolls freely. A stop pulse is duty 0 too. An
 * ESC without a brake (STD_OFF) drives backwards at any pulse below the stop pulse.
 * docs/firmware.md, "The S32K144 kit". */
#ifndef ESC_H
#define ESC_H
#ifdef __cplusplus
extern "C" {
#endif
#include "Pwm.h"

#ifndef ESC_HAS_BRAKE
#define ESC_HAS_BRAKE STD_ON
#endif

enum EscStates { Forward, Braking, Neutral, Reverse };

typedef struct {
    enum EscStates State;
    Pwm_ChannelType Channel;
    uint16 MinDutyCycle;
    uint16 MaxDutyCycle;
    uint16 MedDutyCycle;
    int Speed;    /* -100 .. 100 */
    uint8 Brake;  /* 0 or 1 */
} Esc;

void EscInit(Pwm_ChannelType EscPwmChannel, uint16 MinDutyCycle, uint16 MedDutyCycle, uint16 MaxDutyCycle);
void EscSetSpeed(int Speed);
void EscSetBrake(uint8 Brake);

#ifdef __cplusplus
}
#endif
#endif
