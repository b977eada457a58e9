/* The KL25Z's timers as firmware sets up its own timer interrupt (the simulator's TFC kit,
 * included by derivative.h). Names, masks and interrupt numbers as MKL25Z4.h has them (NXP KL25
 * Sub-Family Reference Manual KL25P80M48SF0RM: chapter 33 LPTMR, 32 PIT, 31 TPM, 12 SIM, 24 MCG;
 * the Cortex-M0+ NVIC), in both spellings (LPTMR0_CSR and LPTMR0->CSR). The registers are memory
 * the kit reads (timers.c): a timer started with its interrupt enabled, in the NVIC too, calls the
 * program's handler of its vector (PIT_IRQHandler, LPTimer_IRQHandler or LPTMR0_IRQHandler,
 * TPM2_IRQHandler) at the rate its registers and clock give (docs/firmware.md, Timer interrupts).
 * The TFC library's own timers (TPM0, TPM1, the PIT's camera timing) stay the library's. */
#ifndef NXPCUP_SIM_TFC_TIMERS_H
#define NXPCUP_SIM_TFC_TIMERS_H
#include <stdint.h>

typedef struct { volatile uint32_t CSR, PSR, CMR, CNR; } LPTMR_Type;
typedef struct { volatile uint32_t LDVAL, CVAL, TCTRL, TFLG; } PIT_CHANNEL_Type;
typedef struct { volatile uint32_t MCR; uint8_t RESERVED_0[220]; volatile uint32_t LTMR64H, LTMR64L;
                 uint8_t RESERVED_1[24]; PIT_CHANNEL_Type CHANNEL[2]; } PIT_Type;
typedef struct { volatile uint32_t CnSC, CnV; } TPM_CONTROLS_Type;
typedef struct { volatile uint32_t SC, CNT, MOD; TPM_CONTROLS_Type CONTROLS[6]; uint32_t reserved[5];
                 volatile uint32_t STATUS, CONF; } TPM_Type;
typedef struct { volatile uint32_t ISER[1], ICER[1], ISPR[1], ICPR[1], IP[8]; } NVIC_Type;
typedef struct { volatile uint32_t SOPT1, SOPT2, SCGC5, SCGC6; } SIM_Type;
typedef struct { volatile uint8_t C1, C2, SC; } MCG_Type;

extern LPTMR_Type tfc_sim_lptmr0;
extern PIT_Type tfc_sim_pit;
extern TPM_Type tfc_sim_tpm2;
extern NVIC_Type tfc_sim_nvic;
extern SIM_Type tfc_sim_sim;
extern MCG_Type tfc_sim_mcg;

/* The counters (PIT CVAL, LPTMR CNR, TPM2 CNT) count simulated time: each use of LPTMR0, PIT or
 * TPM2 gives the registers with them at the time now (timers.c; the kit itself uses the raw ones). */
LPTMR_Type *tfc_sim_lptmr0_now(void);
PIT_Type *tfc_sim_pit_now(void);
TPM_Type *tfc_sim_tpm2_now(void);
#ifdef TFC_SIM_TIMERS_RAW
#define LPTMR0 (&tfc_sim_lptmr0)
#define PIT (&tfc_sim_pit)
#define TPM2 (&tfc_sim_tpm2)
#else
#define LPTMR0 (tfc_sim_lptmr0_now())
#define PIT (tfc_sim_pit_now())
#define TPM2 (tfc_sim_tpm2_now())
#endif
#define LPTMR0_BASE_PTR LPTMR0
#define LPTMR0_CSR (LPTMR0->CSR)
#define LPTMR0_PSR (LPTMR0->PSR)
#define LPTMR0_CMR (LPTMR0->CMR)
#define LPTMR0_CNR (LPTMR0->CNR)
#define LPTMR_CSR_TEN_MASK 0x1u
#define LPTMR_CSR_TMS_MASK 0x2u
#define LPTMR_CSR_TFC_MASK 0x4u
#define LPTMR_CSR_TPP_MASK 0x8u
#define LPTMR_CSR_TPS_MASK 0x30u
#define LPTMR_CSR_TIE_MASK 0x40u
#define LPTMR_CSR_TCF_MASK 0x80u
#define LPTMR_CSR_TPS(x) (((uint32_t)(x) << 4) & LPTMR_CSR_TPS_MASK)
#define LPTMR_PSR_PCS_MASK 0x3u
#define LPTMR_PSR_PBYP_MASK 0x4u
#define LPTMR_PSR_PRESCALE_MASK 0x78u
#define LPTMR_PSR_PRESCALE_SHIFT 3
#define LPTMR_PSR_PCS(x) ((uint32_t)(x) & LPTMR_PSR_PCS_MASK)
#define LPTMR_PSR_PRESCALE(x) (((uint32_t)(x) << 3) & LPTMR_PSR_PRESCALE_MASK)
#define LPTMR_CMR_COMPARE_MASK 0xFFFFu
#define LPTMR_CMR_COMPARE(x) ((uint32_t)(x) & 0xFFFFu)

