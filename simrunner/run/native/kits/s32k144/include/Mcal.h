/* Mcal.h of the simulator's S32K144 kit: the RTD's common header; here the standard types and the
 * core's interrupt mask: the CMSIS intrinsics __disable_irq() / __enable_irq() (cpsid i / cpsie i,
 * PRIMASK) and __get_PRIMASK() / __set_PRIMASK() on spinner_disable_interrupts: while disabled, a
 * Gpt notification that falls due is held pending and runs once when they are enabled again. */
#ifndef NXPCUP_SIM_MCAL_H
#define NXPCUP_SIM_MCAL_H
#include "Std_Types.h"
#ifdef __cplusplus
extern "C" {
#endif
void spinner_disable_interrupts(void);
void spinner_enable_interrupts(void);
int spinner_interrupts_disabled(void);
#ifdef __cplusplus
}
#endif
#define __disable_irq() spinner_disable_interrupts()
#define __enable_irq() spinner_enable_interrupts()
#define __get_PRIMASK() ((uint32)(spinner_interrupts_disabled() != 0))
#define __set_PRIMASK(primask) (((primask) & 1u) ? spinner_disable_interrupts() : spinner_enable_interrupts())
#endif
