/* servo.h of the simulator's S32K144 kit (simrunner drive ... --kit s32k144): the NXP Cup
 * S32K144 kit's steering servo driver, the same names and signatures as in
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * ServoInit(channel, MaxDutyCycle, MinDutyCycle, MedDutyCycle) takes the PWM duty cycles
 * (0 .. 0x8000 = 100 % of the 20 ms frame: the sample's 3300, 1700, 2500 are 2.0, 1.04 and
 * 1.53 ms pulses) of the servo's two ends and its middle, and centres the servo. Steer(-100 ..
 * 100) goes from MedDutyCycle towards MaxDutyCycle for positive values and towards
 * MinDutyCycle for negative ones (clamped at +-100); SteerRight() is MaxDutyCycle, SteerLeft()
 * MinDutyCycle, SteerStraight() MedDutyCycle: positive = right, as the guide says.
 *
 * On the simulated car the servo is calibrated as ServoInit says: MedDutyCycle is straight
 * ahead, MaxDutyCycle full right, MinDutyCycle full left (either the longer pulse: a mirrored
 * linkage passes Max < Med < Min); full is --param s32k_servo_rad
 * (default 0.40 rad, the default car's limit; negative if your linkage turns the other way),
 * plus --param s32k_servo_offset_rad. A duty beyond the calibrated ends is held at them. */
#ifndef SERVO_H
#define SERVO_H
#ifdef __cplusplus
extern "C" {
#endif
#include "Pwm.h"

typedef struct {
    Pwm_ChannelType ServoPwmChannel;
    uint16 MinDutyCycle;
    uint16 MaxDutyCycle;
    uint16 MedDutyCycle;
} Servo;

void ServoInit(Pwm_ChannelType ServoPwmChannel, uint16 MaxDutyCycle, uint16 MinDutyCycle, uint16 MedDutyCycle);
void Steer(int Direction);
void SteerLeft(void);
void SteerRight(void);
void SteerStraight(void);

#ifdef __cplusplus
}
#endif
#endif
