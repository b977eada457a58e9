/* TFC_ADC.h (simulator): the potentiometers (--param pot0, pot1: -1.0 .. 1.0, default 0), the
 * battery (--param battery_v, default 7.2 V), and the line-scan camera's image: LineScanImage0
 * holds the camera row's 128 pixels as 12-bit ADC counts (the row's 8-bit grey x 16, so
 * >> 4 gives the grey back); LineScanImageReady is set to 1 when a new image is there (your
 * code sets it back to 0). Camera 1 reads the same row. */
#ifndef TFC_ADC_H_
#define TFC_ADC_H_
#include <stdint.h>
void TFC_InitADCs(void);
float TFC_ReadPot(uint8_t Channel);
float TFC_ReadBatteryVoltage(void);
extern volatile uint16_t *LineScanImage0;
extern volatile uint16_t *LineScanImage1;
extern volatile uint8_t LineScanImageReady;
#endif
