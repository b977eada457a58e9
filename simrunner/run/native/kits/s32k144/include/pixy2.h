/* pixy2.h of the simulator's S32K144 kit: the kit's I2C Pixy2 driver, the same names and
 * signatures as in NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), in its
 * two published versions:
 * - Pixy2Init, Pixy2SetLed, Pixy2GetVectors(&vectors): github.com/michalfrohlich/NXP-Cup-EXPO
 *   (include/pixy2.h, src/pixy2.c at commit 47d5179), the NXP Cup guide's version
 *   (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/);
 * - the earlier PixySetLed and `DetectedVectors PixyGetVectors()`:
 *   github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (src/pixy2.c at commit d653b16).
 *
 * The driver sends the Pixy2 line-tracking request "all features, vectors only" (bytes 174 193
 * 48 2 1 1: getAllFeatures(LINE_VECTOR)), reads the reply into the global
 * PixyReceivedLinesBuffer (100 bytes; 50 in the earlier version) and copies each vector's x0, y0,
 * x1, y1 (the 79 x 52 line grid, 0,0 = top left) and index into DetectedVectors.
 *
 * On the simulated car the Pixy2 is the simulator's (docs/pixy2.md; the car file needs a Pixy2
 * camera, e.g. examples/pixy2_car.toml, else Pixy2Init ends the run saying so). A
 * Pixy2GetVectors returns the frame not returned yet, else waits for the next one (60 a second
 * on examples/pixy2_car.toml; the real driver would read a "busy" reply instead), and writes the
 * Pixy2's reply packet (sync 175 193, type 49, length, checksum, the vector feature) into
 * PixyReceivedLinesBuffer as the I2C read would. A reply holds at most the vectors that fit in
 * the driver's receive length: 15 (7 in the earlier version). The LED is accepted and not
 * simulated; Pixy2Test is not emulated (a bench loop). */
#ifndef PIXY2_H
#define PIXY2_H
#ifdef __cplusplus
extern "C" {
#endif
#include "main_types.h"
#include "CDD_I2c.h"

typedef struct {
    I2c_AddressType I2cAddress;
    uint8 I2cChannel;
} Pixy2;

extern I2c_DataType PixyReceivedLinesBuffer[100U];

void Pixy2Init(I2c_AddressType PixyI2cAddress, uint8 PixyI2cChannel);
void Pixy2SetLed(uint8 Red, uint8 Green, uint8 Blue);
void Pixy2GetVectors(DetectedVectors *DetectedVectors);
/* the earlier version's names */
void PixySetLed(uint8 Red, uint8 Green, uint8 Blue);
DetectedVectors PixyGetVectors(void);

#ifdef __cplusplus
}
#endif
#endif
