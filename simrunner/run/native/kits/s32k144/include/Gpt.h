/* Gpt.h of the simulator's S32K144 kit: the timer types the linear camera driver's header
 * names. The GPT driver's calls are not emulated: for time use OsIf.h (simulated ms). */
#ifndef NXPCUP_SIM_GPT_H
#define NXPCUP_SIM_GPT_H
#include "Std_Types.h"
typedef uint8 Gpt_ChannelType;
typedef uint32 Gpt_ValueType;
#endif
