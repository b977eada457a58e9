/* hbridge.h of the simulator's S32K144 kit: the NXP Cup S32K144 kit's driver of the two rear
 * DC motors through an L298N H-bridge, the same names and signatures as in
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * HbridgeInit(Motor1_Speed, Motor2_Speed, Motor1_Forward, Motor1_Backward, Motor2_Forward,
 * Motor2_Backward): the two motors' PWM channels and their direction pins (Dio channels).
 * HbridgeSetSpeed(-100 .. 100) drives both: the direction pins by the sign, the duty
 * |Speed| x 0x8000 / 100 (clamped at +-100); ignored while braking. HbridgeSetBrake(non-zero)
 * brakes (full duty, all direction pins low: the L298N's fast stop), HbridgeSetBrake(0) resumes
 * the last speed. HbridgeGetSpeed and HbridgeGetBrake return the last values set.
 *
 * On the simulated car motor 1 is the left rear motor and motor 2 the right one: each one's
 * duty (-1 .. 1: the PWM duty, its sign from its direction pins, 0 when both are equal) goes to
 * spinner_set_motors. A car file with drive.command = "duty" drives each wheel through its
 * motor model (braking is its drive.hbridge at zero duty); a speed-commanded car takes the mean
 * duty x its drive.max_speed_mps as a speed (docs/drive.md). */
#ifndef HBRIDGE
#define HBRIDGE
#ifdef __cplusplus
extern "C" {
#endif
#include "Pwm.h"
#include "Dio.h"

typedef struct {
    Pwm_ChannelType Motor1_Speed;
    Pwm_ChannelType Motor2_Speed;
    Dio_ChannelType Motor1_Forward;
    Dio_ChannelType Motor1_Backward;
    Dio_ChannelType Motor2_Forward;
    Dio_ChannelType Motor2_Backward;
    uint8 Brake;
    int Speed;
} Hbridge;

void HbridgeInit(Pwm_ChannelType Motor1_Speed, Pwm_ChannelType Motor2_Speed, Dio_ChannelType Motor1_Forward,
                 Dio_ChannelType Motor1_Backward, Dio_ChannelType Motor2_Forward, Dio_ChannelType Motor2_Backward);
void HbridgeSetSpeed(int Speed);
void HbridgeSetBrake(uint8 Brake);
int HbridgeGetSpeed(void);
uint8 HbridgeGetBrake(void);

#ifdef __cplusplus
}
#endif
#endif
