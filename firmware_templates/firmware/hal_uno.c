/* hal_uno.c: the Arduino Uno (ATmega328P at 16 MHz), avr-libc only, no Arduino core.
 * Serial link: USART0 at 1,000,000 baud (U2X, UBRR 1: exact at 16 MHz; the Uno's USB bridge takes it),
 * 8N1. Received bytes go into a ring by the RX interrupt, so that a request arriving while an estimate
 * runs (tens of ms in float) is not lost in the UART's 2-byte buffer. A full ring turns the interrupt off
 * until a byte is taken: what comes meanwhile waits in the UART (in simavr, flow control holds it back;
 * on a board, a host that waits for each reply never fills the ring).
 * Ticks: Timer1 counting the CPU clock, its overflows (every 4.096 ms) counted to 64 bits.
 * I2C: the TWI at 400 kHz, master only, for the ADC drivers (hal_i2c); every wait for the bus ends
 * within TWI_TIMEOUT_US, after which the TWI is reset and the transfer reported as a timeout. Each step
 * ends in the TWI interrupt, as in Arduino's Wire (twi.c), not in polling TWINT: simavr 1.6 keeps
 * TWINT set in TWCR once raised (its vector is "sticky"), so only the interrupt tells a step is done.
 * Idle: the core sleeps (idle mode) until a byte arrives or Timer1 overflows.
 * Runs on a Uno as it runs in simavr (tactile-hil emulate --target uno, firmware_templates/avr/uno_board.c).
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <util/twi.h>

#include "hal.h"

#define BAUD_UBRR 1u     /* F_CPU / (8 * (UBRR + 1)) = 1 Mbaud with U2X0 */
#define RX_RING 64u      /* a power of two */
#define TWI_BITRATE 12u  /* F_CPU / (16 + 2 * 12) = 400 kHz, prescaler 1 */
#define TWI_TIMEOUT_US 2000u
#define TICKS_PER_US (F_CPU / 1000000UL)

static volatile uint8_t ring[RX_RING];
static volatile uint8_t ring_head; /* written by the interrupt */
static volatile uint8_t ring_tail;
static volatile uint32_t wraps;
static volatile uint8_t twi_done;

ISR(USART_RX_vect)
{
    const uint8_t next = (uint8_t)((ring_head + 1u) & (RX_RING - 1u));
    if (next == ring_tail) {
        UCSR0B = (uint8_t)(UCSR0B & ~_BV(RXCIE0)); /* full: the byte stays in UDR0 until there is room */
        return;
    }
    ring[ring_head] = UDR0;
    ring_head = next;
}

ISR(TIMER1_OVF_vect)
{
    wraps = wraps + 1u;
}

ISR(TWI_vect)
{
    /* TWIE off, TWINT left set (a 0 written there changes nothing): twi_go reads the status and goes on */
    TWCR = (uint8_t)(TWCR & ~(_BV(TWIE) | _BV(TWINT)));
    twi_done = 1;
}

void hal_init(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    UCSR0A = (uint8_t)_BV(U2X0);
    UBRR0H = (uint8_t)(BAUD_UBRR >> 8);
    UBRR0L = (uint8_t)BAUD_UBRR;
    UCSR0C = (uint8_t)(_BV(UCSZ01) | _BV(UCSZ00));
    UCSR0B = (uint8_t)(_BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0));
    TCCR1A = 0;
    TCCR1B = (uint8_t)_BV(CS10); /* the CPU clock, no prescaler */
    TIMSK1 = (uint8_t)_BV(TOIE1);
    TWSR = 0;
    TWBR = TWI_BITRATE;
    TWCR = (uint8_t)_BV(TWEN);
    sei();
}

int hal_alive(void)
{
    return 1;
}

int hal_poll_byte(uint8_t *b)
{
    if (ring_tail == ring_head) {
        return 0;
    }
    *b = ring[ring_tail];
    ring_tail = (uint8_t)((ring_tail + 1u) & (RX_RING - 1u));
    UCSR0B = (uint8_t)(UCSR0B | _BV(RXCIE0)); /* room again (a no-op unless the ring was full) */
    return 1;
}

void hal_write(const uint8_t *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        loop_until_bit_is_set(UCSR0A, UDRE0); /* the UART empties it within one byte time (10 us) */
        UDR0 = p[i];
    }
}

uint64_t hal_ticks(void)
{
    const uint8_t sreg = SREG;
    uint32_t w;
    uint16_t t;
    cli();
    w = wraps;
    t = TCNT1;
    if ((TIFR1 & _BV(TOV1)) && t < 0x8000u) {
        w += 1u; /* wrapped, its interrupt not yet taken: the count read is past the wrap */
    }
    SREG = sreg;
    return ((uint64_t)w << 16) | t;
}

uint32_t hal_tick_hz(void)
{
    return F_CPU;
}

uint32_t hal_millis(void)
{
    return (uint32_t)(hal_ticks() / (F_CPU / 1000UL));
}

