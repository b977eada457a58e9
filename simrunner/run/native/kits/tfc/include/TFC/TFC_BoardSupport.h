/* TFC_BoardSupport.h (simulator): the shield's H-bridge enable, LEDs, push buttons and DIP
 * switches. Buttons and switches read the run's parameters (--param button0=1, dip=5; button 0
 * is also pressed for 0.2 s at button0_at seconds, default 0.1: a start press). */
#ifndef TFC_BOARDSUPPORT_H_
#define TFC_BOARDSUPPORT_H_
#include <stdint.h>
void TFC_InitGPIO(void);
void TFC_SetBatteryLED_Level(uint8_t BattLevel);
uint8_t TFC_GetDIP_Switch(void);
/* the simulator's hooks behind the macros */
void tfc_sim_hbridge(int on);
void tfc_sim_led(int led, int on);
int tfc_sim_button(int button);
#define TFC_HBRIDGE_ENABLE tfc_sim_hbridge(1)
#define TFC_HBRIDGE_DISABLE tfc_sim_hbridge(0)
#define TFC_BAT_LED0_ON tfc_sim_led(0, 1)
#define TFC_BAT_LED1_ON tfc_sim_led(1, 1)
#define TFC_BAT_LED2_ON tfc_sim_led(2, 1)
#define TFC_BAT_LED3_ON tfc_sim_led(3, 1)
#define TFC_BAT_LED0_OFF tfc_sim_led(0, 0)
#define TFC_BAT_LED1_OFF tfc_sim_led(1, 0)
#define TFC_BAT_LED2_OFF tfc_sim_led(2, 0)
#define TFC_BAT_LED3_OFF tfc_sim_led(3, 0)
#define TFC_BAT_LED0_TOGGLE tfc_sim_led(0, -1)
#define TFC_BAT_LED1_TOGGLE tfc_sim_led(1, -1)
#define TFC_BAT_LED2_TOGGLE tfc_sim_led(2, -1)
#define TFC_BAT_LED3_TOGGLE tfc_sim_led(3, -1)
#define TFC_PUSH_BUTTON_0_PRESSED tfc_sim_button(0)
#define TFC_PUSH_BUTTON_1_PRESSED tfc_sim_button(1)
#endif
