/* Dio.h of the simulator's S32K144 kit: the RTD DIO driver's types and channel calls. A
 * channel's level is kept; the H-bridge's direction pins (HbridgeInit) set the sign of each
 * motor's duty: forward high and backward low drives forwards, the other way backwards, both
 * equal stops it (the L298N's inputs; the car file's drive.hbridge says brake or coast). */
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
