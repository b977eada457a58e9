/* MMA8451Q.h of the simulator's mbed kit (simrunner drive main.cpp --kit tfc-mbed): the API of the
 * mbed MMA8451Q library for the FRDM-KL25Z's on-board accelerometer (Emilio Monti, 2010-2011,
 * os.mbed.com/users/emilmont/code/MMA8451Q/: constructor, getWhoAmI, getAccX/Y/Z, getAccAllAxis;
 * the raw reads, isDataAvailable and the event set-ups of its extended fork by Clemente di Caprio),
 * implemented on the car file's [imu] accelerometer (../sensors.cpp; docs/firmware.md, "The
 * mbed flavour"):
 *
 *     #define MMA8451_I2C_ADDRESS (0x1d << 1)
 *     MMA8451Q acc(PTE25, PTE24, MMA8451_I2C_ADDRESS);
 *     float lateral_g = acc.getAccY();
 *
 * - axes: the board's are the car's (x ahead, y left, z up: the board lies flat, its x ahead), so at
 *   rest getAccZ() is ~ +1 g and in a left turn getAccY() is + v^2 / r / g; mounted otherwise, turn
 *   the axes in your code;
 * - values: the [imu] accelerometer's specific force (with its noise, bias, rate and resolution) in g
 *   (9.80665 m/s^2), then as the library reads the chip: 14-bit counts at +-2 g, 4096 a g (MMA8451Q
 *   datasheet, NXP rev. 10.3, Table 1), clipped to -8192 .. 8191, and the library's conversion
 *   (a negative count reads one count higher: it subtracts 16383, not 16384, from the register);
 * - sampled at each tick of the kit's 1-kHz clock; a read is a read of the board (a loop of them
 *   lets time pass). A car without [imu]: the first read ends the run naming its line.
 * Not emulated (the run ends naming the line): the chip's interrupts (FreeFallDetection,
 * MotionDetection, OrientationDetect, DataReady, GetOrientationState). */
#ifndef MMA8451Q_H
#define MMA8451Q_H
#include "mbed.h"

/* the extended library's output data rates (CTRL_REG1 DR bits) */
#define cODR_800HZ 0
#define cODR_400HZ 1
#define cODR_200HZ 2
#define cODR_100HZ 3
#define cODR_50HZ 4
#define cODR_12_5HZ 5
#define cODR_6_25HZ 6
#define cODR_1_56HZ 7

class MMA8451Q {
    static constexpr const char *NO_EVENTS_ = "the accelerometer's interrupt pins (its event detection) "
                                              "are not simulated: read getAccX/Y/Z and test in your code";
public:
    MMA8451Q(PinName sda, PinName scl, int addr) : m_addr(addr) { (void)sda, (void)scl; tfc_mbed_mma_attach(); }
    ~MMA8451Q() {}

    uint8_t getWhoAmI() { return 0x1A; }  /* the MMA8451Q's WHO_AM_I (datasheet: 0x1A) */
    __attribute__((always_inline)) float getAccX() { return float(getAccAxis(0, "MMA8451Q::getAccX")) / 4096.0; }
    __attribute__((always_inline)) float getAccY() { return float(getAccAxis(1, "MMA8451Q::getAccY")) / 4096.0; }
    __attribute__((always_inline)) float getAccZ() { return float(getAccAxis(2, "MMA8451Q::getAccZ")) / 4096.0; }
    void getAccAllAxis(float *res) {
        res[0] = getAccX();
        res[1] = getAccY();
        res[2] = getAccZ();
    }
    /* the extended library: the 14-bit readings; 1 (new data: the chip samples at 800 Hz) */
    __attribute__((always_inline)) int16_t getAccRawX(int16_t *res) { *res = getAccAxis(0, "MMA8451Q::getAccRawX"); return 1; }
    __attribute__((always_inline)) int16_t getAccRawY(int16_t *res) { *res = getAccAxis(1, "MMA8451Q::getAccRawY"); return 1; }
    __attribute__((always_inline)) int16_t getAccRawZ(int16_t *res) { *res = getAccAxis(2, "MMA8451Q::getAccRawZ"); return 1; }
    unsigned int getAccRawAllAxis(int16_t *res) {
        getAccRawX(&res[0]);
        getAccRawY(&res[1]);
        getAccRawZ(&res[2]);
        return 1;
    }
    unsigned int isDataAvailable(void) { return 0x0F; }  /* STATUS: ZYXDR | ZDR | YDR | XDR */
    void Reset(void) {}

    void FreeFallDetection(void (*fptr)(void)) { (void)fptr; tfc_mbed_not_emulated("MMA8451Q::FreeFallDetection", NO_EVENTS_); }
    void MotionDetection(void (*fptr)(void)) { (void)fptr; tfc_mbed_not_emulated("MMA8451Q::MotionDetection", NO_EVENTS_); }
    void OrientationDetect(void (*fptr)(void), unsigned int Z_LockOut, unsigned int Z_BkFr,
                           unsigned int PL_Thsld, unsigned int PL_Hyst) {
        (void)fptr, (void)Z_LockOut, (void)Z_BkFr, (void)PL_Thsld, (void)PL_Hyst;
        tfc_mbed_not_emulated("MMA8451Q::OrientationDetect", NO_EVENTS_);
    }
    void OrientationDetect(void (*fptr)(void)) { (void)fptr; tfc_mbed_not_emulated("MMA8451Q::OrientationDetect", NO_EVENTS_); }
    unsigned char GetOrientationState(void) { tfc_mbed_not_emulated("MMA8451Q::GetOrientationState", NO_EVENTS_); }
    void DataReady(void (*fptr)(void), unsigned char ODR) { (void)fptr, (void)ODR; tfc_mbed_not_emulated("MMA8451Q::DataReady", NO_EVENTS_); }

private:
    /* the chip's count, as the library's getAccAxis turns the two registers into it (inlined, as
     * the reads: a run ended in one names the program's line) */
    __attribute__((always_inline)) int16_t getAccAxis(int axis, const char *what) {
        int16_t acc = (int16_t)(tfc_mbed_mma_counts(axis, what) & 0x3FFF);
        if (acc > 16383 / 2) acc -= 16383;
        return acc;
    }
    int m_addr;
};
#endif
