/* TFC_LineScanCamera.h (simulator): the line-scan camera, declared where the FRDM-TFC library
 * declares it (its TFC_LineScanCamera.h: LineScanImage0/1, the double buffers
 * LineScanImage0Buffer/LineScanImage1Buffer[2][128], LineScanImageReady). The exposure is the
 * simulated line camera's (docs/camera.md): a new image every exposure (+ the read-out).
 *
 * LineScanImage0 holds the camera row's 128 pixels as 12-bit ADC counts (the row's 8-bit grey
 * x 16, so >> 4 gives the grey back); camera 1 reads the same row. LineScanImageReady is set to
 * 1 when a new image is there (your code sets it back to 0). On the board the PIT and ADC
 * interrupts fill the image while the main loop runs; here the flag and TFC_Ticker are reached
 * through a function (the macros below: `LineScanImageReady = 0`, `&LineScanImageReady` and
 * `extern volatile uint8_t LineScanImageReady;` keep working), so that a loop that only polls
 * them (`while (!LineScanImageReady);`) lets simulated time pass as the interrupts would. */
#ifndef TFC_LINESCANCAMERA_H_
#define TFC_LINESCANCAMERA_H_
#include <stdint.h>
void TFC_InitLineScanCamera(void);
void TFC_SetLineScanExposureTime(uint32_t TimeIn_uS);
extern volatile uint16_t *LineScanImage0;
extern volatile uint16_t *LineScanImage1;
extern volatile uint16_t *LineScanImage0WorkingBuffer;
extern volatile uint16_t *LineScanImage1WorkingBuffer;
extern volatile uint16_t LineScanImage0Buffer[2][128];
extern volatile uint16_t LineScanImage1Buffer[2][128];
extern volatile uint8_t LineScanWorkingBuffer;
/* The camera's clock and SI pins as the library's TFC_LineScanCamera.h writes them (the PIT and ADC
 * interrupts clock the camera out). A program that clocks the camera itself with them writes GPIO
 * registers, which are not emulated: its build fails naming them (docs/firmware.md). */
#define TAOS_CLK_HIGH GPIOE_PSOR = (1 << 1)
#define TAOS_CLK_LOW GPIOE_PCOR = (1 << 1)
#define TAOS_SI_HIGH GPIOD_PSOR = (1 << 7)
#define TAOS_SI_LOW GPIOD_PCOR = (1 << 7)
/* the simulator's hook behind the flag: a poll of it (see above) */
volatile uint8_t *tfc_sim_image_ready(void);
#define LineScanImageReady (*tfc_sim_image_ready())
#endif
