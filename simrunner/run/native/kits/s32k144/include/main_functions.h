/* main_functions.h of the simulator's S32K144 kit: DriversInit and the drivers' bench tests of
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * DriversInit (the RTD's clock, pin and driver set-up) does nothing on the simulated car. The
 * bench tests (ServoTest, HbridgeTest, LinearCameraTest, ...) loop for ever on the bench and
 * are not emulated: calling one stops the run with a message naming it. NormalizePixyVector is
 * declared, not defined (team code defines its own). */
#ifndef MAIN_FUNCTIONS_H
#define MAIN_FUNCTIONS_H
#ifdef __cplusplus
extern "C" {
#endif
#include "main_types.h"

void DriversInit(void);
Vector NormalizePixyVector(Vector PixyVector);
void DisplayTest(void);
void ReceiverTest(void);
void ServoTest(void);
void LinearCameraTest(void);
void Pixy2Test(void);
void HbridgeTest(void);
void EscTest(void);

#ifdef __cplusplus
}
#endif
#endif
