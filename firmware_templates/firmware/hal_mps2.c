/* hal_mps2.c: QEMU's mps2-an386 board (Cortex-M4F, ARM AN386 FPGA image).
 * Serial link: CMSDK APB UART0 at 0x40004000, polled; its RX interrupt (IRQ 0) only wakes WFI.
 * Ticks: SysTick on the processor clock (SYSCLK 25 MHz), 24-bit, its wraps counted in
 * SysTick_Handler to give 64 bits. Under `qemu-system-arm -icount shift=S` one instruction takes
 * 2^S ns of virtual time, so instructions = ticks * (1e9 / 25e6) / 2^S (40 per tick at S = 0).
 */
#include "hal.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

#define UART0_BASE 0x40004000u
#define UART_DATA REG(UART0_BASE + 0x00u)
#define UART_STATE REG(UART0_BASE + 0x04u)
#define UART_CTRL REG(UART0_BASE + 0x08u)
#define UART_INTCLEAR REG(UART0_BASE + 0x0Cu)
#define UART_BAUDDIV REG(UART0_BASE + 0x10u)
#define UART_STATE_TX_FULL 0x1u
#define UART_STATE_RX_FULL 0x2u
#define UART_CTRL_TX_EN 0x1u
#define UART_CTRL_RX_EN 0x2u
#define UART_CTRL_RX_INT_EN 0x8u
#define UART_INT_RX 0x2u

#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define SCB_ICSR REG(0xE000ED04u)
#define ICSR_PENDSTSET (1u << 26)
#define NVIC_ISER0 REG(0xE000E100u)
#define UART0_RX_IRQ 0u

#define SYSCLK_HZ 25000000u
#define SYSTICK_BITS 24u
#define SYSTICK_MAX 0xFFFFFFu

static volatile uint32_t systick_wraps;

void SysTick_Handler(void);
void UART0RX_Handler(void);

void SysTick_Handler(void)
{
    systick_wraps = systick_wraps + 1u;
}

void UART0RX_Handler(void)
{
    UART_INTCLEAR = UART_INT_RX; /* the byte stays in DATA for hal_poll_byte */
}

void hal_init(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    UART_BAUDDIV = 16u; /* the smallest divider the UART accepts */
    UART_CTRL = UART_CTRL_TX_EN | UART_CTRL_RX_EN | UART_CTRL_RX_INT_EN;
    NVIC_ISER0 = 1u << UART0_RX_IRQ;
    SYST_RVR = SYSTICK_MAX;
    SYST_CVR = 0;
    SYST_CSR = 0x7u; /* enable, interrupt on wrap, processor clock */
}

int hal_alive(void)
{
    return 1;
}

int hal_poll_byte(uint8_t *b)
{
    if (UART_STATE & UART_STATE_RX_FULL) {
        *b = (uint8_t)UART_DATA;
        return 1;
    }
    return 0;
}

void hal_write(const uint8_t *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        while (UART_STATE & UART_STATE_TX_FULL) {
        }
        UART_DATA = p[i];
    }
}

uint64_t hal_ticks(void)
{
    for (;;) {
        uint32_t wraps = systick_wraps;
        uint32_t value = SYST_CVR;
        if (SCB_ICSR & ICSR_PENDSTSET) {
            /* wrapped, handler not run yet: the value read now is past the wrap */
            value = SYST_CVR;
            wraps += 1u;
            if (systick_wraps + 1u != wraps) {
                continue; /* the handler ran meanwhile */
            }
        } else if (systick_wraps != wraps) {
            continue;
        }
        return ((uint64_t)wraps << SYSTICK_BITS) + (SYSTICK_MAX - value);
    }
}

uint32_t hal_tick_hz(void)
{
    return SYSCLK_HZ;
}

uint32_t hal_millis(void)
{
    return (uint32_t)(hal_ticks() / (SYSCLK_HZ / 1000u));
}

/* the I2C bridge's channel: CMSDK UART1, polled (the emulator's second serial port) */
#define UART1_BASE 0x40005000u
#define UART1_DATA REG(UART1_BASE + 0x00u)
#define UART1_STATE REG(UART1_BASE + 0x04u)
#define UART1_CTRL REG(UART1_BASE + 0x08u)
#define UART1_BAUDDIV REG(UART1_BASE + 0x10u)

void hal_bridge_write(const uint8_t *p, size_t n)
{
    size_t i;
    if (!(UART1_CTRL & UART_CTRL_TX_EN)) {
        UART1_BAUDDIV = 16u;
        UART1_CTRL = UART_CTRL_TX_EN | UART_CTRL_RX_EN;
    }
    for (i = 0; i < n; ++i) {
        while (UART1_STATE & UART_STATE_TX_FULL) {
        }
        UART1_DATA = p[i];
    }
}

int hal_bridge_read_byte(uint8_t *b, uint32_t timeout_ms)
{
    const uint32_t start = hal_millis();
    while (!(UART1_STATE & UART_STATE_RX_FULL)) {
        if (hal_millis() - start > timeout_ms) {
            return 0;
        }
    }
    *b = (uint8_t)UART1_DATA;
    return 1;
}

void hal_idle(uint32_t max_ms)
{
    if (max_ms != HAL_IDLE_FOREVER) {
        return; /* a stream sample is due soon: keep polling */
    }
    /* sleep until an interrupt (a received byte, or a SysTick wrap every 0.67 s); with interrupts
     * masked a byte arriving between the test and WFI still ends the WFI */
    __asm__ __volatile__("cpsid i" ::: "memory");
    if (!(UART_STATE & UART_STATE_RX_FULL)) {
        __asm__ __volatile__("wfi" ::: "memory");
    }
    __asm__ __volatile__("cpsie i" ::: "memory");
}
