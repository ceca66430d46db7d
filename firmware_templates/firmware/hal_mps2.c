/* hal_mps2.c: QEMU's mps2-an386 board (Cortex-M4F, ARM AN386 FPGA image).
 * Serial link: CMSDK APB UART0 at 0x40004000, polled; its RX interrupt (IRQ 0) only wakes WFI.
 * I2C bridge (ADC builds): UART1 at 0x40005000, polled; its RX interrupt (IRQ 2) only wakes WFI.
 * A UART's RX interrupt is enabled only while the core sleeps waiting for it.
 * Ticks: SysTick on the processor clock (SYSCLK 25 MHz), 24-bit, its wraps counted in
 * SysTick_Handler to give 64 bits. Under `qemu-system-arm -icount shift=S` one instruction takes
 * 2^S ns of virtual time, so instructions = ticks * (1e9 / 25e6) / 2^S (40 per tick at S = 0).
 * Waits with a time limit (the next stream sample, a bridge answer) sleep in WFI with CMSDK TIMER0
 * (IRQ 8) as the alarm instead of polling: under -icount a polling core runs its virtual clock on
 * instructions, and a 10 ms wait costs 0.2-0.3 s of wall time; asleep, QEMU moves the virtual clock
 * with the wall clock (docs/hil.md).
 */
#include "hal.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

#define UART0_BASE 0x40004000u
#define UART_STATE_OFFSET 0x04u
#define UART_CTRL_OFFSET 0x08u
#define UART_DATA REG(UART0_BASE + 0x00u)
#define UART_STATE REG(UART0_BASE + UART_STATE_OFFSET)
#define UART_CTRL REG(UART0_BASE + UART_CTRL_OFFSET)
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
#define UART1_RX_IRQ 2u
#define TIMER0_IRQ 8u

/* the I2C bridge's channel: CMSDK UART1 (the emulator's second serial port) */
#define UART1_BASE 0x40005000u
#define UART1_DATA REG(UART1_BASE + 0x00u)
#define UART1_STATE REG(UART1_BASE + 0x04u)
#define UART1_CTRL REG(UART1_BASE + 0x08u)
#define UART1_INTCLEAR REG(UART1_BASE + 0x0Cu)
#define UART1_BAUDDIV REG(UART1_BASE + 0x10u)

/* the alarm that ends a sleep with a time limit: CMSDK APB TIMER0, counting down at SYSCLK */
#define TIMER0_BASE 0x40000000u
#define TIMER0_CTRL REG(TIMER0_BASE + 0x00u)
#define TIMER0_VALUE REG(TIMER0_BASE + 0x04u)
#define TIMER0_RELOAD REG(TIMER0_BASE + 0x08u)
#define TIMER0_INTCLEAR REG(TIMER0_BASE + 0x0Cu)
#define TIMER_CTRL_EN 0x1u
#define TIMER_CTRL_IRQ_EN 0x8u
#define ALARM_MAX_MS 1000u /* a longer wait sleeps again after the alarm */

#define SYSCLK_HZ 25000000u
#define SYSTICK_BITS 24u
#define SYSTICK_MAX 0xFFFFFFu

static volatile uint32_t systick_wraps;

void SysTick_Handler(void);
void UART0RX_Handler(void);
void UART1RX_Handler(void);
void TIMER0_Handler(void);

void SysTick_Handler(void)
{
    systick_wraps = systick_wraps + 1u;
}

void UART0RX_Handler(void)
{
    UART_INTCLEAR = UART_INT_RX; /* the byte stays in DATA for hal_poll_byte */
}

void UART1RX_Handler(void)
{
    UART1_INTCLEAR = UART_INT_RX; /* the byte stays in DATA for hal_bridge_read_byte */
}

void TIMER0_Handler(void)
{
    TIMER0_INTCLEAR = 1u;
}

void hal_init(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    UART_BAUDDIV = 16u; /* the smallest divider the UART accepts */
    UART_CTRL = UART_CTRL_TX_EN | UART_CTRL_RX_EN;
    /* the bridge's UART from the start: QEMU stops watching a serial port's socket while its UART cannot
     * take a byte, and enabling the UART does not wake QEMU's main loop, so a UART enabled at the first
     * request left the first answer unread until the main loop woke for something else (1-17 s of wall
     * time after boot, docs/hil.md) */
    UART1_BAUDDIV = 16u;
    UART1_CTRL = UART_CTRL_TX_EN | UART_CTRL_RX_EN;
    TIMER0_CTRL = 0;
    NVIC_ISER0 = (1u << UART0_RX_IRQ) | (1u << UART1_RX_IRQ) | (1u << TIMER0_IRQ);
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

/* sleep until the UART at `uart` has a byte (its RX interrupt is enabled only meanwhile: a byte taken by
 * polling costs no interrupt), a SysTick wrap (every 0.67 s), or, unless max_ms is HAL_IDLE_FOREVER, the
 * alarm after max_ms (at most ALARM_MAX_MS). The UART is tested with interrupts masked, so a byte
 * arriving between the test and WFI still ends the WFI. */
static void sleep_until(uint32_t max_ms, uint32_t uart)
{
    if (max_ms != HAL_IDLE_FOREVER) {
        const uint32_t ms = max_ms < ALARM_MAX_MS ? max_ms : ALARM_MAX_MS;
        TIMER0_CTRL = 0;
        TIMER0_RELOAD = ms * (SYSCLK_HZ / 1000u);
        TIMER0_VALUE = ms * (SYSCLK_HZ / 1000u);
        TIMER0_INTCLEAR = 1u;
        TIMER0_CTRL = TIMER_CTRL_EN | TIMER_CTRL_IRQ_EN;
    }
    __asm__ __volatile__("cpsid i" ::: "memory");
    REG(uart + UART_CTRL_OFFSET) = UART_CTRL_TX_EN | UART_CTRL_RX_EN | UART_CTRL_RX_INT_EN;
    if (!(REG(uart + UART_STATE_OFFSET) & UART_STATE_RX_FULL)) {
        __asm__ __volatile__("wfi" ::: "memory");
    }
    REG(uart + UART_CTRL_OFFSET) = UART_CTRL_TX_EN | UART_CTRL_RX_EN;
    __asm__ __volatile__("cpsie i" ::: "memory"); /* a pending interrupt is taken (and cleared) here */
    if (max_ms != HAL_IDLE_FOREVER) {
        TIMER0_CTRL = 0;
    }
}

void hal_bridge_write(const uint8_t *p, size_t n)
{
    size_t i;
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
        const uint32_t waited = hal_millis() - start;
        if (waited > timeout_ms) {
            return 0;
        }
        sleep_until(timeout_ms - waited + 1u, UART1_BASE);
    }
    *b = (uint8_t)UART1_DATA;
    return 1;
}

void hal_idle(uint32_t max_ms)
{
    /* until a byte arrives or, while a stream runs, its next sample is due */
    if (max_ms == 0u) {
        return;
    }
    sleep_until(max_ms, UART0_BASE);
}
