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
 * - a pin bound to an encoder's channel by --param (encoder_PTxN, encoder_b_PTxN, and encoder_z_PTxN
 *   for the index: high one count a revolution) gives the channel's edges as the wheel turns;
 *   other pins keep their level and give none; ports A and D only (the KL25Z's);
 * - mbed 2's chains of handlers, which old FRDM-TFC programs use (the mbed library's
 *   libraries/mbed/api/InterruptIn.h and common/InterruptIn.cpp, 2013-2016, github.com/ARMmbed/mbed-os
 *   history; mbed OS 5.1 dropped them for one Callback): rise_add(fn) / rise_add(&obj,
 *   &Class::method) append a handler to the rising edges' CallChain (mbed.h), rise_add_front puts
 *   it first, each returning the pFunctionPointer_t (FunctionPointer *) it made; rise_remove(pf)
 *   takes it out (true if it was there; the last one out stops the edges' interrupt); rise(fn)
 *   replaces the whole chain with fn (NULL: empty) and returns its pFunctionPointer_t (NULL for
 *   NULL); rise_add(NULL) adds nothing and returns NULL; an edge calls the chain's handlers in
 *   order (one a handler adds, or rise(fn) in a handler, from the next edge). fall_add, fall_add_front, fall_remove and fall likewise. */
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
    /* the handler of rising (falling) edges, in place of any; an empty one (NULL) stops them */
    pFunctionPointer_t rise(Callback<void()> func) { return set(rise_, func, 1, "InterruptIn::rise"); }
    template <typename T, typename M> pFunctionPointer_t rise(T *obj, M method) { return rise(Callback<void()>(obj, method)); }
    pFunctionPointer_t fall(Callback<void()> func) { return set(fall_, func, 0, "InterruptIn::fall"); }
    template <typename T, typename M> pFunctionPointer_t fall(T *obj, M method) { return fall(Callback<void()>(obj, method)); }
    /* mbed 2: one more handler, last (first) of the edge's chain; take it out with *_remove */
    pFunctionPointer_t rise_add(Callback<void()> func) { return add(rise_, func, 0, 1, "InterruptIn::rise_add"); }
    template <typename T, typename M> pFunctionPointer_t rise_add(T *obj, M method) { return rise_add(Callback<void()>(obj, method)); }
    pFunctionPointer_t rise_add_front(Callback<void()> func) { return add(rise_, func, 1, 1, "InterruptIn::rise_add_front"); }
    template <typename T, typename M> pFunctionPointer_t rise_add_front(T *obj, M method) { return rise_add_front(Callback<void()>(obj, method)); }
    bool rise_remove(pFunctionPointer_t pf) { return remove(rise_, pf, 1, "InterruptIn::rise_remove"); }
    pFunctionPointer_t fall_add(Callback<void()> func) { return add(fall_, func, 0, 0, "InterruptIn::fall_add"); }
    template <typename T, typename M> pFunctionPointer_t fall_add(T *obj, M method) { return fall_add(Callback<void()>(obj, method)); }
    pFunctionPointer_t fall_add_front(Callback<void()> func) { return add(fall_, func, 1, 0, "InterruptIn::fall_add_front"); }
    template <typename T, typename M> pFunctionPointer_t fall_add_front(T *obj, M method) { return fall_add_front(Callback<void()>(obj, method)); }
    bool fall_remove(pFunctionPointer_t pf) { return remove(fall_, pf, 0, "InterruptIn::fall_remove"); }
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
    /* the edge's interrupt on (1) or off (0), as mbed's gpio_irq_set(IRQ_RISE / IRQ_FALL) */
    void irq(int rising, int on, const char *what) { tfc_mbed_irq_set(&irq_, rising ? on : -1, rising ? -1 : on, what); }
    pFunctionPointer_t set(CallChain &chain, Callback<void()> func, int rising, const char *what) {
        chain.clear();
        pFunctionPointer_t pf = func ? chain.add(func) : nullptr;
        irq(rising, pf != nullptr, what);
        return pf;
    }
    pFunctionPointer_t add(CallChain &chain, Callback<void()> func, int front, int rising, const char *what) {
        if (!func) return nullptr;
        pFunctionPointer_t pf = front ? chain.add_front(func) : chain.add(func);
        irq(rising, 1, what);
        return pf;
    }
    bool remove(CallChain &chain, pFunctionPointer_t pf, int rising, const char *what) {
        bool removed = chain.remove(pf);
        if (removed && chain.size() == 0) irq(rising, 0, what);
        return removed;
    }
    CallChain rise_, fall_;
    tfc_mbed_irq irq_ = {};
};

}  // namespace mbed
#endif
