/* MKL25Z4.h of the simulator's TFC kit (simrunner drive ... --kit tfc): on the FRDM-KL25Z the
 * MCU's register map, which the project's derivative.h includes (CodeWarrior) and which a team's
 * own modules often include themselves (Kinetis Design Studio projects, a timer's set-up in its own
 * file). Here it is derivative.h: the registers of a timer interrupt's set-up (TFC/sim_timers.h),
 * the interrupt mask and __WFI(); others do not compile (docs/firmware.md). */
#ifndef NXPCUP_SIM_MKL25Z4_H
#define NXPCUP_SIM_MKL25Z4_H
#include "derivative.h"
#endif
