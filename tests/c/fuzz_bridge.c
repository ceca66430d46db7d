/* libFuzzer harness for firmware_templates/firmware/i2c_bridge.c: the emulated boards' I2C, answered over a
 * byte channel by a peer outside the firmware. The first bytes choose a transfer; the rest is the peer's
 * answer line, as it arrives. Built with sanitizers (tests/test_sanitizers.py), it also checks what a transfer
 * returns against the protocol: OK with bytes only for "OK " and two hex digits a byte, the errno's kind only
 * for "E " and at most nine digits, a clock that never runs back. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define HAL_H /* hal.h would bring the model's header in: the bridge needs only its two byte-channel calls */
#include "adc.h"
void hal_bridge_write(const uint8_t *p, size_t n);
int hal_bridge_read_byte(uint8_t *b, uint32_t timeout_ms);
#include "i2c_bridge.c"

static const uint8_t *answer_p;
static size_t answer_n, answer_pos;

void hal_bridge_write(const uint8_t *p, size_t n)
{
    if (n == 0 || p[n - 1] != '\n') {
        abort(); /* every request is one line */
    }
    answer_pos = 0;
}

int hal_bridge_read_byte(uint8_t *b, uint32_t timeout_ms)
{
    (void)timeout_ms;
    if (answer_pos >= answer_n) {
        return 0; /* the peer said no more: a timeout */
    }
    *b = answer_p[answer_pos++];
    return 1;
}

static int hexdigit(uint8_t c)
{
    return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
}

/* the answer's line: the bytes before its newline, or -1 without one (a timeout) */
static long line_length(void)
{
    const uint8_t *nl = memchr(answer_p, '\n', answer_n);
    return nl ? (long)(nl - answer_p) : -1;
}

static void check_read(int st, const uint8_t *rd, uint16_t nr)
{
    const long len = line_length();
    uint16_t i;
    if (st != ADC_I2C_OK) {
        if (len >= 0 && len == 3 + 2 * (long)nr && nr <= 32u && answer_p[0] == 'O' && answer_p[1] == 'K'
            && answer_p[2] == ' ') {
            int all_hex = 1;
            for (i = 0; i < 2u * nr; ++i) {
                all_hex &= hexdigit(answer_p[3u + i]);
            }
            if (all_hex) {
                abort(); /* a well-formed answer refused */
            }
        }
        return;
    }
    if (len != 3 + 2 * (long)nr || answer_p[0] != 'O' || answer_p[1] != 'K' || answer_p[2] != ' ') {
        abort(); /* bytes "read" that the answer did not hold */
    }
    for (i = 0; i < nr; ++i) {
        const char pair[3] = { (char)answer_p[3u + 2u * i], (char)answer_p[4u + 2u * i], 0 };
        if (!hexdigit((uint8_t)pair[0]) || !hexdigit((uint8_t)pair[1]) || rd[i] != strtoul(pair, NULL, 16)) {
            abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const adc_i2c *bus = hal_i2c();
    uint8_t wr[40], rd[40];
    uint16_t nw, nr;
    unsigned op;
    int st;
    if (size < 3) {
        return 0;
    }
    op = data[0] % 5u;
    nw = (uint16_t)(data[1] % 34u); /* 33: past the bridge's 32, refused before a line is sent */
    nr = (uint16_t)(data[2] % 34u);
    answer_p = data + 3;
    answer_n = size - 3;
    memset(wr, 0x5a, sizeof wr);
    memset(rd, 0, sizeof rd);
    switch (op) {
    case 0:
        st = bus->write(bus->ctx, 0x48, wr, nw);
        if (st == ADC_I2C_OK && (nw > 32u || line_length() < 2)) {
            abort();
        }
        break;
    case 1:
        if (nr == 0) {
            break;
        }
        st = bus->read(bus->ctx, 0x48, rd, nr);
        if (nr <= 32u) {
            check_read(st, rd, nr);
        } else if (st == ADC_I2C_OK) {
            abort();
        }
        break;
    case 2:
        if (nw == 0 || nr == 0) {
            break;
        }
        st = bus->write_read(bus->ctx, 0x48, wr, nw, rd, nr);
        if (nw <= 32u && nr <= 32u) {
            check_read(st, rd, nr);
        } else if (st == ADC_I2C_OK) {
            abort();
        }
        break;
    case 3: {
        const uint64_t before = last_ns, now = bus->now_ns(bus->ctx);
        if (now < before) {
            abort(); /* time ran back */
        }
        break;
    }
    default:
        bus->sleep_ns(bus->ctx, 1000u);
        break;
    }
    return 0;
}
