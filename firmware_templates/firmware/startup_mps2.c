/* startup_mps2.c: the Cortex-M4F of mps2-an386: its handlers (hal_mps2.c) in the vector table of startup.h. */
void SysTick_Handler(void);
void UART0RX_Handler(void);
void UART1RX_Handler(void);
void TIMER0_Handler(void);

#define STARTUP_SYSTICK SysTick_Handler
#define STARTUP_IRQ0 UART0RX_Handler /* UART0 RX */
#define STARTUP_IRQ2 UART1RX_Handler /* UART1 RX (the I2C bridge); IRQ 1, UART0 TX, is not enabled */
#define STARTUP_IRQ8 TIMER0_Handler  /* TIMER0 (the alarm of a sleep with a time limit) */
#include "startup.h"
