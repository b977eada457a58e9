/* OsIf.h of the simulator's S32K144 kit: the RTD OS interface (RTD BaseNXP OsIf.h): the
 * millisecond clock and delay (uint32 OsIf_GetMilliseconds(void), void OsIf_TimeDelay(const
 * uint32)) and the tick counters RTD code and teams time busy-waits with (OsIf_CounterType,
 * OsIf_Init, OsIf_GetCounter, OsIf_GetElapsed, OsIf_SetTimerFrequency, OsIf_MicrosToTicks),
 * in simulated time:
 * - OsIf_GetMilliseconds, OsIf_GetCounter and OsIf_GetElapsed let one physics step pass (a
 *   polling loop moves on; a wait is a whole number of steps, 2 ms by default), OsIf_TimeDelay
 *   waits that many simulated ms;
 * - OSIF_COUNTER_SYSTEM counts simulated time at --param s32k_osif_hz (default 48 MHz, the core
 *   clock of a sample-based team project: github.com/charbel-j-estephan/Nxp_Cup_Pixy2_S32K144,
 *   src/main.c, DelayInit(48000000U); the S32K144 runs up to 80 MHz: set your configuration's;
 *   OsIf_SetTimerFrequency changes it), OSIF_COUNTER_DUMMY counts
 *   calls (one per OsIf_GetCounter / OsIf_GetElapsed, MicrosToTicks = the microseconds), as the
 *   RTD's dummy counter does; OSIF_COUNTER_CUSTOM is the system counter here. */
#ifndef NXPCUP_SIM_OSIF_H
#define NXPCUP_SIM_OSIF_H
#include "Mcal.h"
#ifdef __cplusplus
extern "C" {
#endif
/* The critical sections of RTD drivers and team code: bare-metal, the core's interrupt mask
 * (__disable_irq / __set_PRIMASK, Mcal.h), nested as the OS services they stand for - OSEK/VDX OS
 * 2.2.3, 13.3.2 (interrupt handling): SuspendAllInterrupts / ResumeAllInterrupts can be nested; the state
 * saved by the first Suspend is restored by the last Resume (so a driver's section inside the
 * team's does not enable interrupts). Macros, so that the warning of interrupts left disabled
 * names the caller's line. */
extern volatile int s32k_sim_suspend_nesting;
extern volatile uint32 s32k_sim_suspend_primask;
#define SuspendAllInterrupts() do { uint32 s32k_sim_pm_ = __get_PRIMASK(); __disable_irq(); \
        if (s32k_sim_suspend_nesting++ == 0) s32k_sim_suspend_primask = s32k_sim_pm_; } while (0)
#define ResumeAllInterrupts() do { if (s32k_sim_suspend_nesting > 0 && --s32k_sim_suspend_nesting == 0) \
        __set_PRIMASK(s32k_sim_suspend_primask); } while (0)
#define OsIf_SuspendAllInterrupts() SuspendAllInterrupts()
#define OsIf_ResumeAllInterrupts() ResumeAllInterrupts()
typedef enum { OSIF_COUNTER_DUMMY, OSIF_COUNTER_SYSTEM, OSIF_COUNTER_CUSTOM } OsIf_CounterType;

void OsIf_Init(const void *Config);
uint32 OsIf_GetMilliseconds(void);
void OsIf_TimeDelay(const uint32 delayMs);
uint32 OsIf_GetCounter(OsIf_CounterType SelectedCounter);
uint32 OsIf_GetElapsed(uint32 *const CurrentRef, OsIf_CounterType SelectedCounter);
void OsIf_SetTimerFrequency(uint32 Freq, OsIf_CounterType SelectedCounter);
uint32 OsIf_MicrosToTicks(uint32 Micros, OsIf_CounterType SelectedCounter);
#ifdef __cplusplus
}
#endif
#endif
