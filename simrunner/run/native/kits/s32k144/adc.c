/* The RTD's Adc groups on the simulated car (the simulator's S32K144 kit; include/Adc.h says what a
 * call does and whose API it is; docs/firmware.md, "The S32K144 kit").
 *
 * A group's values are --param s32k_adc_<n> (its first channel; also s32k_adc_<n>_0) and
 * s32k_adc_<n>_<i> (its i-th channel), looked up at the group's first conversion: the group has the
 * channels up to the last one given (one when none is), a channel not given reads mid-scale, and the
 * run lists a warning naming the params. A value that is not a whole number of counts within the
 * resolution's range (--param s32k_adc_bits, default 12: 0..4095) ends the run at the call that reads
 * it, on one line. A conversion completes at once (its status ADC_STREAM_COMPLETED, the values in the
 * group's result buffer if one was set up, the notification called if enabled), but after 64
 * conversions at one simulated time in main() each lets one physics step pass, as the kit's polls of
 * its input pins and Gpt counters do: a loop that only reads a knob moves on in time. */
#include <stdio.h>
#include <string.h>

#include "spinner.h"
#include "Adc.h"
#include "sim_poll.h"

#define NUM_GROUPS 256          /* groups 0..255 (the kit's limit; the RTD's is its configuration's) */
#define MAX_CHANNELS 16         /* channels a group may have (s32k_adc_<n>_0 .. _15) */

/* The kit's Adc configuration: group n's notification, -D ADC_NOTIFICATION_<n>=NAME (the function your
 * generated configuration names for it); none unless given. */
#define ADC_NOTIFIED 8
#define STR_(x) #x
#define STR(x) STR_(x)
#define DECLARE(fn) extern void fn(void) __attribute__((weak));
#ifdef ADC_NOTIFICATION_0
DECLARE(ADC_NOTIFICATION_0)
#define A0 ADC_NOTIFICATION_0, STR(ADC_NOTIFICATION_0)
#else
#define A0 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_1
DECLARE(ADC_NOTIFICATION_1)
#define A1 ADC_NOTIFICATION_1, STR(ADC_NOTIFICATION_1)
#else
#define A1 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_2
DECLARE(ADC_NOTIFICATION_2)
#define A2 ADC_NOTIFICATION_2, STR(ADC_NOTIFICATION_2)
#else
#define A2 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_3
DECLARE(ADC_NOTIFICATION_3)
#define A3 ADC_NOTIFICATION_3, STR(ADC_NOTIFICATION_3)
#else
#define A3 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_4
DECLARE(ADC_NOTIFICATION_4)
#define A4 ADC_NOTIFICATION_4, STR(ADC_NOTIFICATION_4)
#else
#define A4 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_5
DECLARE(ADC_NOTIFICATION_5)
#define A5 ADC_NOTIFICATION_5, STR(ADC_NOTIFICATION_5)
#else
#define A5 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_6
DECLARE(ADC_NOTIFICATION_6)
#define A6 ADC_NOTIFICATION_6, STR(ADC_NOTIFICATION_6)
#else
#define A6 NULL, NULL
#endif
#ifdef ADC_NOTIFICATION_7
DECLARE(ADC_NOTIFICATION_7)
#define A7 ADC_NOTIFICATION_7, STR(ADC_NOTIFICATION_7)
#else
#define A7 NULL, NULL
#endif

static const struct {
    void (*fn)(void);       /* the notification, NULL when the program defines none */
    const char *name;       /* its name in the configuration (NULL: none configured) */
} config[ADC_NOTIFIED] = {{A0}, {A1}, {A2}, {A3}, {A4}, {A5}, {A6}, {A7}};

/* The generated configuration's names: Adc_Init takes any (the kit's configuration is above). */
struct Adc_ConfigType { uint8 unused; };
const Adc_ConfigType Adc_Config_VS_0, Adc_Config;

#define NOT_GIVEN -1e300  /* spinner_param's default: the --param was not given */

static struct {
    int inited;
    unsigned full_scale;    /* 2^bits - 1 */
    SimPoll poll;           /* main()'s conversions at one time (sim_poll.h) */
    struct {
        uint8 looked_up;    /* its --params read */
        uint8 channels;     /* 1 .. MAX_CHANNELS */
        uint8 status;       /* Adc_StatusType */
        uint8 converted;    /* converted since Adc_Init (the RTD's AlreadyConverted) */
        uint8 notify;
        Adc_ValueGroupType value[MAX_CHANNELS];   /* the channels' counts (--param) */
        Adc_ValueGroupType result[MAX_CHANNELS];  /* the last conversion's */
        Adc_ValueGroupType *buffer;               /* Adc_SetupResultBuffer's */
    } g[NUM_GROUPS];
} a;

