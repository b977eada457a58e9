/* Platform_Types.h of the simulator's S32K144 kit: AUTOSAR's fixed-size types (uint8, uint16,
 * uint32, sint8 .. sint32, float32, float64, boolean, TRUE/FALSE) as the RTD define them for
 * the S32K144's Cortex-M4F, on the host's <stdint.h>. */
#ifndef NXPCUP_SIM_PLATFORM_TYPES_H
#define NXPCUP_SIM_PLATFORM_TYPES_H
#include <stdint.h>

typedef unsigned char boolean;
typedef uint8_t uint8;
typedef uint16_t uint16;
typedef uint32_t uint32;
typedef uint64_t uint64;
typedef int8_t sint8;
typedef int16_t sint16;
typedef int32_t sint32;
typedef int64_t sint64;
typedef float float32;
typedef double float64;
#ifndef TRUE
#define TRUE ((boolean)1)
#endif
#ifndef FALSE
#define FALSE ((boolean)0)
#endif
#endif
