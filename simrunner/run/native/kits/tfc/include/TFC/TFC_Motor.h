/* TFC_Motor.h (simulator): motor A (left rear) and B (right rear), duty -1.0 .. 1.0 each. Until
 * the simulator models the motors (duty drive), their mean duty is a speed: duty x --param
 * tfc_max_speed_mps (default 3.1, the default car's drive.max_speed_mps); the difference
 * between them is not a differential yet. Nothing moves while the H-bridge is disabled. */
#ifndef TFC_MOTOR_H_
#define TFC_MOTOR_H_
void TFC_InitMotorPWM(void);
void TFC_SetMotorPWM(float MotorA, float MotorB);
#endif
