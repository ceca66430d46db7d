/* startup_microbit.c: vector table and reset handler for the Cortex-M0 of the nRF51822 (QEMU microbit). */
#include <stdint.h>

extern uint32_t _sidata; /* .data's image in flash */
extern uint32_t _sdata;
extern uint32_t _edata;
extern uint32_t _sbss;
extern uint32_t _ebss;
extern uint32_t _estack;

int main(int argc, char **argv);
void Reset_Handler(void);
void Default_Handler(void);
void UART0_Handler(void);
void TIMER0_Handler(void);

typedef union {
    void (*handler)(void);
    uint32_t *stack;
} vector_entry;

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
    uint32_t *src = &_sidata;
    uint32_t *dst = &_sdata;
    while (dst < &_edata) {
        *dst++ = *src++;
    }
    for (dst = &_sbss; dst < &_ebss;) {
        *dst++ = 0;
    }
    (void)main(0, 0);
    for (;;) {
    }
}

/* an unexpected exception is a firmware bug: stop here, where a debugger finds it */
void Default_Handler(void)
{
    for (;;) {
    }
}
