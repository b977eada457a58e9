/* Dio_Cfg.h: the RTD's generated DIO configuration; the kit's hbridge.h includes it for the types. */
#include "Dio.h"
