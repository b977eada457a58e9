/* TFC_ADC.h (simulator): the potentiometers (--param pot0, pot1: -1.0 .. 1.0, default 0) and the
 * battery (--param battery_v, default 7.2 V: TFC_ReadBatteryVoltage returns its sense input, as the
 * library does, battery_v x 10k / (47k + 10k)). The camera's image and ready flag are declared in
 * TFC_LineScanCamera.h, as in the library, which this includes for code that expects them here. */
#ifndef TFC_ADC_H_
#define TFC_ADC_H_
#include <stdint.h>
#include "TFC/TFC_LineScanCamera.h"
void TFC_InitADCs(void);
float TFC_ReadPot(uint8_t Channel);
float TFC_ReadBatteryVoltage(void);
#endif
