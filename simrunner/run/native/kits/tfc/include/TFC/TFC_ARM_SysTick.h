/* TFC_ARM_SysTick.h (simulator): TFC_Ticker[i] count milliseconds of simulated time, as the
 * SysTick interrupt makes them on the board. They move when the program calls the library
 * (TFC_Task in its main loop, TFC_Delay_mS) and when it polls the board: TFC_Ticker is reached
 * through a function (the macro below; `TFC_Ticker[0] = 0` and `extern volatile uint32_t
 * TFC_Ticker[NUM_TFC_TICKERS];` keep working), and a loop that only reads the tickers, the ready
 * flag, buttons, switches or pots (`while (TFC_Ticker[0] < 20);`) lets one physics step pass per
 * read once it has read them many times without calling the library (tfc.c, POLLS_BEFORE_TIME). */
#ifndef TFC_ARM_SYSTICK_H_
#define TFC_ARM_SYSTICK_H_
#include <stdint.h>
#define SYSTICK_FREQUENCY 1000
#include "TFC/TFC_Config.h"  /* NUM_TFC_TICKERS, where the library sets it */
/* the simulator's hook behind the tickers: a poll of them (see above) */
volatile uint32_t (*tfc_sim_tickers(void))[NUM_TFC_TICKERS];
#define TFC_Ticker (*tfc_sim_tickers())
void TFC_InitSysTick(void);
void TFC_Delay_mS(unsigned int TicksIn_mS);
#endif
