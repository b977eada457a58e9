/* receiver.h of the simulator's S32K144 kit: the kit's RC receiver (PPM) driver's names, from
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 * Not emulated (there is no remote control in the simulator): calling one stops the run with a
 * message naming it. */
#ifndef RECEIVER_H
#define RECEIVER_H
#ifdef __cplusplus
extern "C" {
#endif
#include "Icu.h"
#include "Gpt.h"

enum ReceiverStates { Channel1, Channel2, Channel3, Channel4, Channel5, Channel6, Channel7, Channel8,
                      BetweenChannels };

void ReceiverInit(Icu_ChannelType ReceiverIcuChannel, Gpt_ChannelType ReceiverGptChannel, uint16 ChannelMinTicks,
                  uint16 ChannelMedTicks, uint16 ChannelMaxTicks, uint16 OutsideChannelTicks);
int GetReceiverChannel(uint8 Channel);
void ReceiverStateUpdate(Gpt_ValueType ReceiverPeriod);
enum ReceiverStates GetReceiverState(void);

#ifdef __cplusplus
}
#endif
#endif
