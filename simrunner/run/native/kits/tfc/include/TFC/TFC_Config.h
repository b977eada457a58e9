/* TFC_Config.h (simulator): the library's configuration constants, as the FRDM-TFC code has them. */
#ifndef TFC_CONFIG_H_
#define TFC_CONFIG_H_
#define TFC_DEFAULT_LINESCAN_EXPOSURE_TIME_uS 50000
/* TFC_Ticker[]'s length (teams' copies set 4 to 8; the kit counts 16 whatever the length:
 * TFC_SIM_TICKERS in tfc.c, so a project that set more indexes real tickers) */
#define NUM_TFC_TICKERS 4
#define TFC_LINESCAN_IMAGE_SIZE 128      /* pixels of the TSL1401 line sensor */
#define PWM_SERVO_UPDATE_RATE 50         /* Hz: a hobby servo's 20 ms frame */
#define SERVO_MIN_DUTY_CYCLE (0.0010 * PWM_SERVO_UPDATE_RATE)  /* 1.0 ms: full one way */
#define SERVO_MAX_DUTY_CYCLE (0.0020 * PWM_SERVO_UPDATE_RATE)  /* 2.0 ms: full the other */
#define FTM0_SWITCHING_FREQUENCY 10000.0
#define FTM1_SWITCHING_FREQUENCY 50.0
#define TERMINAL_USE_SDA_SERIAL 1
#endif
