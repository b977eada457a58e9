/* TFC_Motor.h (simulator): motor A (left rear) and B (right rear), duty -1.0 .. 1.0 each
 * (spinner_set_motors): a car file with drive.command = "duty" drives each wheel through its
 * motor model; a speed-commanded car takes the mean duty x its drive.max_speed_mps as a speed.
 * Nothing moves while the H-bridge is disabled. */
#ifndef TFC_MOTOR_H_
#define TFC_MOTOR_H_
void TFC_InitMotorPWM(void);
void TFC_SetMotorPWM(float MotorA, float MotorB);
#endif
