/* TFC_ARM_SysTick.h (simulator): TFC_Ticker[i] count milliseconds of simulated time, as the
 * SysTick interrupt makes them on the board; they move when the program calls the library
 * (TFC_Task in its main loop, TFC_Delay_mS): a loop that only reads them waits forever here
 * (the run then stops as stalled, naming the loop's line). */
#ifndef TFC_ARM_SYSTICK_H_
#define TFC_ARM_SYSTICK_H_
#include <stdint.h>
#define SYSTICK_FREQUENCY 1000
#define NUM_TFC_TICKERS 4
extern volatile uint32_t TFC_Ticker[NUM_TFC_TICKERS];
void TFC_InitSysTick(void);
void TFC_Delay_mS(unsigned int TicksIn_mS);
#endif
