/* display.h of the simulator's S32K144 kit: the NXP Cup S32K144 kit's driver of the 128x32
 * SSD1306 OLED (4 lines of 16 characters), the same names and signatures as in
 * NXP's "Nxp_Cup_Linear_Camera_S32K144" sample (S32 Design Studio, RTD), as published in
 * github.com/michalfrohlich/NXP-Cup-EXPO (include/, src/ at commit 47d5179) and
 * github.com/DTGApexRobotics/NXPCUP2025-MCQUEEN (include/), documented in NXP's NXP Cup guide
 * (github.com/NXPHoverGames/GitBook-NXPCup, 2024-fall-2025-nxp-cup-bare-metal-drivers/).
 *
 * On the simulated car the display is the debug video's text column: DisplayText and
 * DisplayValue write into the 4 x 16 character buffer as the driver does (a value left-aligned
 * in its TextLength, blanks after; a text's TextLength characters, blank past its end), DisplayGraph keeps the values it would
 * draw (0 .. 100), DisplayClear empties both, and DisplayRefresh shows the buffer's lines and
 * the graph (as a processed image line) in the video (when one is written; no I2C time
 * passes). DisplayVector and RotateFontmap do nothing.
 *
 * DisplayInit is declared without a prototype (in C++: a defaulted second argument): the sample's first version takes
 * (FontmapRotation), its later one (I2cChannel, FontmapRotation); both calls build. */
#ifndef DISPLAY_H
#define DISPLAY_H
#ifdef __cplusplus
extern "C" {
#endif
#include "PlatformTypes.h"
#include "main_types.h"
#include "CDD_I2c.h"

#define CharacterColumns 16U
#define CharacterRows 4U

void DisplayRefresh(void);
/* the sample spells Text "const char Text[16]": the same type (a pointer), without the
 * compiler's warning for shorter strings */
void DisplayText(uint16 DisplayLine, const char *Text, uint16 TextLength, uint16 TextOffset);
void DisplayValue(uint16 DisplayLine, int Value, uint16 TextLength, uint16 TextOffset);
void DisplayGraph(uint8 DisplayLine, uint8 Values[128], uint16 ValuesCount, uint8 LinesSpan);
void DisplayVector(Vector VectorCoordinates);
void DisplayClear(void);
void RotateFontmap(void);
#ifdef __cplusplus
/* C++ has no declaration without a prototype (DisplayInit() is DisplayInit(void) there): both
 * versions' calls, DisplayInit(FontmapRotation) and DisplayInit(I2cChannel, FontmapRotation),
 * build against a second argument's default (the kit reads neither) */
void DisplayInit(uint8 I2cChannel, uint8 FontmapRotation = 0U);
#else
void DisplayInit();
#endif

#ifdef __cplusplus
}
#endif
#endif
