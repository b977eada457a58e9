/* Mcal.h of the simulator's S32K144 kit: the RTD's common header; here only the standard types. */
#ifndef NXPCUP_SIM_MCAL_H
#define NXPCUP_SIM_MCAL_H
#include "Std_Types.h"
#endif
