/* QEI.h of the simulator's mbed kit (simrunner drive main.cpp --kit tfc-mbed): the API of Aaron Berk's
 * quadrature encoder interface for mbed (os.mbed.com/users/aberk/code/QEI/, 2010; the names and
 * signatures as its QEI.h publishes them, with setPulses, setRevolutions and getInvalidCount of the
 * 2021 mbed OS 6 derivative by D. Smart), implemented on the car file's [encoders] (../sensors.cpp;
 * docs/firmware.md, "The mbed flavour"):
 *
 *     QEI left(PTD4, PTA12, NC, 512, QEI::X4_ENCODING);   // the first QEI: the first encoder (RL)
 *     QEI right(PTA4, PTA5, NC, 512, QEI::X4_ENCODING);   // the second: the second (RR)
 *     int pulses = left.getPulses();                       // since construction or reset()
 *
 * - which wheel: the n-th QEI constructed reads the n-th wheel with an encoder (FL, FR, RL, RR
 *   order), unless --param qei_PTD4=3 (channel A's pin; 0..3: SPINNER_WHEEL_FL..RR) names it;
 * - getPulses() counts as the library decodes the wheel's encoder: X2 two pulses a line (channel
 *   A's edges), X4 four (both channels' edges); up when the wheel rolls forwards. From the car's
 *   counter: exact when its counting is x4 (the default) or equals the encoding;
 * - getRevolutions() counts the index channel's rising edges when an index pin is given, else 0, as
 *   the library (its index pin's InterruptIn: rise -> revolutions_++): the index of --param
 *   encoder_z_PTxN (InterruptIn.h), high for one count of the car's counter a revolution at the
 *   wheel's angle at the start, rising as the count comes to it either way (one a turn);
 * - the counts are sampled at each tick of the kit's 1-kHz clock (the library counts in its pins'
 *   interrupts); a read is a read of the board (a loop of them lets time pass). */
#ifndef QEI_H
#define QEI_H
#include "mbed.h"

#define PREV_MASK 0x1  /* the library's masks of the previous and current 2-bit state */
#define CURR_MASK 0x2
#define INVALID 0x3

class QEI {
public:
    typedef enum Encoding { X2_ENCODING, X4_ENCODING } Encoding;

    QEI(PinName channelA, PinName channelB, PinName index, int pulsesPerRev, Encoding encoding = X2_ENCODING)
        : pulsesPerRev_(pulsesPerRev) {
        (void)channelB;
        tfc_mbed_qei_attach(&q_, channelA, index != NC, encoding == X4_ENCODING ? 4 : 2);
    }
    ~QEI() { tfc_mbed_qei_detach(&q_); }
    QEI(const QEI &) = delete;
    QEI &operator=(const QEI &) = delete;

    __attribute__((always_inline)) void reset(void) { tfc_mbed_qei_set(&q_, 0, 0, "QEI::reset"); }
    __attribute__((always_inline)) int getCurrentState(void) { return tfc_mbed_qei_state(&q_, "QEI::getCurrentState"); }
    __attribute__((always_inline)) int getPulses(void) { return tfc_mbed_qei_pulses(&q_, "QEI::getPulses"); }
    __attribute__((always_inline)) int getRevolutions(void) { return tfc_mbed_qei_revolutions(&q_, "QEI::getRevolutions"); }
    /* the derivative's additions: set the counts; no gray-code violations happen here */
    __attribute__((always_inline)) void setPulses(int newCount) { tfc_mbed_qei_set(&q_, newCount, -1, "QEI::setPulses"); }
    void setRevolutions(int newRevs) {
        tfc_mbed_qei_set(&q_, getPulses(), newRevs, "QEI::setRevolutions");
    }
    int getInvalidCount(void) { return 0; }

private:
    int pulsesPerRev_;  /* the library keeps it; getRevolutions counts index pulses */
    tfc_mbed_qei q_;
};
#endif
