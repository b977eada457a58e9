/* Gpt.h of the simulator's S32K144 kit: the RTD GPT driver's types and its timer calls
 * (AUTOSAR SWS_GeneralPurposeTimer: Gpt_StartTimer(channel, target ticks), Gpt_StopTimer,
 * Gpt_GetTimeElapsed, Gpt_GetTimeRemaining, Gpt_EnableNotification/DisableNotification).
 *
 * On the simulated car (gpt.c) a channel counts simulated time in ticks of --param
 * s32k_gpt_tick_hz (default 8 MHz, the channel clock github.com/michalfrohlich/NXP-Cup-EXPO's
 * src/timebase.c notes for its sample-based configuration: set your channel's), from
 * Gpt_StartTimer, as a continuous channel (the count wraps at the target); a stopped or never
 * started channel reads 0 elapsed. Gpt_StartTimer, Gpt_GetTimeElapsed and Gpt_GetTimeRemaining
 * read the simulated clock as OsIf_GetMilliseconds does, letting one physics step pass (2 ms by
 * default), so a loop polling them moves on. A running channel whose notification is enabled
 * calls it every target ticks: the notification the kit's Gpt configuration names (channel 0:
 * Gpt_Notification, as the sample's generated configuration; another channel:
 * -D GPT_NOTIFICATION_<n>=NAME), unless --isr NAME@HZ runs it at a rate of its own
 * (docs/firmware.md, "Timer interrupts"). */
#ifndef NXPCUP_SIM_GPT_H
#define NXPCUP_SIM_GPT_H
#include "Std_Types.h"
#ifdef __cplusplus
extern "C" {
#endif
typedef uint8 Gpt_ChannelType;
typedef uint32 Gpt_ValueType;

void Gpt_StartTimer(Gpt_ChannelType Channel, Gpt_ValueType Value);
void Gpt_StopTimer(Gpt_ChannelType Channel);
Gpt_ValueType Gpt_GetTimeElapsed(Gpt_ChannelType Channel);
Gpt_ValueType Gpt_GetTimeRemaining(Gpt_ChannelType Channel);
void Gpt_EnableNotification(Gpt_ChannelType Channel);
void Gpt_DisableNotification(Gpt_ChannelType Channel);
#ifdef __cplusplus
}
#endif
#endif
