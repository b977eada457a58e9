/* TFC_Servo.h (simulator): servo 0 steers the car. Position -1.0 .. 1.0 is the servo's travel;
 * the car's steering angle is position x --param tfc_servo_rad (default 0.40 rad, the default
 * car's limit; negative if your servo turns the other way) + tfc_servo_offset_rad, + = left. */
#ifndef TFC_SERVO_H_
#define TFC_SERVO_H_
#include <stdint.h>
void TFC_InitServos(void);
void TFC_SetServo(uint8_t ServoNumber, float Position);
void TFC_SetServoDutyCycle(uint8_t ServoNumber, float DutyCycle);
#endif