void hal_idle(uint32_t max_ms)
{
    if (max_ms == 0u) {
        return;
    }
    /* interrupts off between the test and SLEEP: a byte that arrives in between still wakes the core
     * (the instruction after SEI runs before any interrupt) */
    set_sleep_mode(SLEEP_MODE_IDLE);
    cli();
    if (ring_tail == ring_head) {
        sleep_enable();
        sei();
        sleep_cpu();
        sleep_disable();
    }
    sei();
}

/* --- I2C: the TWI as master -------------------------------------------------------------- */

static uint64_t deadline(void)
{
    return hal_ticks() + (uint64_t)TWI_TIMEOUT_US * TICKS_PER_US;
}

/* the step within the time limit: the status (TW_STATUS), or -1 after resetting the TWI */
static int twi_go(uint8_t control)
{
    const uint64_t end = deadline();
    twi_done = 0;
    TWCR = (uint8_t)(control | _BV(TWINT) | _BV(TWEN) | _BV(TWIE));
    while (!twi_done) {
        if (hal_ticks() > end) {
            TWCR = 0; /* a stuck bus: release it and start afresh */
            TWCR = (uint8_t)_BV(TWEN);
            return -1;
        }
    }
    return TW_STATUS;
}

static void twi_stop(void)
{
    const uint64_t end = deadline();
    TWCR = (uint8_t)(_BV(TWINT) | _BV(TWEN) | _BV(TWSTO));
    while ((TWCR & _BV(TWSTO)) && hal_ticks() <= end) {
    }
}

/* START (or a repeated one) and the address byte; ADC_I2C_* */
static int twi_address(uint8_t addr, uint8_t read)
{
    int st = twi_go(_BV(TWSTA));
    if (st != TW_START && st != TW_REP_START) {
        return st < 0 ? ADC_I2C_TIMEOUT : ADC_I2C_OTHER;
    }
    TWDR = (uint8_t)((addr << 1) | read);
    st = twi_go(0);
    if (st < 0) {
        return ADC_I2C_TIMEOUT;
    }
    /* an acknowledged SLA+W is 0x18; simavr 1.6 reports 0x28 (data acknowledged) when TWDR was written
     * before TWINT was cleared, as it must be: both taken, as Arduino's Wire (twi.c) takes both */
    if (read ? st == TW_MR_SLA_ACK : (st == TW_MT_SLA_ACK || st == TW_MT_DATA_ACK)) {
        return ADC_I2C_OK;
    }
    return st == TW_MR_SLA_NACK || st == TW_MT_SLA_NACK ? ADC_I2C_NACK : ADC_I2C_OTHER;
}

static int twi_send(const uint8_t *data, uint16_t n)
{
    uint16_t i;
    for (i = 0; i < n; ++i) {
        int st;
        TWDR = data[i];
        st = twi_go(0);
        if (st != TW_MT_DATA_ACK) {
            return st < 0 ? ADC_I2C_TIMEOUT : st == TW_MT_DATA_NACK ? ADC_I2C_NACK : ADC_I2C_OTHER;
        }
    }
    return ADC_I2C_OK;
}

static int twi_receive(uint8_t *data, uint16_t n)
{
    uint16_t i;
    for (i = 0; i < n; ++i) {
        const uint8_t last = (uint8_t)(i + 1u == n);
        const int st = twi_go(last ? 0 : _BV(TWEA)); /* ACK every byte but the last */
        if (st != (last ? TW_MR_DATA_NACK : TW_MR_DATA_ACK)) {
            return st < 0 ? ADC_I2C_TIMEOUT : ADC_I2C_OTHER;
        }
        data[i] = TWDR;
    }
    return ADC_I2C_OK;
}

static int i2c_write_read(void *ctx, uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    int st = ADC_I2C_OK;
    (void)ctx;
    if (nw) {
        st = twi_address(addr, 0);
        if (st == ADC_I2C_OK) {
            st = twi_send(wr, nw);
        }
    }
    if (st == ADC_I2C_OK && nr) {
        st = twi_address(addr, 1);
        if (st == ADC_I2C_OK) {
            st = twi_receive(rd, nr);
        }
    }
    twi_stop();
    return st;
}

static int i2c_write(void *ctx, uint8_t addr, const uint8_t *data, uint16_t n)
{
    return i2c_write_read(ctx, addr, data, n, 0, 0);
}

static int i2c_read(void *ctx, uint8_t addr, uint8_t *data, uint16_t n)
{
    return i2c_write_read(ctx, addr, 0, 0, data, n);
}

static uint64_t i2c_now(void *ctx)
{
    (void)ctx;
    return hal_ticks() * 125u / 2u; /* 62.5 ns a tick */
}

static void i2c_sleep(void *ctx, uint64_t ns)
{
    const uint64_t end = hal_ticks() + ns * 2u / 125u;
    (void)ctx;
    while (hal_ticks() < end) {
    }
}

const adc_i2c *hal_i2c(void)
{
    static const adc_i2c bus = { 0, i2c_write, i2c_read, i2c_write_read, i2c_now, i2c_sleep };
    return &bus;
}
