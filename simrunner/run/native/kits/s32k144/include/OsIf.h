/* OsIf.h of the simulator's S32K144 kit: the RTD OS interface's millisecond clock and delay
 * (RTD BaseNXP OsIf.h: uint32 OsIf_GetMilliseconds(void), void OsIf_TimeDelay(const uint32)),
 * in simulated time: OsIf_GetMilliseconds lets one physics step pass (a polling loop moves on),
 * OsIf_TimeDelay waits that many simulated ms. */
#ifndef NXPCUP_SIM_OSIF_H
#define NXPCUP_SIM_OSIF_H
#include "Std_Types.h"
uint32 OsIf_GetMilliseconds(void);
void OsIf_TimeDelay(const uint32 delayMs);
#endif
