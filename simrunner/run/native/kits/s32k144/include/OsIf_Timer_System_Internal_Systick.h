/* OsIf_Timer_System_Internal_Systick.h: the RTD's SysTick back end of OsIf's system counter;
 * here the counters of OsIf.h (simulated time). */
#include "OsIf.h"
