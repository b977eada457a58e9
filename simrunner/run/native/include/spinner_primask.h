/* spinner_primask.h: the Cortex-M's interrupt mask (PRIMASK) as the CMSIS intrinsics spell it,
 * on the Spinner calls that mask the timer interrupts (spinner.h, spinner_disable_interrupts):
 * the kits' headers that stand for the MCU's (tfc derivative.h, s32k144 Mcal.h) include it, so
 * that team code gets these names without the rest of spinner.h. */
#ifndef NXPCUP_SIM_SPINNER_PRIMASK_H
#define NXPCUP_SIM_SPINNER_PRIMASK_H
#include <stdint.h>
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
#define __get_PRIMASK() ((uint32_t)(spinner_interrupts_disabled() != 0))
#define __set_PRIMASK(primask) (((primask) & 1u) ? spinner_disable_interrupts() : spinner_enable_interrupts())
#endif
