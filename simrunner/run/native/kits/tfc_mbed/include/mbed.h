/* mbed.h of the simulator's mbed FRDM-TFC kit (simrunner drive main.cpp --kit tfc-mbed): the
 * part of the mbed 2 / mbed OS 5 C++ API that FRDM-KL25Z + FRDM-TFC programs use, with mbed's
 * names and signatures (the drivers' headers, platform/Callback.h, the KL25Z target's PinNames.h),
 * implemented on the simulated car (../tfc_mbed.cpp; docs/firmware.md, "The mbed flavour"):
 * - wait(s), wait_ms, wait_us, sleep(), __WFI(): simulated time passes (a physics step at least);
 * - Timer, us_ticker_read(): simulated time; Ticker, Timeout: handlers run by simulated time, as
 *   interrupts inside main()'s waits (not inside a handler: a wait there ends the run);
 * - Serial/RawSerial: output to the program's standard output; input is not emulated (getc ends
 *   the run naming the line, readable() is 0);
 * - DigitalOut, DigitalIn, BusOut, BusIn, PwmOut, AnalogIn, AnalogOut: the FRDM-TFC's pins act on
 *   the car (PTE21 the H-bridge enable, PTB8..11 the LEDs, PTC13/PTC17 the buttons, PTE2..5 the
 *   DIP switch, PTB2/PTB3 the pots, PTE29 the battery sense, a servo pulse on PTB0 steers); a pin
 *   --param encoder_PTxN=W (encoder_b_PTxN=W, encoder_z_PTxN=W) gives wheel W's encoder reads its
 *   channel A (B, the index Z);
 *   other outputs keep what is written, other inputs read --param digital_PTxN / analog_PTxN;
 * - InterruptIn (InterruptIn.h): rise()/fall() handlers run as interrupts at the kit's 1-kHz ticks
 *   for the edges of the millisecond gone: an encoder's channel on a pin as above; other pins keep
 *   their level (no edges); ports A and D only, as the KL25Z; mbed 2's chains of handlers
 *   (rise_add, rise_add_front, rise_remove; CallChain, pFunctionPointer_t) too.
 * What is not here (I2C, SPI, CAN, threads, the MCU's registers) does not compile. */
#ifndef MBED_H
#define MBED_H
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <type_traits>
#include "tfc_mbed_sim.h"

#define MBED_LIBRARY_VERSION 161