__attribute__((noreturn)) static void bad_param(const char *name, double value, const char *expected) {
    char text[400];
    snprintf(text, sizeof text, "--param %s=%g: expected %s (docs/firmware.md, \"The S32K144 kit\")", name, value,
             expected);
    spinner_fail(text);
}

static void init(void) {
    if (a.inited) return;
    a.inited = 1;
    double bits = spinner_param("s32k_adc_bits", 12.0);
    if (bits != 8.0 && bits != 10.0 && bits != 12.0)
        bad_param("s32k_adc_bits", bits, "8, 10 or 12: the resolution your Adc configuration gives the converter");
    a.full_scale = (1U << (unsigned)bits) - 1U;
}

/* Group n, checked: a group out of the kit's range ends the run at the call (the RTD: ADC_E_PARAM_GROUP). */
static int group(const char *call, Adc_GroupType n) {
    init();
    if (n >= NUM_GROUPS) {
        char text[300];
        snprintf(text, sizeof text, "%s(%u): the simulator's Adc has groups 0..%d (your configuration's group "
                 "names, given as -D AdcGroup_NAME=N)", call, (unsigned)n, NUM_GROUPS - 1);
        spinner_fail(text);
    }
    return n;
}

/* Group n's channel values from --param, at its first conversion (or read). */
static void look_up(int n) {
    if (a.g[n].looked_up) return;
    double v[MAX_CHANNELS];
    char names[MAX_CHANNELS][40], first[40];
    int last = -1;
    snprintf(first, sizeof first, "s32k_adc_%d", n);
    double plain = spinner_param(first, NOT_GIVEN);
    for (int i = 0; i < MAX_CHANNELS; i++) {
        snprintf(names[i], sizeof names[i], "s32k_adc_%d_%d", n, i);
        v[i] = spinner_param(names[i], NOT_GIVEN);
        if (i == 0 && plain != NOT_GIVEN) {
            if (v[0] != NOT_GIVEN) bad_param(names[0], v[0], "one of s32k_adc_N and s32k_adc_N_0 (both are the "
                                                              "group's first channel)");
            v[0] = plain;
            snprintf(names[0], sizeof names[0], "%s", first);
        }
        if (v[i] != NOT_GIVEN) last = i;
    }
    char expected[200];
    snprintf(expected, sizeof expected, "the channel's conversion result: a whole number of counts 0..%u (%s bits, "
             "--param s32k_adc_bits)", a.full_scale, a.full_scale == 4095U ? "12" : (a.full_scale == 1023U ? "10" : "8"));
    char missing[300] = "";
    size_t used = 0;
    int nmissing = 0;
    unsigned mid = (a.full_scale + 1U) / 2U;
    for (int i = 0; i <= (last < 0 ? 0 : last); i++) {
        if (v[i] == NOT_GIVEN) {
            a.g[n].value[i] = (Adc_ValueGroupType)mid;
            nmissing++;
            if (used < sizeof missing - 40)
                used += (size_t)snprintf(missing + used, sizeof missing - used, "%s%s", used ? ", " : "",
                                         i == 0 ? first : names[i]);
            continue;
        }
        if (!(v[i] >= 0.0 && v[i] <= a.full_scale && v[i] == (double)(long)v[i])) bad_param(names[i], v[i], expected);
        a.g[n].value[i] = (Adc_ValueGroupType)v[i];
    }
    a.g[n].channels = (uint8)(last < 0 ? 1 : last + 1);
    a.g[n].looked_up = 1U;
    if (used > 0) {
        char text[600];
        snprintf(text, sizeof text, "Adc group %d: no value given for --param %s: %s mid-scale, %u counts; give "
                 "%s (docs/firmware.md, \"The S32K144 kit\")", n, missing, nmissing > 1 ? "those channels read" :
                 "the channel reads", mid, nmissing > 1 ? "each channel's counts as --param NAME=COUNTS" :
                 "its counts as --param NAME=COUNTS");
        spinner_warn(text);
    }
}

void Adc_Init(const Adc_ConfigType *ConfigPtr) {
    (void)ConfigPtr;
    init();
    for (int n = 0; n < NUM_GROUPS; n++) {
        a.g[n].status = ADC_IDLE, a.g[n].converted = 0U, a.g[n].notify = 0U, a.g[n].buffer = NULL;
    }
}

void Adc_DeInit(void) {
    init();
    for (int n = 0; n < NUM_GROUPS; n++) a.g[n].status = ADC_IDLE, a.g[n].notify = 0U;
}

/* The converter's self-calibration: nothing to calibrate on the simulated car; it succeeds. */
void Adc_Calibrate(Adc_HwUnitType Unit, Adc_CalibrationStatusType *pStatus) {
    (void)Unit;
    init();
    if (pStatus != NULL) pStatus->AdcUnitSelfTestStatus = E_OK;
}

