/* Std_Types.h of the simulator's S32K144 kit (simrunner drive ... --kit s32k144): the AUTOSAR
 * standard types the NXP Cup S32K144 drivers use (STD_HIGH, STD_ON, E_OK, ...), over
 * Platform_Types.h. On the car it comes with NXP's Real-Time Drivers (RTD); here it is ours.
 *
 * A call to a function no header declares is an error in kit builds (not C's old implicit
 * declaration): the RTD and register functions the simulator does not have (Pwm_Init,
 * Icu_StartSignalMeasurement, IP_PTD->PSOR, ...) then fail to compile at the line that calls
 * them, instead of at load time (docs/firmware.md, "The S32K144 kit"). */
#ifndef NXPCUP_SIM_STD_TYPES_H
#define NXPCUP_SIM_STD_TYPES_H
#ifndef __cplusplus  /* C++ has no implicit declarations: an undeclared call is an error already */
#pragma GCC diagnostic error "-Wimplicit-function-declaration"
#endif
#include "Platform_Types.h"

typedef uint8 Std_ReturnType;
#define E_OK ((Std_ReturnType)0U)
#define E_NOT_OK ((Std_ReturnType)1U)
#define STD_HIGH 0x01U
#define STD_LOW 0x00U
#define STD_ACTIVE 0x01U
#define STD_IDLE 0x00U
#define STD_ON 0x01U
#define STD_OFF 0x00U
#ifndef NULL_PTR
#define NULL_PTR ((void *)0)  /* as the RTD's Compiler.h */
#endif
#endif