/* The KL25Z's pins: PinName values as the target's PinNames.h (port << 12 | pin << 2). */
typedef enum {
    PTA0 = 0x0, PTA1 = 0x4, PTA2 = 0x8, PTA3 = 0xc, PTA4 = 0x10, PTA5 = 0x14, PTA6 = 0x18, PTA7 = 0x1c,
    PTA8 = 0x20, PTA9 = 0x24, PTA10 = 0x28, PTA11 = 0x2c, PTA12 = 0x30, PTA13 = 0x34, PTA14 = 0x38, PTA15 = 0x3c,
    PTA16 = 0x40, PTA17 = 0x44, PTA18 = 0x48, PTA19 = 0x4c, PTA20 = 0x50, PTA21 = 0x54, PTA22 = 0x58, PTA23 = 0x5c,
    PTA24 = 0x60, PTA25 = 0x64, PTA26 = 0x68, PTA27 = 0x6c, PTA28 = 0x70, PTA29 = 0x74, PTA30 = 0x78, PTA31 = 0x7c,
    PTB0 = 0x1000, PTB1 = 0x1004, PTB2 = 0x1008, PTB3 = 0x100c, PTB4 = 0x1010, PTB5 = 0x1014, PTB6 = 0x1018, PTB7 = 0x101c,
    PTB8 = 0x1020, PTB9 = 0x1024, PTB10 = 0x1028, PTB11 = 0x102c, PTB12 = 0x1030, PTB13 = 0x1034, PTB14 = 0x1038, PTB15 = 0x103c,
    PTB16 = 0x1040, PTB17 = 0x1044, PTB18 = 0x1048, PTB19 = 0x104c, PTB20 = 0x1050, PTB21 = 0x1054, PTB22 = 0x1058, PTB23 = 0x105c,
    PTB24 = 0x1060, PTB25 = 0x1064, PTB26 = 0x1068, PTB27 = 0x106c, PTB28 = 0x1070, PTB29 = 0x1074, PTB30 = 0x1078, PTB31 = 0x107c,
    PTC0 = 0x2000, PTC1 = 0x2004, PTC2 = 0x2008, PTC3 = 0x200c, PTC4 = 0x2010, PTC5 = 0x2014, PTC6 = 0x2018, PTC7 = 0x201c,
    PTC8 = 0x2020, PTC9 = 0x2024, PTC10 = 0x2028, PTC11 = 0x202c, PTC12 = 0x2030, PTC13 = 0x2034, PTC14 = 0x2038, PTC15 = 0x203c,
    PTC16 = 0x2040, PTC17 = 0x2044, PTC18 = 0x2048, PTC19 = 0x204c, PTC20 = 0x2050, PTC21 = 0x2054, PTC22 = 0x2058, PTC23 = 0x205c,
    PTC24 = 0x2060, PTC25 = 0x2064, PTC26 = 0x2068, PTC27 = 0x206c, PTC28 = 0x2070, PTC29 = 0x2074, PTC30 = 0x2078, PTC31 = 0x207c,
    PTD0 = 0x3000, PTD1 = 0x3004, PTD2 = 0x3008, PTD3 = 0x300c, PTD4 = 0x3010, PTD5 = 0x3014, PTD6 = 0x3018, PTD7 = 0x301c,
    PTD8 = 0x3020, PTD9 = 0x3024, PTD10 = 0x3028, PTD11 = 0x302c, PTD12 = 0x3030, PTD13 = 0x3034, PTD14 = 0x3038, PTD15 = 0x303c,
    PTD16 = 0x3040, PTD17 = 0x3044, PTD18 = 0x3048, PTD19 = 0x304c, PTD20 = 0x3050, PTD21 = 0x3054, PTD22 = 0x3058, PTD23 = 0x305c,
    PTD24 = 0x3060, PTD25 = 0x3064, PTD26 = 0x3068, PTD27 = 0x306c, PTD28 = 0x3070, PTD29 = 0x3074, PTD30 = 0x3078, PTD31 = 0x307c,
    PTE0 = 0x4000, PTE1 = 0x4004, PTE2 = 0x4008, PTE3 = 0x400c, PTE4 = 0x4010, PTE5 = 0x4014, PTE6 = 0x4018, PTE7 = 0x401c,
    PTE8 = 0x4020, PTE9 = 0x4024, PTE10 = 0x4028, PTE11 = 0x402c, PTE12 = 0x4030, PTE13 = 0x4034, PTE14 = 0x4038, PTE15 = 0x403c,
    PTE16 = 0x4040, PTE17 = 0x4044, PTE18 = 0x4048, PTE19 = 0x404c, PTE20 = 0x4050, PTE21 = 0x4054, PTE22 = 0x4058, PTE23 = 0x405c,
    PTE24 = 0x4060, PTE25 = 0x4064, PTE26 = 0x4068, PTE27 = 0x406c, PTE28 = 0x4070, PTE29 = 0x4074, PTE30 = 0x4078, PTE31 = 0x407c,
    LED_RED = PTB18, LED_GREEN = PTB19, LED_BLUE = PTD1,
    LED1 = LED_RED, LED2 = LED_GREEN, LED3 = LED_BLUE, LED4 = LED_BLUE,
    USBTX = PTA2, USBRX = PTA1,
    D0 = PTA1, D1 = PTA2, D2 = PTD4, D3 = PTA12, D4 = PTA4, D5 = PTA5, D6 = PTC8, D7 = PTC9,
    D8 = PTA13, D9 = PTD5, D10 = PTD0, D11 = PTD2, D12 = PTD3, D13 = PTD1, D14 = PTE0, D15 = PTE1,
    A0 = PTB0, A1 = PTB1, A2 = PTB2, A3 = PTB3, A4 = PTC2, A5 = PTC1,
    I2C_SCL = D15, I2C_SDA = D14, TSI_ELEC0 = PTB16, TSI_ELEC1 = PTB17,
    NC = (int)0xFFFFFFFF
} PinName;
typedef enum { PullNone = 0, PullUp = 2, PullDefault = PullUp } PinMode;

