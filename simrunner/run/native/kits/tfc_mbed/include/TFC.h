/* TFC.h of the simulator's mbed FRDM-TFC kit (simrunner drive main.cpp --kit tfc-mbed): the API
 * of the mbed "FRDM-TFC" library (Eli Hughes; os.mbed.com/users/emh203/code/FRDM-TFC/, as teams
 * publish it beside their main.cpp: FRDM-TFC/TFC.h and TFC.cpp) with the same names, types and
 * signatures, implemented on the simulated car (../tfc_mbed.cpp; docs/firmware.md, "The mbed
 * flavour"). On the board the library's TPM1 interrupt starts a camera read-out every servo period
 * and its ADC interrupt fills the image; here images arrive while the program waits or polls. */
#ifndef _TFC_H
#define _TFC_H
#include "mbed.h"
#include "tfc_mbed_sim.h"

/* Constants of the library's TFC.cpp: the servo frame (SERVO_DEFAULT_PERIOD 10 ms, also the camera
 * read-out's period), the servo pulse range and the motor PWM frequency TFC_Init() sets. */
#define SERVO_DEFAULT_PERIOD (float)(.010)
#define SERVO_MIN_PULSE_WIDTH_DEFAULT (float)(.0005)
#define SERVO_MAX_PULSE_WIDTH_DEFAULT (float)(.002)
#define FTM0_DEFAULT_SWITCHING_FREQUENCY (4000.0)
#define ADC_MAX_CODE (4095)

void TFC_Init();
void TFC_GPIO_Init();
/* The library's count of servo frames: its TPM1 overflow interrupt increments it (up to 0xFFFFFFFF),
 * at each image's read-out start. A program's write sticks (`TFC_ServoTicker = 0;`: it counts on
 * from 0); TFC_Init zeroes it, TFC_InitServos does not. Read through a poll (below). */
#define TFC_ServoTicker (*tfc_mbed_servo_ticker())
uint8_t TFC_GetDIP_Switch();                   /* --param dip (0..15) */
uint8_t TFC_ReadPushButton(uint8_t Index);     /* --param button0/button1; button0_at */
void TFC_SetBatteryLED(uint8_t Value);         /* lower 4 bits: the 4 LEDs */
void TFC_SetBatteryLED_Level(uint8_t BattLevel);
/* Position -1..1 of servo 0 (1: --param tfc_servo_channel=1) steers: x --param tfc_servo_rad
 * (0.40, + = left) + tfc_servo_offset_rad. Queued, as the library does: TPM1's interrupt writes it to
 * the channel's CnV at the next overflow, which loads it at the one after: the servo steers by it
 * from the second servo frame edge after the call. */
void TFC_SetServo(uint8_t ServoNumber, float Position);
void TFC_SetServoDutyCycle(uint8_t ServoNumber, float DutyCycle);
/* The pulse range of positions -1..1 and the servo frame, which is the camera's period too. TPM1's
 * counter counts on: the frame in progress ends one new period after it began (87.4 ms more when the
 * counter is past the new period already: it counts round 0xFFFF); TFC_ServoTicker counts on. */
void TFC_InitServos(float ServoPulseWidthMin, float ServoPulseWidthMax, float ServoPeriod);
void TFC_InitMotorPWM(float SwitchingFrequency);
/* -1..1 duties of H-bridge A (the left rear motor) and B (the right), while enabled. */
void TFC_SetMotorPWM(float MotorA, float MotorB);
float TFC_ReadPot(uint8_t Channel);            /* --param pot0/pot1 (-1..1) */
/* The battery sense input in volts (the library returns the ADC's 0..3 V, its divider factor
 * commented out): --param battery_v (7.2) x 10k / (47k + 10k). */
float TFC_ReadBatteryVoltage();
/* Not in the mbed library (the CodeWarrior one's name): the servo frame, the camera's read-out period,
 * written as TPM1's MOD while it counts - it loads at the overflow that ends the frame in progress
 * (the next image is still of the old frame; the one after it of the new). */
void TFC_SetLineScanExposureTime(uint32_t TimeIn_uS);
void TFC_InitLineScanCamera();
void TFC_InitADC_System();

/* The two cameras' 128 pixels as 12-bit counts (the camera row's 8-bit grey x 16; camera 1 reads
 * the same row), ping-pong buffers as the library has them: the pointers swap at each image. */
