/* TFC_arm_cm0.h (simulator): the Cortex-M0+ helpers are no-ops here. */
#ifndef TFC_ARM_CM0_H_
#define TFC_ARM_CM0_H_
#define enable_irq(irq) ((void)(irq))
#define disable_irq(irq) ((void)(irq))
#define set_irq_priority(irq, prio) ((void)(irq), (void)(prio))
#endif
