/* Gpt.h of the simulator's S32K144 kit: the RTD GPT driver's types and calls (AUTOSAR SWS General
 * Purpose Timer: Gpt_Init, Gpt_DeInit, Gpt_StartTimer(channel, target ticks), Gpt_StopTimer,
 * Gpt_GetTimeElapsed, Gpt_GetTimeRemaining, Gpt_EnableNotification/DisableNotification).
 *
 * On the simulated car (gpt.c) a channel counts simulated time in ticks of --param
 * s32k_gpt_tick_hz (default 8 MHz, the channel clock github.com/michalfrohlich/NXP-Cup-EXPO's
 * src/timebase.c notes for its sample-based configuration: set your channel's) from
 * Gpt_StartTimer. A continuous channel (the default) wraps at its target; a one-shot channel
 * (your generated configuration's GPT_CH_MODE_ONESHOT, given as -D GPT_CHANNEL_MODE_<n>=
 * GPT_CH_MODE_ONESHOT, n = 0..7) stops there, expired: it reads the target elapsed, 0 remaining,
 * and may be started again. A stopped channel reads what it had at its stop; one never started 0.
 * The reads let no time pass (the count at the program's last call; a loop polling them lets a
 * physics step pass a read after 64 reads without one). A running channel whose notification is
 * enabled calls it at each expiry (once for a one-shot): the notification the kit's Gpt
 * configuration names (channel 0: Gpt_Notification, as the sample's generated configuration;
 * another channel: -D GPT_NOTIFICATION_<n>=NAME), unless --isr NAME@HZ runs it at a rate of its own
 * (docs/firmware.md, "Timer interrupts"). Gpt_Init takes any configuration (NULL_PTR, or the
 * generated Gpt_Config_VS_0 / Gpt_Config): it stops every channel. */
#ifndef NXPCUP_SIM_GPT_H
#define NXPCUP_SIM_GPT_H
#include "Std_Types.h"
#ifdef __cplusplus
extern "C" {
#endif
typedef uint8 Gpt_ChannelType;
typedef uint32 Gpt_ValueType;
typedef enum { GPT_CH_MODE_CONTINUOUS = 0, GPT_CH_MODE_ONESHOT = 1 } Gpt_ChannelModeType;
typedef struct Gpt_ConfigType Gpt_ConfigType;  /* the generated configuration: its content is the kit's */
extern const Gpt_ConfigType Gpt_Config_VS_0;   /* the generated configuration's names (Gpt_VS_0_PBcfg.c) */
extern const Gpt_ConfigType Gpt_Config;

void Gpt_Init(const Gpt_ConfigType *ConfigPtr);
void Gpt_DeInit(void);

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
