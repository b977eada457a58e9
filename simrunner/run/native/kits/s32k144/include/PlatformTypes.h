/* PlatformTypes.h: the spelling the NXP Cup kit's main_types.h and display.h include. */
#include "Platform_Types.h"
