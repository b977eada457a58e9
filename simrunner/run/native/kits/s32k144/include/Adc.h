/* Adc.h of the simulator's S32K144 kit: the RTD ADC driver's types and its software-triggered group
 * calls, for a team's own analog inputs (the board's potentiometer as a speed knob, a battery
 * sense). The linear camera's read-out is LinearCameraGetFrame's (linear_camera.h), not these.
 *
 * The names, types and signatures are the AUTOSAR SWS ADC Driver's as NXP's S32K1 RTD give them
 * (S32K1 RTD 1.0.0 / 2.0.0 Adc.h, Adc_Types.h, Adc_Ipw_Types.h: Adc_GroupType, Adc_ValueGroupType
 * and Adc_ChannelType uint16, Adc_HwUnitType uint8, Adc_StreamNumSampleType uint16, Adc_StatusType
 * ADC_IDLE / ADC_BUSY / ADC_COMPLETED / ADC_STREAM_COMPLETED, Adc_CalibrationStatusType's
 * AdcUnitSelfTestStatus; as published e.g. in github.com/gettobyte/GB_ElecronicsV_S32K144_Autosar_MCAL,
 * Freemaster_ADC/Potentiometer__Interfacing/.../RTD/include/Adc_Types.h), and as the NXP Cup sample's
 * DriversInit calls them (Adc_Init(NULL_PTR), Adc_Calibrate(0U, &CalibStatus), CalibStatus.
 * AdcUnitSelfTestStatus == E_OK: github.com/michalfrohlich/NXP-Cup-EXPO, src/main_functions.c at
 * commit 47d5179); the code is ours.
 *
 * On the simulated car (adc.c) a conversion completes at once: the S32K144's 12-bit SAR ADC converts
 * a channel in microseconds, well inside one simulated step. After Adc_StartGroupConversion the
 * group's status is ADC_STREAM_COMPLETED (a one-shot, software-triggered group of one sample: the
 * result buffer is full, AUTOSAR SWS_Adc_00325), so `while (Adc_GetGroupStatus(g) == ADC_BUSY) {}`
 * ends at once; Adc_ReadGroup copies the group's values and returns E_OK, the group then ADC_IDLE
 * (SWS_Adc_00330: a group that stops by itself); read again, it gives the same values. A group never
 * converted since Adc_Init reads E_NOT_OK (SWS_Adc_00388, ADC_E_IDLE: the RTD's Adc_ReadGroup).
 * Adc_SetupResultBuffer's buffer gets the values at each conversion (optional here: the RTD refuses
 * a start without it, ADC_E_BUFFER_UNINIT); Adc_GetStreamLastPointer points at them (1 sample).
 * A notification enabled for a group is called at once, before Adc_StartGroupConversion returns, as
 * if the conversion's interrupt came then: the function your generated configuration names for the
 * group, given as -D ADC_NOTIFICATION_<n>=NAME (groups 0..7; the kit cannot see your configuration).
 *
 * The values are --param s32k_adc_<n>=COUNTS for group n's first channel, s32k_adc_<n>_<i> for its
 * i-th (i = 0..15; the group's channels are those given), in the converter's counts: 0..4095 at 12
 * bits (--param s32k_adc_bits=8/10/12, the resolution your configuration gives, default 12). A group
 * converted with none given reads mid-scale (2048 at 12 bits) and the run lists a warning saying so.
 * The group's number is your configuration's name for it: -D AdcGroup_pot=1U, as for other
 * generated names (docs/firmware.md, "The S32K144 kit"). Not emulated: hardware-triggered groups
 * (Adc_EnableHardwareTrigger), streaming of several samples, values that change in time. */
#ifndef NXPCUP_SIM_ADC_H
#define NXPCUP_SIM_ADC_H
#include "Std_Types.h"
#ifdef __cplusplus
extern "C" {
#endif

typedef uint8 Adc_HwUnitType;
typedef uint16 Adc_ChannelType;
typedef uint16 Adc_GroupType;
typedef uint16 Adc_ValueGroupType;
typedef uint16 Adc_StreamNumSampleType;
typedef enum { ADC_IDLE = 0U, ADC_BUSY, ADC_COMPLETED, ADC_STREAM_COMPLETED } Adc_StatusType;
typedef void (*Adc_NotifyType)(void);
typedef struct {
    Std_ReturnType AdcUnitSelfTestStatus;  /* the calibration's result: E_OK here */
} Adc_CalibrationStatusType;
typedef struct Adc_ConfigType Adc_ConfigType;  /* the generated configuration: its content is the kit's */
extern const Adc_ConfigType Adc_Config_VS_0;   /* the generated configuration's names (Adc_VS_0_PBcfg.c) */
extern const Adc_ConfigType Adc_Config;

/* The S32K144's two converters, ADC0 and ADC1, as the generated configuration names its units. */
#ifndef AdcHwUnit_0
#define AdcHwUnit_0 ((Adc_HwUnitType)0U)
#endif
#ifndef AdcHwUnit_1
#define AdcHwUnit_1 ((Adc_HwUnitType)1U)
#endif

void Adc_Init(const Adc_ConfigType *ConfigPtr);
void Adc_DeInit(void);
void Adc_Calibrate(Adc_HwUnitType Unit, Adc_CalibrationStatusType *pStatus);
Std_ReturnType Adc_SetupResultBuffer(Adc_GroupType Group, const Adc_ValueGroupType *DataBufferPtr);
void Adc_StartGroupConversion(Adc_GroupType Group);
void Adc_StopGroupConversion(Adc_GroupType Group);
Std_ReturnType Adc_ReadGroup(Adc_GroupType Group, Adc_ValueGroupType *DataBufferPtr);
Adc_StatusType Adc_GetGroupStatus(Adc_GroupType Group);
Adc_StreamNumSampleType Adc_GetStreamLastPointer(Adc_GroupType Group, Adc_ValueGroupType **PtrToSamplePtr);
void Adc_EnableGroupNotification(Adc_GroupType Group);
void Adc_DisableGroupNotification(Adc_GroupType Group);
#ifdef __cplusplus
}
#endif
#endif