/* time: mbed's wait_api.h and us_ticker_api.h */
inline void wait(float s) { tfc_mbed_wait_s(s, "wait"); }
inline void wait_ms(int ms) { tfc_mbed_wait_s(ms * 1e-3, "wait_ms"); }
inline void wait_us(int us) { tfc_mbed_wait_s(us * 1e-6, "wait_us"); }
inline uint32_t us_ticker_read() { tfc_mbed_poll(); return (uint32_t)(uint64_t)(tfc_mbed_now_s() * 1e6); }
inline void sleep() { tfc_mbed_idle(); }   /* mbed's sleep(): until the next interrupt */
inline void deepsleep() { tfc_mbed_idle(); }
#define __WFI() tfc_mbed_idle()
/* The interrupt mask (the CMSIS intrinsics on PRIMASK): while disabled, the kit's 1-kHz interrupt (the
 * camera read-out, Tickers, Timeouts, InterruptIn edges) and --isr handlers are held pending and run
 * once at the enable (docs/firmware.md, "Critical sections"); mbed's critical sections
 * (mbed_critical.h) nest on it: the outermost exit enables them again if the enter found them
 * enabled. */
#define __enable_irq() spinner_enable_interrupts()
#define __disable_irq() spinner_disable_interrupts()
#define __get_PRIMASK() ((uint32_t)tfc_mbed_irq_masked())
#define __set_PRIMASK(primask) tfc_mbed_irq_mask((int)((primask) & 1u))
inline void core_util_critical_section_enter() { tfc_mbed_critical_enter(); }
inline void core_util_critical_section_exit() { tfc_mbed_critical_exit(); }
inline bool core_util_are_interrupts_enabled() { return !tfc_mbed_irq_masked(); }
inline bool core_util_in_critical_section() { return tfc_mbed_in_critical() != 0; }

