#ifndef TFC_CRYSTALCLOCK_H_
#define TFC_CRYSTALCLOCK_H_
#define CORE_CLOCK 48000000   /* the KL25Z's 48 MHz core */
#define PERIPHERAL_BUS_CLOCK (CORE_CLOCK / 2)
void InitClock(void);
#endif
