/* TFC_LineScanCamera.h (simulator): the exposure is the simulated line camera's
 * (docs/camera.md): a new image every exposure (+ the read-out). */
#ifndef TFC_LINESCANCAMERA_H_
#define TFC_LINESCANCAMERA_H_
#include <stdint.h>
void TFC_InitLineScanCamera(void);
void TFC_SetLineScanExposureTime(uint32_t TimeIn_uS);
#endif
