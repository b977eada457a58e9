/* TFC.h of the simulator's TFC kit: the FRDM-TFC shield library's API (TFC_Init, TFC_Task,
 * the servo, the two motors, the line-scan camera, the potentiometers, DIP switches, push
 * buttons and LEDs, the SysTick tickers) implemented on the simulated car
 * (simrunner/run/native/kits/tfc/tfc.c; docs/firmware.md). */
#ifndef TFC_H_
#define TFC_H_

#include <stdint.h>
#include <stdio.h>
#include <stdarg.h>
#include <string.h>
#include "derivative.h"
#include "TFC/TFC_Config.h"
#include "TFC/TFC_Types.h"
#include "TFC/TFC_arm_cm0.h"
#include "TFC/TFC_ARM_SysTick.h"
#include "TFC/TFC_BoardSupport.h"
#include "TFC/TFC_CrystalClock.h"
#include "TFC/TFC_Servo.h"
#include "TFC/TFC_Motor.h"
#include "TFC/TFC_ADC.h"
#include "TFC/TFC_LineScanCamera.h"
#include "TFC/TFC_Queue.h"
#include "TFC/TFC_UART.h"
#include "TFC/TFC_Terminal.h"

#define _USE_MATH_DEFINES
#include <math.h>
#include <stdlib.h>

void TFC_Task(void);
void TFC_Init(void);

#endif
