/* standin.c: the kernel's side of i2c-dev, and the clocks, answered by a test harness.
 *
 * Each call is one request line on fd 3 and one answer line on fd 4 (host/pi.py serves them
 * from host/simbus.py and a virtual clock):
 *   O <path>                               -> OK <fd> | E <errno>
 *   R <addr> <n> {<flags> <len> <hex>}*n   -> OK <hex of the read messages' bytes> | E <errno>
 *   M | W                                  -> OK <monotonic ns> | OK <Unix time ns>
 *   S <ns>                                 -> OK
 * A harness that is gone ends the program: there is no device to fall back on. */
#define _POSIX_C_SOURCE 200809L
#include "standin.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <linux/i2c-dev.h>
#include <linux/i2c.h>

#define REQ_FD 3
#define ANS_FD 4
#define LINE_MAX_LEN 512

static void send_line(const char *s)
{
    size_t n = strlen(s), off = 0;
    while (off < n) {
        const ssize_t w = write(REQ_FD, s + off, n - off);
        if (w < 0 && errno == EINTR) {
            continue; /* tm_pi's SIGINT/SIGTERM handler ran: the request still goes out whole */
        }
        if (w <= 0) {
            _exit(3);
        }
        off += (size_t)w;
    }
}

/* the answer without its newline; the program ends if the harness is gone or the line is too long */
static void receive_line(char *buf)
{
    size_t n = 0;
    for (;;) {
        char c;
        const ssize_t r = read(ANS_FD, &c, 1);
        if (r < 0 && errno == EINTR) {
            continue;
        }
        if (r != 1 || n + 1 >= LINE_MAX_LEN) {
            _exit(3);
        }
        if (c == '\n') {
            break;
        }
        buf[n++] = c;
    }
    buf[n] = 0;
}

/* "OK rest" gives 0 and rest; "E errno" sets errno and gives -1 */
static int ask(const char *req, char *rest)
{
    char ans[LINE_MAX_LEN];
    send_line(req);
    receive_line(ans);
    if (ans[0] == 'O' && ans[1] == 'K') {
        strcpy(rest, ans[2] == ' ' ? ans + 3 : "");
        return 0;
    }
    errno = ans[0] == 'E' ? atoi(ans + 1) : EIO;
    return -1;
}

int standin_open(const char *path, int flags)
{
    char req[LINE_MAX_LEN], rest[LINE_MAX_LEN];
    (void)flags;
    if (strlen(path) > 200) {
        errno = ENAMETOOLONG;
        return -1;
    }
    snprintf(req, sizeof req, "O %s\n", path);
    return ask(req, rest) == 0 ? atoi(rest) : -1;
}

int standin_close(int fd)
{
    (void)fd;
    return 0;
}

static int hexval(char c)
{
    return c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
}

int standin_ioctl(int fd, unsigned long request, void *arg)
{
    const struct i2c_rdwr_ioctl_data *d = (const struct i2c_rdwr_ioctl_data *)arg;
    char req[LINE_MAX_LEN], rest[LINE_MAX_LEN];
    size_t len, i, pos = 0, want = 0;
    unsigned m;
    (void)fd;
    if (request != I2C_RDWR || d->nmsgs < 1 || d->nmsgs > 2) {
        errno = EINVAL;
        return -1;
    }
    len = (size_t)snprintf(req, sizeof req, "R %u %u", (unsigned)d->msgs[0].addr, (unsigned)d->nmsgs);
    for (m = 0; m < d->nmsgs; ++m) {
        const struct i2c_msg *msg = &d->msgs[m];
        if (msg->len > 32) {
            errno = EINVAL;
            return -1;
        }
        len += (size_t)snprintf(req + len, sizeof req - len, " %u %u ", (unsigned)msg->flags, (unsigned)msg->len);
        if (msg->flags & I2C_M_RD) {
            want += msg->len;
            len += (size_t)snprintf(req + len, sizeof req - len, "-");
        } else {
            for (i = 0; i < msg->len; ++i) {
                len += (size_t)snprintf(req + len, sizeof req - len, "%02x", msg->buf[i]);
            }
        }
    }
    snprintf(req + len, sizeof req - len, "\n");
    if (ask(req, rest) != 0) {
        return -1;
    }
    if (strlen(rest) != 2 * want) {
        errno = EIO;
        return -1;
    }
    for (m = 0; m < d->nmsgs; ++m) {
        const struct i2c_msg *msg = &d->msgs[m];
        if (!(msg->flags & I2C_M_RD)) {
            continue;
        }
        for (i = 0; i < msg->len; ++i, pos += 2) {
            msg->buf[i] = (uint8_t)(hexval(rest[pos]) * 16 + hexval(rest[pos + 1]));
        }
    }
    return (int)d->nmsgs;
}

static uint64_t ask_time(const char *req)
{
    char rest[LINE_MAX_LEN];
    return ask(req, rest) == 0 ? strtoull(rest, NULL, 10) : 0;
}

uint64_t standin_monotonic_ns(void)
{
    return ask_time("M\n");
}

uint64_t standin_realtime_ns(void)
{
    return ask_time("W\n");
}

void standin_sleep_ns(uint64_t ns)
{
    char req[64], rest[LINE_MAX_LEN];
    snprintf(req, sizeof req, "S %llu\n", (unsigned long long)ns);
    (void)ask(req, rest);
}
