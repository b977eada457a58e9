/* TFC_arm_cm0.h (simulator): the library's Cortex-M0+ helpers (arm_cm0.c). enable_irq(n) and
 * disable_irq(n) take the IRQ number (the vector's INT_x - 16) as NVIC_EnableIRQ does; priorities
 * are accepted and not modelled. */
#ifndef TFC_ARM_CM0_H_
#define TFC_ARM_CM0_H_
#define enable_irq(irq) tfc_sim_nvic_enable((int)(irq))
#define disable_irq(irq) tfc_sim_nvic_disable((int)(irq))
#define set_irq_priority(irq, prio) ((void)(irq), (void)(prio))
#endif