#define PIT_BASE_PTR PIT
#define PIT_MCR (PIT->MCR)
#define PIT_LDVAL0 (PIT->CHANNEL[0].LDVAL)
#define PIT_CVAL0 (PIT->CHANNEL[0].CVAL)
#define PIT_TCTRL0 (PIT->CHANNEL[0].TCTRL)
#define PIT_TFLG0 (PIT->CHANNEL[0].TFLG)
#define PIT_LDVAL1 (PIT->CHANNEL[1].LDVAL)
#define PIT_CVAL1 (PIT->CHANNEL[1].CVAL)
#define PIT_TCTRL1 (PIT->CHANNEL[1].TCTRL)
#define PIT_TFLG1 (PIT->CHANNEL[1].TFLG)
#define PIT_LDVAL_REG(base, index) ((base)->CHANNEL[index].LDVAL)
#define PIT_TCTRL_REG(base, index) ((base)->CHANNEL[index].TCTRL)
#define PIT_TFLG_REG(base, index) ((base)->CHANNEL[index].TFLG)
#define PIT_MCR_FRZ_MASK 0x1u
#define PIT_MCR_MDIS_MASK 0x2u
#define PIT_TCTRL_TEN_MASK 0x1u
#define PIT_TCTRL_TIE_MASK 0x2u
#define PIT_TCTRL_CHN_MASK 0x4u
#define PIT_TFLG_TIF_MASK 0x1u
#define PIT_LDVAL_TSV(x) ((uint32_t)(x))

#define TPM2_BASE_PTR TPM2
#define TPM2_SC (TPM2->SC)
#define TPM2_CNT (TPM2->CNT)
#define TPM2_MOD (TPM2->MOD)
#define TPM2_C0SC (TPM2->CONTROLS[0].CnSC)
#define TPM2_C0V (TPM2->CONTROLS[0].CnV)
#define TPM2_C1SC (TPM2->CONTROLS[1].CnSC)
#define TPM2_C1V (TPM2->CONTROLS[1].CnV)
#define TPM2_STATUS (TPM2->STATUS)
#define TPM2_CONF (TPM2->CONF)
#define TPM_SC_PS_MASK 0x7u
#define TPM_SC_CMOD_MASK 0x18u
#define TPM_SC_CPWMS_MASK 0x20u
#define TPM_SC_TOIE_MASK 0x40u
#define TPM_SC_TOF_MASK 0x80u
#define TPM_SC_PS(x) ((uint32_t)(x) & TPM_SC_PS_MASK)
#define TPM_SC_CMOD(x) (((uint32_t)(x) << 3) & TPM_SC_CMOD_MASK)
#define TPM_MOD_MOD(x) ((uint32_t)(x) & 0xFFFFu)
#define TPM_CnSC_CHIE_MASK 0x40u
#define TPM_CnSC_CHF_MASK 0x80u
#define TPM_CNT_COUNT(x) ((uint32_t)(x) & 0xFFFFu)
/* STATUS (RM 31.3.5): the channels' flags and TOF, bit 8, a copy of SC TOF (the kit sets both) */
#define TPM_STATUS_CH0F_MASK 0x1u
#define TPM_STATUS_CH1F_MASK 0x2u
#define TPM_STATUS_TOF_MASK 0x100u
/* CONF (RM 31.3.7): accepted, not modelled (DBGMODE: counting while the debugger halts the core) */
#define TPM_CONF_DOZEEN_MASK 0x20u
#define TPM_CONF_DBGMODE_MASK 0xC0u
#define TPM_CONF_DBGMODE(x) (((uint32_t)(x) << 6) & TPM_CONF_DBGMODE_MASK)