extern volatile uint16_t *TFC_LineScanImage0;
extern volatile uint16_t *TFC_LineScanImage1;
extern volatile uint16_t LineScanImage0Buffer[2][128];
extern volatile uint16_t LineScanImage1Buffer[2][128];
extern volatile uint16_t *LineScanImage0WorkingBuffer;
extern volatile uint16_t *LineScanImage1WorkingBuffer;
extern volatile uint8_t LineScanWorkingBuffer;
extern volatile uint16_t PotADC_Value[2];
extern volatile uint16_t BatSenseADC_Value;
/* Incremented at each new image (the library's ADC interrupt: TFC_LineScanImageReady++); your code
 * sets it back to 0. Read through the kit, so that a loop polling it lets time pass (a value of a
 * class type converting to uint8_t: pass it to printf as (int)TFC_LineScanImageReady). */
#define TFC_LineScanImageReady (tfc_mbed_ready_flag())

/* TFC_Ticker[]: mbed programs define these tickers themselves (`volatile uint32_t
 * TFC_Ticker[NUM_TFC_TICKERS];`, counted by a Ticker of theirs), as the CodeWarrior library had
 * them. The name becomes a read through the kit (that definition then declares the kit's
 * function, whatever its length up to 16), so `while (TFC_Ticker[3] < 100) {}` lets time pass for
 * the Ticker to count. Its handler's increments count as written. */
#define TFC_Ticker (*tfc_mbed_tickers())

/* LEDs, H-bridge enable, push buttons, DIP switches: the library's macros (they write and read
 * the KL25Z's GPIO registers there; here the kit's board). */
#define TFC_HBRIDGE_ENABLE tfc_mbed_digital_write(PTE21, 1)
#define TFC_HBRIDGE_DISABLE tfc_mbed_digital_write(PTE21, 0)
#define TFC_BAT_LED0_ON tfc_mbed_digital_write(PTB8, 1)
#define TFC_BAT_LED1_ON tfc_mbed_digital_write(PTB9, 1)
#define TFC_BAT_LED2_ON tfc_mbed_digital_write(PTB10, 1)
#define TFC_BAT_LED3_ON tfc_mbed_digital_write(PTB11, 1)
#define TFC_BAT_LED0_OFF tfc_mbed_digital_write(PTB8, 0)
#define TFC_BAT_LED1_OFF tfc_mbed_digital_write(PTB9, 0)
#define TFC_BAT_LED2_OFF tfc_mbed_digital_write(PTB10, 0)
#define TFC_BAT_LED3_OFF tfc_mbed_digital_write(PTB11, 0)
#define TFC_BAT_LED0_TOGGLE tfc_mbed_digital_write(PTB8, -1)
#define TFC_BAT_LED1_TOGGLE tfc_mbed_digital_write(PTB9, -1)
#define TFC_BAT_LED2_TOGGLE tfc_mbed_digital_write(PTB10, -1)
#define TFC_BAT_LED3_TOGGLE tfc_mbed_digital_write(PTB11, -1)
#define TFC_PUSH_BUTTON_0_PRESSED (tfc_mbed_digital_read(PTC13) > 0)
#define TFC_PUSH_BUTTON_1_PRESSED (tfc_mbed_digital_read(PTC17) > 0)
#define TFC_DIP_SWITCH_0_ON ((TFC_GetDIP_Switch() & 0x01) > 0)
#define TFC_DIP_SWITCH_1_ON ((TFC_GetDIP_Switch() & 0x02) > 0)
#define TFC_DIP_SWITCH_2_ON ((TFC_GetDIP_Switch() & 0x04) > 0)
#define TFC_DIP_SWITCH_3_ON ((TFC_GetDIP_Switch() & 0x08) > 0)

/* The camera's clock and SI lines, as the library writes them (GPIO registers: not emulated, so
 * code that drives the camera itself does not compile here). */
#define TAOS_CLK_HIGH PTE->PSOR = (1 << 1)
#define TAOS_CLK_LOW PTE->PCOR = (1 << 1)
#define TAOS_SI_HIGH PTD->PSOR = (1 << 7)
#define TAOS_SI_LOW PTD->PCOR = (1 << 7)
#endif
