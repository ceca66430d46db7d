/* tactile_wire.cpp: adc_i2c over Wire. Lengths past Wire's buffer are refused (ADC_I2C_OTHER) rather
 * than cut; every transaction ends within the Wire timeout set by tactile_wire_bus; the clock is micros()
 * widened to 64 bits, so that the drivers' time limits hold past its 71-minute wrap. */
#include <Arduino.h>
#include <Wire.h>

#include "tactile_wire.h"

/* Wire.endTransmission: 0 ok, 1 too long, 2 address NACK, 3 data NACK, 4 other, 5 timeout */
static int status_of(uint8_t st)
{
    if (st == 0) return ADC_I2C_OK;
    if (st == 2 || st == 3) return ADC_I2C_NACK;
    if (st == 5) return ADC_I2C_TIMEOUT;
    return ADC_I2C_OTHER;
}

static int send(uint8_t addr, const uint8_t *data, uint16_t n, bool stop)
{
    if (n > BUFFER_LENGTH) {
        return ADC_I2C_OTHER;
    }
    Wire.clearWireTimeoutFlag();
    Wire.beginTransmission(addr);
    if (Wire.write(data, n) != n) {
        Wire.endTransmission(true);
        return ADC_I2C_OTHER;
    }
    return status_of(Wire.endTransmission(stop));
}

static int receive(uint8_t addr, uint8_t *data, uint16_t n)
{
    uint16_t i;
    if (n == 0 || n > BUFFER_LENGTH) {
        return ADC_I2C_OTHER;
    }
    Wire.clearWireTimeoutFlag();
    if (Wire.requestFrom(addr, (uint8_t)n, (uint8_t)true) != n) {
        while (Wire.available() > 0) {
            Wire.read(); /* at most BUFFER_LENGTH bytes */
        }
        return Wire.getWireTimeoutFlag() ? ADC_I2C_TIMEOUT : ADC_I2C_NACK;
    }
    for (i = 0; i < n; ++i) {
        data[i] = (uint8_t)Wire.read();
    }
    return ADC_I2C_OK;
}

static int port_write(void *ctx, uint8_t addr, const uint8_t *data, uint16_t n)
{
    (void)ctx;
    return send(addr, data, n, true);
}

static int port_read(void *ctx, uint8_t addr, uint8_t *data, uint16_t n)
{
    (void)ctx;
    return receive(addr, data, n);
}

static int port_write_read(void *ctx, uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    const int st = send(addr, wr, nw, false); /* a repeated start, as smbus2's register read sends it */
    (void)ctx;
    return st == ADC_I2C_OK ? receive(addr, rd, nr) : st;
}

static uint64_t port_now(void *ctx)
{
    static uint32_t last;
    static uint64_t high;
    const uint32_t us = micros();
    (void)ctx;
    if (us < last) {
        high += (uint64_t)1 << 32;
    }
    last = us;
    return (high + us) * 1000u;
}

static void port_sleep(void *ctx, uint64_t ns)
{
    const uint64_t us = (ns + 999u) / 1000u;
    (void)ctx;
    if (us >= 1000u) {
        delay((unsigned long)(us / 1000u));
    }
    delayMicroseconds((unsigned int)(us % 1000u)); /* exact up to 16383 us */
}

void tactile_wire_bus(adc_i2c *out, uint32_t timeout_us)
{
    Wire.setWireTimeout(timeout_us, true);
    out->ctx = 0;
    out->write = port_write;
    out->read = port_read;
    out->write_read = port_write_read;
    out->now_ns = port_now;
    out->sleep_ns = port_sleep;
}
