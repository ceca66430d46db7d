/* startup.h: what every bare-metal port's reset handler does first, before main(): copy .data's
 * image from flash and clear .bss (the symbols come from the port's linker script). */
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

/* a vector table entry: the initial stack pointer first, then handlers */
typedef union {
    void (*handler)(void);
    uint32_t *stack;
} vector_entry;

void Reset_Handler(void);
void Default_Handler(void);

static inline void startup_init_memory(void)
{
    uint32_t *src = &_sidata;
    uint32_t *dst = &_sdata;
    while (dst < &_edata) {
        *dst++ = *src++;
    }
    for (dst = &_sbss; dst < &_ebss;) {
        *dst++ = 0;
    }
}

/* an unexpected exception is a firmware bug: stop here, where a debugger finds it */
static inline void startup_halt(void)
{
    for (;;) {
    }
}

#endif /* STARTUP_H */