namespace mbed {

/* platform/Callback.h: a function, an object and its method, a function and its argument, or a
 * function object (a lambda) of up to two pointers' size (mbed OS 5 takes one pointer's), taking
 * nothing. */
template <typename F> class Callback;
template <> class Callback<void()> {
public:
    Callback() {}
    Callback(void (*fn)()) : fn_(fn) {}
    template <typename T> Callback(T *obj, void (T::*method)()) { bind(obj, method); }
    template <typename T> Callback(void (T::*method)(), T *obj) { bind(obj, method); }
    template <typename T> Callback(void (*func)(T *), T *arg) {
        obj_ = arg;
        memcpy(method_, &func, sizeof func);
        thunk_ = [](const Callback *c) {
            void (*f)(T *);
            memcpy(&f, c->method_, sizeof f);
            f(static_cast<T *>(c->obj_));
        };
    }
    template <typename F, typename = decltype(&F::operator())> Callback(F f) {
        static_assert(sizeof(F) <= sizeof method_ && std::is_trivially_copyable<F>::value,
                      "a Callback holds a function object (a lambda) of up to two pointers' captures");
        memcpy(method_, &f, sizeof f);
        thunk_ = [](const Callback *c) { (*reinterpret_cast<F *>(const_cast<unsigned char *>(c->method_)))(); };
    }
    void call() const { if (thunk_) thunk_(this); else if (fn_) fn_(); }
    void operator()() const { call(); }
    explicit operator bool() const { return thunk_ || fn_; }
private:
    template <typename T> void bind(T *obj, void (T::*method)()) {
        static_assert(sizeof method <= sizeof method_, "method pointer size");
        obj_ = obj;
        memcpy(method_, &method, sizeof method);
        thunk_ = [](const Callback *c) {
            void (T::*m)();
            memcpy(&m, c->method_, sizeof m);
            (static_cast<T *>(c->obj_)->*m)();
        };
    }
    void (*fn_)() = nullptr;
    void *obj_ = nullptr;
    alignas(void *) unsigned char method_[2 * sizeof(void *)] = {};
    void (*thunk_)(const Callback *) = nullptr;
};
inline Callback<void()> callback(void (*fn)()) { return Callback<void()>(fn); }
template <typename T> Callback<void()> callback(T *obj, void (T::*method)()) { return Callback<void()>(obj, method); }
template <typename T> Callback<void()> callback(void (T::*method)(), T *obj) { return Callback<void()>(obj, method); }
template <typename T> Callback<void()> callback(void (*func)(T *), T *arg) { return Callback<void()>(func, arg); }
template <typename F, typename = decltype(&F::operator())> Callback<void()> callback(F f) { return Callback<void()>(f); }
typedef Callback<void()> FunctionPointer;

/* mbed 2's CallChain (libraries/mbed/api/CallChain.h, common/CallChain.cpp of the mbed library,
 * github.com/ARMmbed/mbed-os history; deprecated in mbed OS 5 and removed in 6): functions called
 * in order by call(); add() appends one, add_front() puts it first, each returning the
 * FunctionPointer it made (pFunctionPointer_t), which remove() takes out and frees (false when it
 * is not in the chain) and get(i) / [i] return. One of the chain's functions may remove or add
 * functions, or delete the chain's owner: the others still run that call, none twice (mbed 2's
 * array would skip the one after a removed one); one added during a call waits for the next (so
 * InterruptIn::rise(fn) in a handler, which replaces the chain, does not call fn for the edge
 * being handled, as in mbed OS 5/6 and mbed 2). */
typedef FunctionPointer *pFunctionPointer_t;
class CallChain {
public:
    CallChain(int size = 4) { (void)size; }
    ~CallChain() {
        if (alive_) *alive_ = false;  /* deleted by one of its functions: call() stops */
        alive_ = nullptr;
        clear();
        free(chain_);
    }
    CallChain(const CallChain &) = delete;
    CallChain &operator=(const CallChain &) = delete;
    pFunctionPointer_t add(Callback<void()> func) { return insert(n_, func); }
    template <typename T, typename M> pFunctionPointer_t add(T *obj, M method) { return add(Callback<void()>(obj, method)); }
    pFunctionPointer_t add_front(Callback<void()> func) { return insert(0, func); }
    template <typename T, typename M> pFunctionPointer_t add_front(T *obj, M method) { return add_front(Callback<void()>(obj, method)); }
    int size() const { return n_; }
    pFunctionPointer_t get(int i) const { return i < 0 || i >= n_ ? nullptr : chain_[i]; }
    int find(pFunctionPointer_t f) const {
        for (int i = 0; i < n_; i++) if (chain_[i] == f) return i;
        return -1;
    }
    void clear() { while (n_) take(n_ - 1); }
    bool remove(pFunctionPointer_t f) {
        int i = find(f);
        if (i < 0) return false;
        take(i);
        return true;
    }
    void call() {
        bool alive = true, *outer = alive_;
        int outer_at = at_, outer_end = end_;
        alive_ = &alive;
        for (at_ = 0, end_ = n_; at_ < end_; at_++) {
            FunctionPointer f = *chain_[at_];  /* a copy: the function may remove itself */
            f.call();
            if (!alive) {
                if (outer) *outer = false;
                return;
            }
        }
        alive_ = outer, at_ = outer_at, end_ = outer_end;
    }
    void operator()() { call(); }
    pFunctionPointer_t operator[](int i) const { return get(i); }
private:
    pFunctionPointer_t insert(int i, Callback<void()> func) {
        if (n_ == cap_) {
            cap_ = cap_ ? 2 * cap_ : 4;
            chain_ = static_cast<pFunctionPointer_t *>(realloc(chain_, (size_t)cap_ * sizeof chain_[0]));
            if (!chain_) abort();
        }
        memmove(&chain_[i + 1], &chain_[i], (size_t)(n_ - i) * sizeof chain_[0]);
        chain_[i] = new FunctionPointer(func);
        n_++;
        /* added where call() has been or goes next (at_ + 1: add_front() once the first removed
         * itself, add() after the last): not called this time; add() elsewhere appends past end_ */
        if (alive_ && i <= at_ + 1) at_++, end_++;
        return chain_[i];
    }
    void take(int i) {
        delete chain_[i];
        memmove(&chain_[i], &chain_[i + 1], (size_t)(n_ - i - 1) * sizeof chain_[0]);
        n_--;
        if (alive_ && i <= at_) at_--;
        if (alive_ && i < end_) end_--;
    }
    pFunctionPointer_t *chain_ = nullptr;
    int n_ = 0, cap_ = 0;
    bool *alive_ = nullptr;  /* in call(): its flag that the chain still exists */
    int at_ = 0;             /* in call(): the function it is at */
    int end_ = 0;            /* in call(): one past the last function of those there when it began */
};

/* platform/CriticalSectionLock.h: a critical section for the object's lifetime (mbed OS 5.8+) */
class CriticalSectionLock {
public:
    CriticalSectionLock() { core_util_critical_section_enter(); }
    ~CriticalSectionLock() { core_util_critical_section_exit(); }
    CriticalSectionLock(const CriticalSectionLock &) = delete;
    CriticalSectionLock &operator=(const CriticalSectionLock &) = delete;
    static void enable() { core_util_critical_section_enter(); }
    static void disable() { core_util_critical_section_exit(); }
};

/* drivers/Timer.h: simulated time while running; reading it is a read of the board */
class Timer {
public:
    void start() { if (!running_) { tfc_mbed_start(); start_s_ = tfc_mbed_now_s(); running_ = 1; } }
    void stop() { if (running_) { held_s_ += tfc_mbed_now_s() - start_s_; running_ = 0; } }
    void reset() { held_s_ = 0.0; start_s_ = tfc_mbed_now_s(); }
    float read() { return (float)elapsed_s(); }
    int read_ms() { return (int)(elapsed_s() * 1e3); }
    int read_us() { return (int)(elapsed_s() * 1e6); }
    uint64_t read_high_resolution_us() { return (uint64_t)(elapsed_s() * 1e6); }
    operator float() { return read(); }
private:
    double elapsed_s() { tfc_mbed_poll(); return held_s_ + (running_ ? tfc_mbed_now_s() - start_s_ : 0.0); }
    double start_s_ = 0.0, held_s_ = 0.0;
    int running_ = 0;
};

/* drivers/Ticker.h, Timeout.h: the handler every `t` seconds (once, for a Timeout) of simulated
 * time from attach(), run by the kit's clock (docs/firmware.md, "The mbed flavour"). */
class Ticker {
public:
    Ticker() {}
    Ticker(const Ticker &) = delete;
    Ticker &operator=(const Ticker &) = delete;
    virtual ~Ticker() { detach(); }
    void attach(Callback<void()> func, float t) { arm(func, t); }
    template <typename T, typename M> void attach(T *obj, M method, float t) { arm(Callback<void()>(obj, method), t); }
    void attach_us(Callback<void()> func, int64_t t) { arm(func, t * 1e-6); }
    template <typename T, typename M> void attach_us(T *obj, M method, int64_t t) { arm(Callback<void()>(obj, method), t * 1e-6); }
    void detach() { tfc_mbed_event_detach(&ev_); }
protected:
    virtual int repeats() const { return 1; }
private:
    void arm(Callback<void()> func, double t) {
        handler_ = func;
        ev_.fn = [](void *self) { static_cast<Ticker *>(self)->handler_.call(); };
        ev_.arg = this;
        tfc_mbed_event_attach(&ev_, t, repeats(), repeats() ? "Ticker::attach" : "Timeout::attach");
    }
    Callback<void()> handler_;
    tfc_mbed_event ev_ = {};
};
class Timeout : public Ticker {
protected:
    int repeats() const override { return 0; }
};

/* drivers/DigitalOut.h, DigitalIn.h, BusOut.h, BusIn.h */
class DigitalOut {
public:
    explicit DigitalOut(PinName pin, int value = 0) : pin_(pin) { write(value); }
    void write(int value) { value_ = value != 0; tfc_mbed_digital_write(pin_, value_); }
    int read() { return value_; }
    int is_connected() { return pin_ != NC; }
    DigitalOut &operator=(int value) { write(value); return *this; }
    DigitalOut &operator=(DigitalOut &rhs) { write(rhs.read()); return *this; }
    operator int() { return read(); }
private:
    PinName pin_;
    int value_ = 0;
};
class DigitalIn {
public:
    explicit DigitalIn(PinName pin, PinMode mode = PullDefault) : pin_(pin) { (void)mode; }
    int read() { return tfc_mbed_digital_read(pin_) != 0; }
    void mode(PinMode mode) { (void)mode; }
    int is_connected() { return pin_ != NC; }
    operator int() { return read(); }
private:
    PinName pin_;
};
class BusOut {
public:
    BusOut(PinName p0, PinName p1 = NC, PinName p2 = NC, PinName p3 = NC, PinName p4 = NC,
           PinName p5 = NC, PinName p6 = NC, PinName p7 = NC, PinName p8 = NC, PinName p9 = NC,
           PinName p10 = NC, PinName p11 = NC, PinName p12 = NC, PinName p13 = NC,
           PinName p14 = NC, PinName p15 = NC)
        : pins_{p0, p1, p2, p3, p4, p5, p6, p7, p8, p9, p10, p11, p12, p13, p14, p15} {}
    void write(int value) {
        value_ = value;
        for (int i = 0; i < 16; i++) if (pins_[i] != NC) tfc_mbed_digital_write(pins_[i], (value >> i) & 1);
    }
    int read() { return value_; }
    int mask() { int m = 0; for (int i = 0; i < 16; i++) if (pins_[i] != NC) m |= 1 << i; return m; }
    BusOut &operator=(int value) { write(value); return *this; }
    operator int() { return read(); }
private:
    PinName pins_[16];
    int value_ = 0;
};
class BusIn {
public:
    BusIn(PinName p0, PinName p1 = NC, PinName p2 = NC, PinName p3 = NC, PinName p4 = NC,
          PinName p5 = NC, PinName p6 = NC, PinName p7 = NC)
        : pins_{p0, p1, p2, p3, p4, p5, p6, p7} {}
    int read() {
        int v = 0;
        for (int i = 0; i < 8; i++) if (pins_[i] != NC && tfc_mbed_digital_read(pins_[i])) v |= 1 << i;
        return v;
    }
    void mode(PinMode mode) { (void)mode; }
    operator int() { return read(); }
private:
    PinName pins_[8];
};

/* drivers/PwmOut.h: duty 0..1 and period; a servo pulse on PTB0 (servo channel 0) steers */
class PwmOut {
public:
    explicit PwmOut(PinName pin) : pin_(pin) {}
    void write(float duty) { duty_ = duty < 0 ? 0 : (duty > 1 ? 1 : duty); tfc_mbed_pwm_write(pin_, duty_, period_s_); }
    float read() { return duty_; }
    void period(float s) { period_s_ = s; write(duty_); }
    void period_ms(int ms) { period(ms * 1e-3f); }
    void period_us(int us) { period(us * 1e-6f); }
    void pulsewidth(float s) { write(period_s_ > 0 ? s / period_s_ : 0.0f); }
    void pulsewidth_ms(int ms) { pulsewidth(ms * 1e-3f); }
    void pulsewidth_us(int us) { pulsewidth(us * 1e-6f); }
    PwmOut &operator=(float duty) { write(duty); return *this; }
    PwmOut &operator=(PwmOut &rhs) { write(rhs.read()); return *this; }
    operator float() { return read(); }
private:
    PinName pin_;
    float duty_ = 0.0f, period_s_ = 0.020f;   /* mbed's default period: 20 ms */
};

/* drivers/AnalogIn.h, AnalogOut.h: 0..1 of the ADC's (DAC's) 3.3 V */
class AnalogIn {
public:
    explicit AnalogIn(PinName pin) : pin_(pin) {}
    float read() { return tfc_mbed_analog_read(pin_); }
    unsigned short read_u16() { return (unsigned short)(read() * 65535.0f + 0.5f); }
    operator float() { return read(); }
private:
    PinName pin_;
};
class AnalogOut {
public:
    explicit AnalogOut(PinName pin) { (void)pin; }
    void write(float v) { value_ = v < 0 ? 0 : (v > 1 ? 1 : v); }
    void write_u16(unsigned short v) { write(v / 65535.0f); }
    float read() { return value_; }
    AnalogOut &operator=(float v) { write(v); return *this; }
    operator float() { return read(); }
private:
    float value_ = 0.0f;
};

/* drivers/Serial.h, RawSerial.h: what is written goes to the program's standard output */
class SerialBase {
    static constexpr const char *NO_INPUT_ = "the serial port's input: nothing arrives on the simulated car";
public:
    enum Parity { None = 0, Odd, Even, Forced1, Forced0 };
    enum IrqType { RxIrq = 0, TxIrq };
    void baud(int rate) { (void)rate; }
    void format(int bits = 8, Parity parity = None, int stop_bits = 1) { (void)bits, (void)parity, (void)stop_bits; }
    int readable() { return 0; }
    int writeable() { return 1; }
    void attach(Callback<void()> func, IrqType type = RxIrq) { (void)func, (void)type; }  /* no input comes */
    template <typename T, typename M> void attach(T *obj, M method, IrqType type = RxIrq) { (void)obj, (void)method, (void)type; }
    int putc(int c) { return fputc(c, stdout); }
    int puts(const char *s) { return fputs(s, stdout); }
    int printf(const char *format, ...) __attribute__((format(printf, 2, 3))) {
        va_list ap;
        va_start(ap, format);
        int n = vprintf(format, ap);
        va_end(ap);
        return n;
    }
    /* inlined: a run ended here names the caller's line */
    __attribute__((always_inline)) int getc() { tfc_mbed_not_emulated("Serial::getc", NO_INPUT_); }
    __attribute__((always_inline)) char *gets(char *s, int size) { (void)s, (void)size; tfc_mbed_not_emulated("Serial::gets", NO_INPUT_); }
    __attribute__((always_inline)) int scanf(const char *format, ...) { (void)format; tfc_mbed_not_emulated("Serial::scanf", NO_INPUT_); }
protected:
    SerialBase() {}
};
class Serial : public SerialBase {
public:
    Serial(PinName tx, PinName rx, const char *name = nullptr) { (void)tx, (void)rx, (void)name; }
    Serial(PinName tx, PinName rx, int baud_rate) { (void)tx, (void)rx, (void)baud_rate; }
};
class RawSerial : public SerialBase {
public:
    RawSerial(PinName tx, PinName rx, int baud_rate = 9600) { (void)tx, (void)rx, (void)baud_rate; }
};

}  // namespace mbed

#include "InterruptIn.h"
using namespace mbed;
using namespace std;
#endif
