/* Gpt.h of the simulator's S32K144 kit: the RTD GPT driver's types and its timer calls
 * (AUTOSAR SWS_GeneralPurposeTimer: Gpt_StartTimer(channel, target ticks), Gpt_StopTimer,
 * Gpt_GetTimeElapsed, Gpt_GetTimeRemaining, Gpt_EnableNotification/DisableNotification).
 *
 * On the simulated car a channel counts simulated time in ticks of --param s32k_gpt_tick_hz
 * (default 8 MHz, the channel clock github.com/michalfrohlich/NXP-Cup-EXPO's src/main.c notes for
 * its sample-based configuration, "ticks = 8e6 * seconds": set your channel's), from
 * Gpt_StartTimer, as a
 * continuous channel (the count wraps at the target); a stopped or never started channel reads 0
 * elapsed. Gpt_StartTimer, Gpt_GetTimeElapsed and Gpt_GetTimeRemaining read the simulated
 * clock as OsIf_GetMilliseconds does, letting one physics step pass (2 ms by default), so a
 * loop polling them moves on. A channel's notification is an
 * interrupt handler your generated configuration names: run with --isr NAME@HZ it is called at
 * that rate and Gpt_EnableNotification does nothing more; without --isr, Gpt_EnableNotification
 * stops the run saying so (docs/firmware.md, "Timer interrupts"). */
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
