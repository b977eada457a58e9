/* sim_poll.h: the S32K144 kit's own (not a header of the board's): the rule its reads follow when
 * main() polls them (Gpt counts, input pins, Adc conversions). A read lets no simulated time pass
 * (with --mcu-time, main()'s read is charged: spinner_now), but after SIM_POLLS_FREE reads at one
 * simulated time each further one lets one physics step pass, so a loop that only polls ends (on the
 * board the hardware or a person moves meanwhile), as the TFC kit's polls of its board. In an
 * interrupt handler no time passes (the count starts again). */
#ifndef NXPCUP_SIM_S32K_POLL_H
#define NXPCUP_SIM_S32K_POLL_H
#include "spinner.h"

#define SIM_POLLS_FREE 64

typedef struct {
    double at_s;  /* the simulated time of the last read, and the reads at it */
    long polls;
} SimPoll;

/* The simulated time a read sees (spinner_now, or after a physics step: spinner_get_time). */
static inline double sim_poll_time(SimPoll *p) {
    double now = spinner_now();
    if (spinner_in_interrupt() || now != p->at_s) {
        p->at_s = now, p->polls = 0;
        return now;
    }
    if (++p->polls <= SIM_POLLS_FREE) return now;
    return p->at_s = spinner_get_time();
}
#endif
