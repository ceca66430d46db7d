/* i2c_bridge.c: hal_i2c() for the emulated boards: an I2C bus and its clock reached over a byte
 * channel of the port (a second UART on QEMU's mps2-an386, fds 3 and 4 in the host build), answered
 * by host.pi.StandIn from the bus model (host/simbus.py) and a virtual clock, in the protocol of
 * firmware_templates/pi/standin.c:
 *   R <addr> <n> {<flags> <len> <hex or ->}*n -> OK <hex of the bytes read> | E <errno>
 *   M -> OK <ns>        S <ns> -> OK
 * A board with real ADCs implements hal_i2c() against its I2C peripheral instead (docs/hil.md).
 * Every wait for an answer has a time limit; a missing answer is an I2C timeout. */
#include "adc.h"
#include "hal.h"

#define BRIDGE_TIMEOUT_MS 2000u
#define LINE_MAX_LEN 160u
#define ERRNO_EREMOTEIO 121
#define ERRNO_ENXIO 6
#define ERRNO_ETIMEDOUT 110

static uint64_t last_ns; /* the clock's last answer: time never runs back, even after a lost answer */

static size_t put_text(char *p, size_t n, const char *s)
{
    while (*s && n < LINE_MAX_LEN - 1u) {
        p[n++] = *s++;
    }
    return n;
}

static size_t put_uint(char *p, size_t n, uint64_t v)
{
    char digits[24];
    size_t k = 0;
    do {
        digits[k++] = (char)('0' + (int)(v % 10u));
        v /= 10u;
    } while (v && k < sizeof digits);
    while (k && n < LINE_MAX_LEN - 1u) {
        p[n++] = digits[--k];
    }
    return n;
}

static size_t put_hex(char *p, size_t n, uint8_t b)
{
    static const char hex[] = "0123456789abcdef";
    if (n + 2u < LINE_MAX_LEN) {
        p[n++] = hex[b >> 4];
        p[n++] = hex[b & 15u];
    }
    return n;
}

static int hexval(char c)
{
    return c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
}

/* send the request, read the answer line: 1 "OK" or "OK <rest>" (the line's length in *len), 0 "E <errno>"
 * (its number in *err; -1 for an answer the protocol has no word for), -1 no answer in time. Only the
 * line's own characters are read: the answer comes from outside the firmware. */
static int ask(char *line, size_t n, char *answer, size_t *len, int *err)
{
    size_t k = 0, d;
    int v = 0;
    line[n++] = '\n';
    hal_bridge_write((const uint8_t *)line, n);
    for (;;) {
        uint8_t c;
        if (!hal_bridge_read_byte(&c, BRIDGE_TIMEOUT_MS) || k + 1u >= LINE_MAX_LEN) {
            return -1;
        }
        if (c == '\n') {
            break;
        }
        answer[k++] = (char)c;
    }
    answer[k] = 0;
    *len = k;
    if (k >= 2u && answer[0] == 'O' && answer[1] == 'K' && (k == 2u || answer[2] == ' ')) {
        return 1;
    }
    *err = -1;
    if (k < 3u || answer[0] != 'E' || answer[1] != ' ') {
        return 0;
    }
    /* at most 9 digits: an int holds them; a longer number is no errno */
    for (d = 2; d < k && d < 11u && answer[d] >= '0' && answer[d] <= '9'; ++d) {
        v = v * 10 + (answer[d] - '0');
    }
    if (d == k) {
        *err = v;
    }
    return 0;
}

static int transfer(uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    char line[LINE_MAX_LEN], answer[LINE_MAX_LEN];
    size_t n = 0, i, len = 0;
    int err = 0, r;
    if (nw > 32u || nr > 32u) {
        return ADC_I2C_OTHER;
    }
    n = put_text(line, n, "R ");
    n = put_uint(line, n, addr);
    n = put_text(line, n, (nw && nr) ? " 2" : " 1");
    if (nw) {
        n = put_text(line, n, " 0 ");
        n = put_uint(line, n, nw);
        n = put_text(line, n, " ");
        for (i = 0; i < nw; ++i) {
            n = put_hex(line, n, wr[i]);
        }
    }
    if (nr) {
        n = put_text(line, n, " 1 ");
        n = put_uint(line, n, nr);
        n = put_text(line, n, " -");
    }
    r = ask(line, n, answer, &len, &err);
    if (r < 0) {
        return ADC_I2C_TIMEOUT;
    }
    if (r == 0) {
        return err == ERRNO_EREMOTEIO || err == ERRNO_ENXIO ? ADC_I2C_NACK
             : err == ERRNO_ETIMEDOUT ? ADC_I2C_TIMEOUT : ADC_I2C_OTHER;
    }
    if (nr && len != 3u + 2u * nr) { /* "OK " and two hex digits a byte, no fewer: none read past the line */
        return ADC_I2C_OTHER;
    }
    for (i = 0; i < nr; ++i) {
        const int hi = hexval(answer[3u + 2u * i]), lo = hi < 0 ? -1 : hexval(answer[4u + 2u * i]);
        if (hi < 0 || lo < 0) {
            return ADC_I2C_OTHER;
        }
        rd[i] = (uint8_t)(hi * 16 + lo);
    }
    return ADC_I2C_OK;
}

static int bridge_write(void *ctx, uint8_t addr, const uint8_t *data, uint16_t n)
{
    (void)ctx;
    return transfer(addr, data, n, 0, 0);
}

static int bridge_read(void *ctx, uint8_t addr, uint8_t *data, uint16_t n)
{
    (void)ctx;
    return transfer(addr, 0, 0, data, n);
}

static int bridge_write_read(void *ctx, uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    (void)ctx;
    return transfer(addr, wr, nw, rd, nr);
}

static uint64_t bridge_now(void *ctx)
{
    char line[LINE_MAX_LEN], answer[LINE_MAX_LEN];
    size_t len;
    int err;
    (void)ctx;
    line[0] = 'M';
    if (ask(line, 1, answer, &len, &err) == 1) {
        uint64_t v = 0;
        size_t k;
        /* 19 digits at most: past them uint64_t would wrap */
        for (k = 3; k < len && k < 22u && answer[k] >= '0' && answer[k] <= '9'; ++k) {
            v = v * 10u + (uint64_t)(answer[k] - '0');
        }
        if (k == len && v > last_ns) { /* a clock's answer is all digits: any other is lost, as a late one is */
            last_ns = v;
        }
    }
    return last_ns;
}

static void bridge_sleep(void *ctx, uint64_t ns)
{
    char line[LINE_MAX_LEN], answer[LINE_MAX_LEN];
    size_t n, len;
    int err;
    (void)ctx;
    n = put_text(line, 0, "S ");
    n = put_uint(line, n, ns);
    (void)ask(line, n, answer, &len, &err);
}

const adc_i2c *hal_i2c(void)
{
    static const adc_i2c bus = { 0, bridge_write, bridge_read, bridge_write_read, bridge_now, bridge_sleep };
    return &bus;
}
