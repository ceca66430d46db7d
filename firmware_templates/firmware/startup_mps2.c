/* startup_mps2.c: vector table and reset handler for the Cortex-M4F of mps2-an386. */
#include "startup.h"
void SysTick_Handler(void);
void UART0RX_Handler(void);
void UART1RX_Handler(void);
void TIMER0_Handler(void);

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

#define N_IRQ 32

__attribute__((section(".isr_vector"), used)) const vector_entry vector_table[16 + N_IRQ] = {
    { .stack = &_estack },
    { .handler = Reset_Handler },
    { .handler = Default_Handler }, /* NMI */
    { .handler = Default_Handler }, /* HardFault */
    { .handler = Default_Handler }, /* MemManage */
    { .handler = Default_Handler }, /* BusFault */
    { .handler = Default_Handler }, /* UsageFault */
    { .handler = 0 },
    { .handler = 0 },
    { .handler = 0 },
    { .handler = 0 },
    { .handler = Default_Handler }, /* SVCall */
    { .handler = Default_Handler }, /* DebugMonitor */
    { .handler = 0 },
    { .handler = Default_Handler }, /* PendSV */
    { .handler = SysTick_Handler },
    { .handler = UART0RX_Handler }, /* IRQ 0: UART0 RX */
    { .handler = Default_Handler }, /* IRQ 1: UART0 TX (not enabled); the others not named likewise */
    { .handler = UART1RX_Handler }, /* IRQ 2: UART1 RX (the I2C bridge) */
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = TIMER0_Handler }, /* IRQ 8: TIMER0 (the alarm of a sleep with a time limit) */
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
    /* full access to CP10 and CP11 (the FPU) before any floating-point instruction */
    SCB_CPACR |= 0xFu << 20;
    __asm__ __volatile__("dsb\n\tisb" ::: "memory");
    (void)main(0, 0);
    for (;;) {
    }
}

void Default_Handler(void)
{
    startup_halt();
}
