/* derivative.h of the simulator's TFC kit (simrunner drive ... --kit tfc).
 *
 * On the FRDM-KL25Z this header pulls in MKL25Z4.h, the MCU's register map. The simulator has
 * no registers but those of a timer interrupt's set-up (TFC/sim_timers.h, read by the kit's
 * timers.c: the handler runs at the rate they give): code that writes
 * others directly (GPIOB_PSOR = ..., TPM0_C0V = ...) does not compile here; reach the hardware through the TFC library's functions and macros, which the
 * simulator implements (docs/firmware.md). */
#ifndef NXPCUP_SIM_DERIVATIVE_H
#define NXPCUP_SIM_DERIVATIVE_H
#include <stdint.h>
#include "TFC/sim_timers.h"  /* the timers of a timer interrupt of your own */
/* The MCU's interrupt mask (PRIMASK; MKL25Z4.h's EnableInterrupts / DisableInterrupts, the CMSIS
 * __enable_irq() / __disable_irq(), __get_PRIMASK() / __set_PRIMASK()): while disabled, a timer
 * interrupt that falls due is held pending and its handler runs once when they are enabled again
 * (spinner.h, spinner_disable_interrupts); the library's SysTick tickers and camera read-out stop
 * (tfc.c: interrupts too). */
#include "spinner_primask.h"  /* __disable_irq, __enable_irq, __get_PRIMASK, __set_PRIMASK */
#define EnableInterrupts spinner_enable_interrupts()
#define DisableInterrupts spinner_disable_interrupts()
/* The CMSIS intrinsics of core_cm0plus.h that firmware calls. __WFI() (wait for an interrupt)
 * lets the board's interrupts run: a pass of TFC_Task() (a physics step, the SysTick tickers, the
 * camera read-out), in which the timer interrupts' handlers due run (docs/firmware.md, Timer
 * interrupts); an idle `for (;;) __WFI();` main loop leaves the work to them. */
void tfc_sim_wfi(void);
#define __WFI() tfc_sim_wfi()
#define __WFE() tfc_sim_wfi()
#define __NOP() do { } while (0)
#endif
