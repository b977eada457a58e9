/* TFC_Config.h (simulator): the library's configuration constants, as the FRDM-TFC code has them. */
#ifndef TFC_CONFIG_H_
#define TFC_CONFIG_H_
#define TFC_DEFAULT_LINESCAN_EXPOSURE_TIME_uS 50000
#define TFC_LINESCAN_IMAGE_SIZE 128      /* pixels of the TSL1401 line sensor */
#define PWM_SERVO_UPDATE_RATE 50         /* Hz: a hobby servo's 20 ms frame */
#define SERVO_MIN_DUTY_CYCLE (0.0010 * PWM_SERVO_UPDATE_RATE)  /* 1.0 ms: full one way */
#define SERVO_MAX_DUTY_CYCLE (0.0020 * PWM_SERVO_UPDATE_RATE)  /* 2.0 ms: full the other */
#define FTM0_SWITCHING_FREQUENCY 10000.0
#define FTM1_SWITCHING_FREQUENCY 50.0
#define TERMINAL_USE_SDA_SERIAL 1
#endif
