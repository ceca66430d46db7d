/* startup_microbit.c: vector table and reset handler for the Cortex-M0 of the nRF51822 (QEMU microbit). */
#include "startup.h"
void UART0_Handler(void);
void TIMER0_Handler(void);

#define N_IRQ 32

__attribute__((section(".isr_vector"), used)) const vector_entry vector_table[16 + N_IRQ] = {
    { .stack = &_estack },
    { .handler = Reset_Handler },
    { .handler = Default_Handler }, /* NMI */
    { .handler = Default_Handler }, /* HardFault */
    { .handler = 0 }, { .handler = 0 }, { .handler = 0 }, { .handler = 0 },
    { .handler = 0 }, { .handler = 0 }, { .handler = 0 },
    { .handler = Default_Handler }, /* SVCall */
    { .handler = 0 }, { .handler = 0 },
    { .handler = Default_Handler }, /* PendSV */
    { .handler = Default_Handler }, /* SysTick (not used: the nRF51 has none) */
    { .handler = Default_Handler }, /* IRQ 0: POWER_CLOCK */
    { .handler = Default_Handler }, /* IRQ 1: RADIO */
    { .handler = UART0_Handler },   /* IRQ 2: UART0 */
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = TIMER0_Handler },  /* IRQ 8: TIMER0 */
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler }
};

void Reset_Handler(void)
{
    startup_init_memory();
    (void)main(0, 0);
    for (;;) {
    }
}

void Default_Handler(void)
{
    startup_halt();
}
