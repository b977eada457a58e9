/* Dio.h of the simulator's S32K144 kit: the RTD DIO driver's types and channel calls. A
 * channel's level is kept; the H-bridge's direction pins (HbridgeInit) set the sign of each
 * motor's duty: forward high and backward low drives forwards, the other way backwards, both
 * equal stops it (the L298N's inputs; the car file's drive.hbridge says brake or coast).
 * Inputs: --param s32k_sw2=N / s32k_sw3=N make channel N the board's button SW2 / SW3 (STD_HIGH
 * while pressed, STD_LOW with s32k_sw2_pressed_level=0: SW2 for 0.2 s at s32k_sw2_at, default
 * 0.1 s, and again at s32k_sw2_at_2, _at_3, ...; SW3 at s32k_sw3_at if given), and s32k_pin_N=0/1
 * a constant level; writes to them are ignored, as on an input channel. */
#ifndef NXPCUP_SIM_DIO_H
#define NXPCUP_SIM_DIO_H
#include "Std_Types.h"

typedef uint16 Dio_ChannelType;
typedef uint8 Dio_LevelType;
#ifdef __cplusplus
extern "C" {
#endif

void Dio_WriteChannel(Dio_ChannelType ChannelId, Dio_LevelType Level);
Dio_LevelType Dio_ReadChannel(Dio_ChannelType ChannelId);
Dio_LevelType Dio_FlipChannel(Dio_ChannelType ChannelId);
#ifdef __cplusplus
}
#endif
#endif
