/* derivative.h of the simulator's TFC kit (simrunner drive ... --kit tfc).
 *
 * On the FRDM-KL25Z this header pulls in MKL25Z4.h, the MCU's register map. The simulator has
 * no registers: code that writes them directly (GPIOB_PSOR = ..., TPM0_C0V = ...) does not
 * compile here; reach the hardware through the TFC library's functions and macros, which the
 * simulator implements (docs/c_controllers.md, "Kit libraries"). */
#ifndef NXPCUP_SIM_DERIVATIVE_H
#define NXPCUP_SIM_DERIVATIVE_H
#include <stdint.h>
#define EnableInterrupts do { } while (0)
#define DisableInterrupts do { } while (0)
#endif