#define SIM (&tfc_sim_sim)
#define SIM_SOPT1 (SIM->SOPT1)
#define SIM_SOPT2 (SIM->SOPT2)
#define SIM_SCGC5 (SIM->SCGC5)
#define SIM_SCGC6 (SIM->SCGC6)
#define SIM_SOPT1_OSC32KSEL_MASK 0xC0000u
#define SIM_SOPT1_OSC32KSEL(x) (((uint32_t)(x) << 18) & SIM_SOPT1_OSC32KSEL_MASK)
#define SIM_SOPT2_PLLFLLSEL_MASK 0x10000u
#define SIM_SOPT2_TPMSRC_MASK 0x3000000u
#define SIM_SOPT2_TPMSRC(x) (((uint32_t)(x) << 24) & SIM_SOPT2_TPMSRC_MASK)
#define SIM_SCGC5_LPTMR_MASK 0x1u
#define SIM_SCGC6_PIT_MASK 0x800000u
#define SIM_SCGC6_TPM2_MASK 0x4000000u

/* the MCG's internal reference clock (MCGIRCLK), a clock of the LPTMR and the TPM */
#define MCG (&tfc_sim_mcg)
#define MCG_C1 (MCG->C1)
#define MCG_C2 (MCG->C2)
#define MCG_SC (MCG->SC)
#define MCG_C1_IREFSTEN_MASK 0x1u
#define MCG_C1_IRCLKEN_MASK 0x2u
#define MCG_C2_IRCS_MASK 0x1u
#define MCG_SC_FCRDIV_MASK 0xEu
#define MCG_SC_FCRDIV(x) ((uint8_t)(((uint32_t)(x) << 1) & MCG_SC_FCRDIV_MASK))

/* the NVIC (CMSIS core_cm0plus.h) and the vector numbers: IRQn as CMSIS counts (both MKL25Z4.h
 * spellings of the LPTMR's), INT_ as the older MKL25Z4.h */
#define NVIC (&tfc_sim_nvic)
#define NVIC_ISER (NVIC->ISER[0])
#define NVIC_ICER (NVIC->ICER[0])
#define NVIC_ISPR (NVIC->ISPR[0])
#define NVIC_ICPR (NVIC->ICPR[0])
/* the priority registers (older MKL25Z4.h: NVIC_IPR0..7, four IRQs each): written as
 * NVIC_SetPriority is, accepted and not modelled (docs/firmware.md: the NVIC's priorities) */
#define NVIC_IPR0 (NVIC->IP[0])
#define NVIC_IPR1 (NVIC->IP[1])
#define NVIC_IPR2 (NVIC->IP[2])
#define NVIC_IPR3 (NVIC->IP[3])
#define NVIC_IPR4 (NVIC->IP[4])
#define NVIC_IPR5 (NVIC->IP[5])
#define NVIC_IPR6 (NVIC->IP[6])
#define NVIC_IPR7 (NVIC->IP[7])
typedef enum { TPM0_IRQn = 17, TPM1_IRQn = 18, TPM2_IRQn = 19, PIT_IRQn = 22, LPTimer_IRQn = 28,
               LPTMR0_IRQn = 28 } IRQn_Type;
#define INT_TPM2 35
#define INT_PIT 38
#define INT_LPTimer 44
/* The pending bits (timers.c; ARMv6-M, ARM DDI 0419, B3.4): independent of the enable bits, one an
 * IRQ; a pending, enabled IRQ is taken when PRIMASK allows - inside NVIC_EnableIRQ,
 * NVIC_SetPendingIRQ, __enable_irq, or at the next call after a raw NVIC_ISER / NVIC_ISPR write.
 * A read of the raw registers does not give the bits: NVIC_GetPendingIRQ does. */
void tfc_sim_nvic_enable(int irq);   /* timers.c: NVIC_EnableIRQ, enable_irq */
void tfc_sim_nvic_disable(int irq);
void tfc_sim_nvic_set_pending(int irq);
uint32_t tfc_sim_nvic_pending(int irq);
#define NVIC_EnableIRQ(irq) tfc_sim_nvic_enable((int)(irq))
#define NVIC_DisableIRQ(irq) tfc_sim_nvic_disable((int)(irq))
#define NVIC_ClearPendingIRQ(irq) ((void)(NVIC->ICPR[0] |= 1u << ((uint32_t)(irq) & 31u)))  /* (|=: two clears before the kit's look) */
#define NVIC_SetPendingIRQ(irq) tfc_sim_nvic_set_pending((int)(irq))
#define NVIC_GetPendingIRQ(irq) tfc_sim_nvic_pending((int)(irq))
#define NVIC_SetPriority(irq, prio) ((void)(irq), (void)(prio))
#endif
