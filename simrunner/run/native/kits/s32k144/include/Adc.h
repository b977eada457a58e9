/* Adc.h of the simulator's S32K144 kit: the ADC types the linear camera driver's header names.
 * The camera's ADC read-out itself is LinearCameraGetFrame's (linear_camera.h); the ADC
 * driver's calls are not emulated. */
#ifndef NXPCUP_SIM_ADC_H
#define NXPCUP_SIM_ADC_H
#include "Std_Types.h"
typedef uint16 Adc_GroupType;
typedef uint16 Adc_ValueGroupType;
#endif
