/* linear_camera.h of the simulator's S32K144 kit: the NXP Cup S32K144 kit's driver of the
 * 128-pixel linear camera (TSL1401 type), the same names and signatures as in
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * LinearCameraInit(clock PWM channel, shutter GPT channel, ADC group, shutter DIO pin) sets it
 * up; LinearCameraGetFrame(&frame) blocks until a whole image is in frame.Values, as the
 * driver does (it pulses the shutter and waits while the PWM clock and the ADC read the 128
 * pixels). A pixel is the 8-bit ADC's count x 25 / 64: 0 (dark) .. 99 (bright), as the
 * driver stores it.
 *
 * On the simulated car LinearCameraGetFrame waits for the car camera's next image of its line
 * row (with the camera's noise; simulated time passes) and converts its 8-bit grey the same
 * way (a camera wider than 128 pixels is sampled at 128 evenly spaced ones). The exposure is the camera's (the car file's, 19.5 ms on the default car; docs/camera.md)
 * unless --param s32k_exposure_ms sets it; the camera's frames are exposure + read-out apart. */
#ifndef LINEAR_CAMERA_H
#define LINEAR_CAMERA_H
#ifdef __cplusplus
extern "C" {
#endif
#include "Pwm.h"
#include "Adc.h"
#include "Gpt.h"
#include "Dio.h"

typedef struct {
    uint8 Values[128];
} LinearCameraFrame;

typedef struct {
    Pwm_ChannelType ClkPwmChannel;
    Gpt_ChannelType ShutterGptChannel;
    Adc_GroupType InputAdcGroup;
    Dio_ChannelType ShutterDioChannel;
    uint16 CurrentIndex;
    LinearCameraFrame *BufferReference;
} LinearCamera;

void LinearCameraInit(Pwm_ChannelType ClkPwmChannel, Gpt_ChannelType ShutterGptChannel, Adc_GroupType InputAdcGroup,
                      Dio_ChannelType ShutterDioChannel);
void LinearCameraGetFrame(LinearCameraFrame *Frame);

#ifdef __cplusplus
}
#endif
#endif