Std_ReturnType Adc_SetupResultBuffer(Adc_GroupType Group, const Adc_ValueGroupType *DataBufferPtr) {
    int n = group("Adc_SetupResultBuffer", Group);
    a.g[n].buffer = (Adc_ValueGroupType *)DataBufferPtr;
    return E_OK;
}

/* Main's conversions at one simulated time: after SIM_POLLS_FREE each lets one physics step pass
 * (a handler's leave main's count as it is). */
static void poll_time(void) {
    if (!spinner_in_interrupt()) (void)sim_poll_time(&a.poll);
}

void Adc_StartGroupConversion(Adc_GroupType Group) {
    int n = group("Adc_StartGroupConversion", Group);
    look_up(n);
    poll_time();
    memcpy(a.g[n].result, a.g[n].value, sizeof a.g[n].result);
    if (a.g[n].buffer != NULL) memcpy(a.g[n].buffer, a.g[n].value, a.g[n].channels * sizeof(Adc_ValueGroupType));
    a.g[n].status = ADC_STREAM_COMPLETED;
    a.g[n].converted = 1U;
    if (a.g[n].notify && n < ADC_NOTIFIED && config[n].fn != NULL) config[n].fn();  /* the conversion's end */
}

void Adc_StopGroupConversion(Adc_GroupType Group) {
    int n = group("Adc_StopGroupConversion", Group);
    a.g[n].status = ADC_IDLE;
}

/* A read of a completed group: it is then idle (a one-shot group stops by itself: SWS_Adc_00330). */
static void read_done(int n) {
    if (a.g[n].status == ADC_STREAM_COMPLETED || a.g[n].status == ADC_COMPLETED) a.g[n].status = ADC_IDLE;
}

Std_ReturnType Adc_ReadGroup(Adc_GroupType Group, Adc_ValueGroupType *DataBufferPtr) {
    int n = group("Adc_ReadGroup", Group);
    if (a.g[n].status == ADC_IDLE && !a.g[n].converted) return E_NOT_OK;  /* SWS_Adc_00388 (ADC_E_IDLE) */
    if (DataBufferPtr == NULL) return E_NOT_OK;                             /* ADC_E_PARAM_POINTER */
    memcpy(DataBufferPtr, a.g[n].result, a.g[n].channels * sizeof(Adc_ValueGroupType));
    read_done(n);
    return E_OK;
}

Adc_StatusType Adc_GetGroupStatus(Adc_GroupType Group) {
    int n = group("Adc_GetGroupStatus", Group);
    return (Adc_StatusType)a.g[n].status;
}

/* The group's last sample: 1 per channel (a group of one sample), in its result buffer (the kit's copy
 * when none was set up); none (0, NULL) for a group never converted (the RTD: ADC_E_IDLE). */
Adc_StreamNumSampleType Adc_GetStreamLastPointer(Adc_GroupType Group, Adc_ValueGroupType **PtrToSamplePtr) {
    int n = group("Adc_GetStreamLastPointer", Group);
    if (a.g[n].status == ADC_IDLE && !a.g[n].converted) {
        if (PtrToSamplePtr != NULL) *PtrToSamplePtr = NULL;
        return 0U;
    }
    if (PtrToSamplePtr != NULL) *PtrToSamplePtr = a.g[n].buffer != NULL ? a.g[n].buffer : a.g[n].result;
    read_done(n);
    return 1U;
}

void Adc_EnableGroupNotification(Adc_GroupType Group) {
    int n = group("Adc_EnableGroupNotification", Group);
    const char *name = n < ADC_NOTIFIED ? config[n].name : NULL;
    if (n >= ADC_NOTIFIED || config[n].fn == NULL) {  /* the RTD: ADC_E_NOTIF_CAPABILITY */
        char text[500];
        if (name != NULL)
            snprintf(text, sizeof text, "Adc_EnableGroupNotification: group %d's notification %s (-D "
                     "ADC_NOTIFICATION_%d) is not a function of the program", n, name, n);
        else
            snprintf(text, sizeof text, "Adc_EnableGroupNotification: group %d has no notification in the kit's Adc "
                     "configuration; name yours as your generated configuration does, -D ADC_NOTIFICATION_%d=NAME "
                     "(groups 0..%d) (docs/firmware.md, \"The S32K144 kit\")", n, n, ADC_NOTIFIED - 1);
        spinner_fail(text);
    }
    a.g[n].notify = 1U;
}

void Adc_DisableGroupNotification(Adc_GroupType Group) {
    int n = group("Adc_DisableGroupNotification", Group);
    a.g[n].notify = 0U;
}
