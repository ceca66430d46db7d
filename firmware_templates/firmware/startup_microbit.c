/* startup_microbit.c: the Cortex-M0 of the nRF51822 (QEMU microbit): its handlers (hal_microbit.c) in the
 * vector table of startup.h. The nRF51 has no SysTick. */
void UART0_Handler(void);
void TIMER0_Handler(void);

#define STARTUP_IRQ2 UART0_Handler  /* UART0 (IRQ 0 is POWER_CLOCK, IRQ 1 RADIO) */
#define STARTUP_IRQ8 TIMER0_Handler /* TIMER0 */
#include "startup.h"
