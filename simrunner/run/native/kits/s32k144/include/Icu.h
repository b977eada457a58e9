/* Icu.h of the simulator's S32K144 kit: the input-capture types receiver.h names (not emulated). */
#ifndef NXPCUP_SIM_ICU_H
#define NXPCUP_SIM_ICU_H
#include "Std_Types.h"
typedef uint8 Icu_ChannelType;
typedef uint16 Icu_ValueType;
#endif
