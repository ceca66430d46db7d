/* i2c_linux.c: the ADC drivers' port over Linux i2c-dev. Each transfer is one ioctl(I2C_RDWR) with
 * one or two messages (a register read is a write and a read joined by a repeated start, as
 * smbus2's read_i2c_block_data sends it); errno becomes the drivers' error kinds.
 *
 * Built with -DI2C_STANDIN, open/ioctl/close and the clocks go to standin.c, a stand-in for the
 * kernel device that the tests answer from host/simbus.py (under qemu-arm, with a virtual clock). */
#define _POSIX_C_SOURCE 200809L
#include "i2c_linux.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <time.h>
#include <unistd.h>

#include <linux/i2c-dev.h>
#include <linux/i2c.h>

#ifdef I2C_STANDIN
#include "standin.h"
#define SYS_OPEN standin_open
#define SYS_IOCTL standin_ioctl
#define SYS_CLOSE standin_close
#define NOW_NS standin_monotonic_ns
#define SLEEP_NS standin_sleep_ns
#define REAL_NS standin_realtime_ns
#else
#define SYS_OPEN open
#define SYS_IOCTL ioctl
#define SYS_CLOSE close
#define NOW_NS clock_ns_monotonic
#define SLEEP_NS clock_sleep_ns
#define REAL_NS clock_ns_realtime

static uint64_t clock_ns(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static uint64_t clock_ns_monotonic(void)
{
    return clock_ns(CLOCK_MONOTONIC);
}

static uint64_t clock_ns_realtime(void)
{
    return clock_ns(CLOCK_REALTIME);
}

static void clock_sleep_ns(uint64_t ns)
{
    struct timespec ts;
    unsigned tries;
    ts.tv_sec = (time_t)(ns / 1000000000u);
    ts.tv_nsec = (long)(ns % 1000000000u);
    /* a signal may cut a sleep short: go on with what is left, a bounded number of times */
    for (tries = 0; tries < 100 && nanosleep(&ts, &ts) != 0 && errno == EINTR; ++tries) {
    }
}
#endif

static int status_of(int err)
{
    if (err == EREMOTEIO || err == ENXIO) {
        return ADC_I2C_NACK;
    }
    if (err == ETIMEDOUT) {
        return ADC_I2C_TIMEOUT;
    }
    return ADC_I2C_OTHER;
}

static int rdwr(void *ctx, struct i2c_msg *msgs, unsigned n)
{
    const i2c_linux *port = (const i2c_linux *)ctx;
    struct i2c_rdwr_ioctl_data data;
    data.msgs = msgs;
    data.nmsgs = n;
    if (SYS_IOCTL(port->fd, I2C_RDWR, &data) < 0) {
        return status_of(errno);
    }
    return ADC_I2C_OK;
}

static int port_write(void *ctx, uint8_t addr, const uint8_t *buf, uint16_t n)
{
    struct i2c_msg m;
    m.addr = addr;
    m.flags = 0;
    m.len = n;
    m.buf = (uint8_t *)(uintptr_t)buf; /* the kernel reads a write message's buffer only */
    return rdwr(ctx, &m, 1);
}

static int port_read(void *ctx, uint8_t addr, uint8_t *buf, uint16_t n)
{
    struct i2c_msg m;
    m.addr = addr;
    m.flags = I2C_M_RD;
    m.len = n;
    m.buf = buf;
    return rdwr(ctx, &m, 1);
}

static int port_write_read(void *ctx, uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    struct i2c_msg m[2];
    m[0].addr = addr;
    m[0].flags = 0;
    m[0].len = nw;
    m[0].buf = (uint8_t *)(uintptr_t)wr;
    m[1].addr = addr;
    m[1].flags = I2C_M_RD;
    m[1].len = nr;
    m[1].buf = rd;
    return rdwr(ctx, m, 2);
}

static uint64_t port_now(void *ctx)
{
    (void)ctx;
    return NOW_NS();
}

static void port_sleep(void *ctx, uint64_t ns)
{
    (void)ctx;
    SLEEP_NS(ns);
}

uint64_t i2c_linux_realtime_ns(void)
{
    return REAL_NS();
}

int i2c_linux_open(i2c_linux *port, int bus, adc_i2c *out, char *err, size_t err_len)
{
    char path[32];
    snprintf(path, sizeof path, "/dev/i2c-%d", bus);
    port->fd = SYS_OPEN(path, O_RDWR);
    if (port->fd < 0) {
        const int e = errno;
        snprintf(err, err_len, "I2C bus %d: cannot open %s: %s%s", bus, path, strerror(e),
                 e == ENOENT ? " (enable I2C: raspi-config, or dtparam=i2c_arm=on in config.txt)"
                 : e == EACCES ? " (add the user to the i2c group)" : "");
        return -1;
    }
    out->ctx = port;
    out->write = port_write;
    out->read = port_read;
    out->write_read = port_write_read;
    out->now_ns = port_now;
    out->sleep_ns = port_sleep;
    return 0;
}

void i2c_linux_close(i2c_linux *port)
{
    if (port->fd >= 0) {
        SYS_CLOSE(port->fd);
        port->fd = -1;
    }
}
