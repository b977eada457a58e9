/* main_types.h of the simulator's S32K144 kit: the Pixy2 vector types of
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/). */
#ifndef MAIN_TYPES_H
#define MAIN_TYPES_H
#include "PlatformTypes.h"

typedef struct {
    uint16 x0, y0, x1, y1;
    uint8 VectorIndex;
} Vector;

typedef struct {
    uint8 NumberOfVectors;
    Vector Vectors[100];
} DetectedVectors;
#endif
