/* CDD_I2c.h of the simulator's S32K144 kit: the I2C types display.h and pixy2.h name (RTD
 * CDD_I2c_Types.h: I2c_AddressType, I2c_DataType). The I2C driver's calls are not emulated. */
#ifndef NXPCUP_SIM_CDD_I2C_H
#define NXPCUP_SIM_CDD_I2C_H
#include "Std_Types.h"
typedef uint8 I2c_AddressType;
typedef uint8 I2c_DataType;
#endif
