/* InterruptIn.h of the simulator's mbed kit (simrunner drive main.cpp --kit tfc-mbed; mbed.h
 * includes it): mbed's drivers/InterruptIn.h as mbed 2 and mbed OS 5/6 publish it (a function, an
 * object and its method, a Callback or a lambda for rise() and fall(); enable_irq, disable_irq,
 * mode, read), on the KL25Z's pins as ../interrupt_in.cpp maps them (docs/firmware.md, "The mbed
 * flavour"):
 *
 *     InterruptIn wheel(PTA13);          // --param encoder_PTA13=2: channel A of RL's encoder
 *     volatile int ticks;
 *     void tick() { ticks++; }
 *     wheel.rise(&tick);                 // once a rising edge, at the kit's tick it fell in
 *
 * - the handlers run as interrupts (no waits in them) at each tick of the kit's 1-kHz clock, once
 *   per edge of the millisecond gone, in the order the edges fell, before the Tickers due then;
 * - a pin bound to an encoder's channel by --param gives the channel's edges as the wheel turns;
 *   other pins keep their level and give none; ports A and D only (the KL25Z's). */
#ifndef INTERRUPTIN_H
#define INTERRUPTIN_H
#include "mbed.h"

namespace mbed {

class InterruptIn {
public:
    InterruptIn(PinName pin) { attach(pin); }
    InterruptIn(PinName pin, PinMode mode) { attach(pin), (void)mode; }
    virtual ~InterruptIn() { tfc_mbed_irq_detach(&irq_); }
    InterruptIn(const InterruptIn &) = delete;
    InterruptIn &operator=(const InterruptIn &) = delete;

    int read() { return tfc_mbed_irq_read(&irq_, "InterruptIn::read"); }
    operator int() { return read(); }
    /* a handler for rising (falling) edges; an empty one (NULL) stops them */
    void rise(Callback<void()> func) { rise_ = func; tfc_mbed_irq_set(&irq_, (bool)func, -1, "InterruptIn::rise"); }
    template <typename T, typename M> void rise(T *obj, M method) { rise(Callback<void()>(obj, method)); }
    void fall(Callback<void()> func) { fall_ = func; tfc_mbed_irq_set(&irq_, -1, (bool)func, "InterruptIn::fall"); }
    template <typename T, typename M> void fall(T *obj, M method) { fall(Callback<void()>(obj, method)); }
    void mode(PinMode pull) { (void)pull; }  /* the pin's level is the sensor's */
    /* the port's interrupt (every InterruptIn on port A, or on port D), as mbed's KL25Z code */
    void enable_irq() { tfc_mbed_irq_enable(&irq_, 1, "InterruptIn::enable_irq"); }
    void disable_irq() { tfc_mbed_irq_enable(&irq_, 0, "InterruptIn::disable_irq"); }

private:
    void attach(PinName pin) {
        tfc_mbed_irq_attach(&irq_, pin);
        irq_.call = [](void *self, int rising) {
            InterruptIn *in = static_cast<InterruptIn *>(self);
            (rising ? in->rise_ : in->fall_).call();
        };
        irq_.obj = this;
    }
    Callback<void()> rise_, fall_;
    tfc_mbed_irq irq_ = {};
};

}  // namespace mbed
#endif
