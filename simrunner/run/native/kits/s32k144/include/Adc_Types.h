/* Adc_Types.h of the simulator's S32K144 kit: the RTD's Adc types header (S32K1 RTD Adc_Types.h,
 * which the NXP Cup sample's linear_camera.c includes); the kit's types and calls are Adc.h's. */
#ifndef NXPCUP_SIM_ADC_TYPES_H
#define NXPCUP_SIM_ADC_TYPES_H
#include "Adc.h"
#endif
