/* startup.h: the vector table and reset handler every bare-metal port shares (Cortex-M0 microbit,
 * Cortex-M4F mps2-an386). Included once, by the port's startup_<port>.c, after it has named its
 * handlers: STARTUP_SYSTICK and STARTUP_IRQ0, STARTUP_IRQ2, STARTUP_IRQ8 (the slots some port uses);
 * every slot it leaves unnamed halts in Default_Handler. The reset handler copies .data's image from
 * flash, clears .bss (the symbols come from the port's linker script), turns the FPU on where the
 * core has one, then calls main(). */
#ifndef STARTUP_H
#define STARTUP_H

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

#ifndef STARTUP_SYSTICK
#define STARTUP_SYSTICK Default_Handler
#endif
#ifndef STARTUP_IRQ0
#define STARTUP_IRQ0 Default_Handler
#endif
#ifndef STARTUP_IRQ2
#define STARTUP_IRQ2 Default_Handler
#endif
#ifndef STARTUP_IRQ8
#define STARTUP_IRQ8 Default_Handler
#endif

#define N_IRQ 32
#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

/* MemManage, BusFault, UsageFault and DebugMonitor came with ARMv7-M; ARMv6-M (Cortex-M0) reserves their slots */
#if defined(__ARM_ARCH) && __ARM_ARCH >= 7
#define V7M_HANDLER Default_Handler
#else
#define V7M_HANDLER 0
#endif

/* a vector table entry: the initial stack pointer first, then handlers */
typedef union {
    void (*handler)(void);
    uint32_t *stack;
} vector_entry;

__attribute__((section(".isr_vector"), used)) const vector_entry vector_table[16 + N_IRQ] = {
    { .stack = &_estack },
    { .handler = Reset_Handler },
    { .handler = Default_Handler }, /* NMI */
    { .handler = Default_Handler }, /* HardFault */
    { .handler = V7M_HANDLER },     /* MemManage */
    { .handler = V7M_HANDLER },     /* BusFault */
    { .handler = V7M_HANDLER },     /* UsageFault */
    { .handler = 0 }, { .handler = 0 }, { .handler = 0 }, { .handler = 0 },
    { .handler = Default_Handler }, /* SVCall */
    { .handler = V7M_HANDLER },     /* DebugMonitor */
    { .handler = 0 },
    { .handler = Default_Handler }, /* PendSV */
    { .handler = STARTUP_SYSTICK },
    { .handler = STARTUP_IRQ0 },
    { .handler = Default_Handler },
    { .handler = STARTUP_IRQ2 },
    { .handler = Default_Handler }, { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = Default_Handler }, { .handler = Default_Handler },
    { .handler = STARTUP_IRQ8 },
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
#if defined(__ARM_FP)
    /* full access to CP10 and CP11 (the FPU) before any floating-point instruction */
    SCB_CPACR |= 0xFu << 20;
    __asm__ __volatile__("dsb\n\tisb" ::: "memory");
#endif
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

#endif /* STARTUP_H */
