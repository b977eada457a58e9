/* CDD_I2c.h of the simulator's S32K144 kit: the I2C address type display.h and pixy2.h name. */
#ifndef NXPCUP_SIM_CDD_I2C_H
#define NXPCUP_SIM_CDD_I2C_H
#include "Std_Types.h"
typedef uint8 I2c_AddressType;
#endif
