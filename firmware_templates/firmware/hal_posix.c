/* hal_posix.c: the host port. The serial link is stdin/stdout, or with --pty a pseudo-terminal
 * whose slave path is printed as one line "PTY <path>" on stderr. Ticks are CLOCK_MONOTONIC ns.
 * Exits cleanly at the end of stdin, and on SIGTERM or SIGINT. */
#define _XOPEN_SOURCE 700 /* POSIX 2008 with the XSI pseudo-terminal calls */
#define _DEFAULT_SOURCE

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "hal.h"

static int in_fd = 0;
static int out_fd = 1;
static int slave_fd = -1; /* kept open: the slave's settings persist, the master never reads EIO */
static volatile sig_atomic_t stop_requested = 0;
static int at_eof = 0;
static uint8_t rx_buf[256];
static size_t rx_len = 0;
static size_t rx_pos = 0;
static uint64_t start_ns = 0;

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void fail(const char *what)
{
    fprintf(stderr, "firmware: %s: %s\n", what, strerror(errno));
    exit(2);
}

static void open_pty(void)
{
    struct termios tio;
    const char *name;
    const int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0) {
        fail("posix_openpt");
    }
    if (grantpt(master) != 0 || unlockpt(master) != 0) {
        fail("grantpt/unlockpt");
    }
    name = ptsname(master);
    if (name == NULL) {
        fail("ptsname");
    }
    slave_fd = open(name, O_RDWR | O_NOCTTY);
    if (slave_fd < 0) {
        fail("open pty slave");
    }
    if (tcgetattr(slave_fd, &tio) != 0) {
        fail("tcgetattr");
    }
    cfmakeraw(&tio);
    if (tcsetattr(slave_fd, TCSANOW, &tio) != 0) {
        fail("tcsetattr");
    }
    in_fd = out_fd = master;
    fprintf(stderr, "PTY %s\n", name);
    fflush(stderr);
}

void hal_init(int argc, char **argv)
{
    struct sigaction sa;
    int i;
    for (i = 1; i < argc; ++i) {
        if (strcmp(argv[i], "--pty") == 0) {
            open_pty();
        } else {
            fprintf(stderr, "usage: %s [--pty]\n", argv[0]);
            exit(2);
        }
    }
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    start_ns = now_ns();
}

int hal_alive(void)
{
    return !stop_requested && !at_eof;
}

/* wait up to timeout_ms (-1: no limit) for input; then read what is there */
static void fill(int timeout_ms)
{
    struct pollfd pfd;
    ssize_t n;
    pfd.fd = in_fd;
    pfd.events = POLLIN;
    pfd.revents = 0;
    if (poll(&pfd, 1, timeout_ms) <= 0 || !(pfd.revents & (POLLIN | POLLHUP | POLLERR))) {
        return;
    }
    n = read(in_fd, rx_buf, sizeof rx_buf);
    if (n > 0) {
        rx_len = (size_t)n;
        rx_pos = 0;
    } else if (n == 0 || (errno != EINTR && errno != EAGAIN)) {
        at_eof = 1; /* end of stdin (a pty master never reads 0 while slave_fd is open) */
    }
}

int hal_poll_byte(uint8_t *b)
{
    if (rx_pos >= rx_len && !at_eof) {
        fill(0);
    }
    if (rx_pos < rx_len) {
        *b = rx_buf[rx_pos++];
        return 1;
    }
    return 0;
}

void hal_write(const uint8_t *p, size_t n)
{
    while (n > 0) {
        const ssize_t w = write(out_fd, p, n);
        if (w > 0) {
            p += w;
            n -= (size_t)w;
        } else if (w < 0 && errno == EAGAIN) {
            struct pollfd pfd;
            pfd.fd = out_fd;
            pfd.events = POLLOUT;
            pfd.revents = 0;
            (void)poll(&pfd, 1, 100);
        } else if (!(w < 0 && errno == EINTR)) {
            at_eof = 1; /* the host went away */
            return;
        }
    }
}

uint64_t hal_ticks(void)
{
    return now_ns();
}

uint32_t hal_tick_hz(void)
{
    return 1000000000u;
}

uint32_t hal_millis(void)
{
    return (uint32_t)((now_ns() - start_ns) / 1000000u);
}

/* the I2C bridge's channel: requests on fd 3, answers on fd 4 (host.pi.StandIn's pipes) */
void hal_bridge_write(const uint8_t *p, size_t n)
{
    size_t off = 0;
    unsigned tries = 0;
    while (off < n && tries++ < 1000u) {
        const ssize_t w = write(3, p + off, n - off);
        if (w > 0) {
            off += (size_t)w;
        } else if (w < 0 && errno != EINTR) {
            return;
        }
    }
}

int hal_bridge_read_byte(uint8_t *b, uint32_t timeout_ms)
{
    struct pollfd pfd;
    pfd.fd = 4;
    pfd.events = POLLIN;
    if (poll(&pfd, 1, (int)timeout_ms) != 1 || read(4, b, 1) != 1) {
        return 0;
    }
    return 1;
}

void hal_idle(uint32_t max_ms)
{
    /* a bounded wait, so that a signal arriving just before poll() is seen soon */
    const int limit = 200;
    if (rx_pos < rx_len || at_eof || stop_requested) {
        return;
    }
    fill(max_ms < (uint32_t)limit ? (int)max_ms : limit);
}
