/* pixy2.h of the simulator's S32K144 kit: the kit's I2C Pixy2 driver's names, from
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 * Not emulated here: calling one stops the run with a message naming it (the simulator's
 * Pixy2 is the Pixy2 library's API: docs/pixy2.md). */
#ifndef PIXY2_H
#define PIXY2_H
#ifdef __cplusplus
extern "C" {
#endif
#include "main_types.h"
#include "CDD_I2c.h"

void Pixy2Init(I2c_AddressType PixyI2cAddress, uint8 PixyI2cChannel);
void Pixy2SetLed(uint8 Red, uint8 Green, uint8 Blue);
void Pixy2GetVectors(DetectedVectors *DetectedVectors);

#ifdef __cplusplus
}
#endif
#endif
