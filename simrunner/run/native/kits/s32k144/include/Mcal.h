/* Mcal.h of the simulator's S32K144 kit: the RTD's common header; here the standard types and the
 * core's interrupt mask: the CMSIS intrinsics __disable_irq() / __enable_irq() (cpsid i / cpsie i,
 * PRIMASK) and __get_PRIMASK() / __set_PRIMASK() on spinner_disable_interrupts: while disabled, a
 * Gpt notification that falls due is held pending and runs once when they are enabled again. */
#ifndef NXPCUP_SIM_MCAL_H
#define NXPCUP_SIM_MCAL_H
#include "Std_Types.h"
#include "spinner_primask.h"  /* __disable_irq, __enable_irq, __get_PRIMASK, __set_PRIMASK */
#endif
