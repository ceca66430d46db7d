/* hal_microbit.c: QEMU's microbit (nRF51822: Cortex-M0, ARMv6-M, no FPU, 16 KB RAM): the
 * fixed-point firmware's port. Serial link: UART0 (0x40002000), polled; its RXDRDY interrupt only
 * wakes WFI. Ticks: TIMER0 in 32-bit mode at 16 MHz (prescaler 0), its wraps counted by a compare
 * interrupt at 0 to give 64 bits (the nRF51 has no SysTick). Under `-icount shift=S` one
 * instruction takes 2^S ns, so instructions = ticks * 62.5 / 2^S. The nRF51 has one UART: this
 * port has no I2C bridge (inputs are simulated; a board reads its ADCs through hal_i2c()). */
#include "hal.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

#define UART0 0x40002000u
#define UART_STARTRX REG(UART0 + 0x000u)
#define UART_STARTTX REG(UART0 + 0x008u)
#define UART_RXDRDY REG(UART0 + 0x108u)
#define UART_TXDRDY REG(UART0 + 0x11Cu)
#define UART_INTENSET REG(UART0 + 0x304u)
#define UART_ENABLE REG(UART0 + 0x500u)
#define UART_RXD REG(UART0 + 0x518u)
#define UART_TXD REG(UART0 + 0x51Cu)
#define UART_BAUDRATE REG(UART0 + 0x524u)
#define UART_INT_RXDRDY (1u << 2)
#define UART_BAUD_115200 0x01D7E000u

#define TIMER0 0x40008000u
#define TIMER_START REG(TIMER0 + 0x000u)
#define TIMER_CLEAR REG(TIMER0 + 0x00Cu)
#define TIMER_CAPTURE0 REG(TIMER0 + 0x040u)
#define TIMER_COMPARE1 REG(TIMER0 + 0x144u)
#define TIMER_INTENSET REG(TIMER0 + 0x304u)
#define TIMER_MODE REG(TIMER0 + 0x504u)
#define TIMER_BITMODE REG(TIMER0 + 0x508u)
#define TIMER_PRESCALER REG(TIMER0 + 0x510u)
#define TIMER_CC0 REG(TIMER0 + 0x540u)
#define TIMER_CC1 REG(TIMER0 + 0x544u)
#define TIMER_INT_COMPARE1 (1u << 17)

#define NVIC_ISER REG(0xE000E100u)
#define NVIC_ISPR REG(0xE000E200u)
#define IRQ_UART0 2u
#define IRQ_TIMER0 8u

#define TICK_HZ 16000000u

static volatile uint32_t timer_wraps;

void UART0_Handler(void);
void TIMER0_Handler(void);

void UART0_Handler(void)
{
    /* RXDRDY stays set for hal_poll_byte; mask the interrupt until the byte is taken */
    REG(UART0 + 0x308u) = UART_INT_RXDRDY; /* INTENCLR */
}

void TIMER0_Handler(void)
{
    TIMER_COMPARE1 = 0;
    timer_wraps = timer_wraps + 1u;
}

void hal_init(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    UART_BAUDRATE = UART_BAUD_115200;
    UART_ENABLE = 4u;
    UART_STARTRX = 1u;
    UART_STARTTX = 1u;
    UART_INTENSET = UART_INT_RXDRDY;
    TIMER_MODE = 0u;      /* timer */
    TIMER_BITMODE = 3u;   /* 32 bit */
    TIMER_PRESCALER = 0u; /* 16 MHz */
    TIMER_CC1 = 0u;       /* a compare event at every wrap */
    TIMER_INTENSET = TIMER_INT_COMPARE1;
    TIMER_CLEAR = 1u;
    TIMER_START = 1u;
    NVIC_ISER = (1u << IRQ_UART0) | (1u << IRQ_TIMER0);
}

int hal_alive(void)
{
    return 1;
}

int hal_poll_byte(uint8_t *b)
{
    if (UART_RXDRDY) {
        UART_RXDRDY = 0;
        *b = (uint8_t)UART_RXD;
        UART_INTENSET = UART_INT_RXDRDY;
        return 1;
    }
    return 0;
}

void hal_write(const uint8_t *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        unsigned spins = 0;
        UART_TXDRDY = 0;
        UART_TXD = p[i];
        /* the byte is out when TXDRDY rises; the bound keeps a stuck UART from hanging the loop */
        while (!UART_TXDRDY && ++spins < 100000u) {
        }
    }
}

uint64_t hal_ticks(void)
{
    for (;;) {
        const uint32_t wraps = timer_wraps;
        uint32_t value;
        TIMER_CAPTURE0 = 1u;
        value = TIMER_CC0;
        if (timer_wraps != wraps) {
            continue; /* the handler ran meanwhile */
        }
        if ((NVIC_ISPR & (1u << IRQ_TIMER0)) && value < 0x80000000u) {
            /* wrapped, handler not run yet (interrupts masked): count the wrap here */
            return ((uint64_t)(wraps + 1u) << 32) + value;
        }
        return ((uint64_t)wraps << 32) + value;
    }
}

uint32_t hal_tick_hz(void)
{
    return TICK_HZ;
}

uint32_t hal_millis(void)
{
    return (uint32_t)(hal_ticks() / (TICK_HZ / 1000u));
}

void hal_idle(uint32_t max_ms)
{
    if (max_ms != HAL_IDLE_FOREVER) {
        return; /* a stream sample is due soon: keep polling */
    }
    /* sleep until an interrupt (a received byte, or a timer wrap); with interrupts masked a byte
     * arriving between the test and WFI still ends the WFI */
    __asm__ __volatile__("cpsid i" ::: "memory");
    if (!UART_RXDRDY) {
        __asm__ __volatile__("wfi" ::: "memory");
    }
    __asm__ __volatile__("cpsie i" ::: "memory");
}

void hal_bridge_write(const uint8_t *p, size_t n)
{
    (void)p;
    (void)n;
}

int hal_bridge_read_byte(uint8_t *b, uint32_t timeout_ms)
{
    (void)b;
    (void)timeout_ms;
    return 0;
}
