/* uno_board.c: an Arduino Uno in libsimavr for the HIL tools (hil/emulate.py builds and starts it).
 *
 * The ATmega328P at 16 MHz runs FILE.elf (with --mcu, another AVR whose USART0 and TWI are at the same
 * addresses, as the Mega's ATmega2560: another board's sketch; --eeprom stays the ATmega328P's).
 * Its USART0 is served on 127.0.0.1:PORT (one client at a time, a new one accepted when the last has gone,
 * as QEMU's socket chardev does), so host tools reach it as socket://127.0.0.1:PORT; bytes go in only
 * while the program has the receiver on (simavr drops a byte that arrives before: a client that connects
 * at once would lose its first request to the program's start-up) and simavr's UART FIFO has room (its
 * XON/XOFF IRQs).
 * With --bridge, the TWI bus carries the chips of the bus model: each I2C transaction becomes a request
 * of the line protocol host.pi.StandIn answers (firmware/i2c_bridge.c's, plus A and T) on fd 3, its answer
 * read from fd 4, so the same Python bus model answers every board:
 *   T <ns>   the bus model's clock moved to the AVR's time (simavr's cycle count), never back
 *   A <addr> is a chip there: OK, or E <errno> (the address is not acknowledged)
 *   R <addr> <n> {<flags> <len> <hex or ->}*n   a write (sent at STOP or before a repeated start's read)
 *            and reads of two bytes at a time (the chips' registers are 16-bit; a longer read asks again)
 * While the core sleeps, the board waits for the socket in wall time instead of spinning.
 * --eeprom FILE: the EEPROM's 1 KB loaded from FILE when it exists, and written back to it (atomically)
 * on exit, so that a calibration flashed there survives a restart, as on the board.
 * --paint ADDR: RAM from ADDR (the end of .bss) to RAMEND is painted before the program starts; on exit
 * "STACK n" on stderr gives the deepest the stack reached below RAMEND (bytes no longer painted). The
 * stack pointer is also watched after every instruction: once it is below ADDR the stack has run into
 * static RAM (a frame may skip the painted bytes it reserves), the board says so, reports the whole span
 * as used and exits 6, before the program goes on with corrupted variables.
 * --hold: the core starts when the first client connects, as an Uno restarts when a serial monitor opens
 * its port (DTR), so that the client sees everything the program prints from its start.
 * UNO_BOARD_TRACE in the environment: each TWI message and bus-model exchange is printed on stderr.
 * PORT 0: the system picks a free port (no race with another process between choosing and binding); the
 * first line on stderr, "LISTENING <port>", says which.
 * Runs until SIGTERM or SIGINT; exits 3 when the program crashes, 4 when the bus model goes away, 5 when
 * the EEPROM image cannot be written, 6 when the stack runs into static RAM (with --paint).
 * usage: uno_board FILE.elf PORT [--bridge] [--eeprom FILE] [--paint ADDR] [--hold] [--mcu NAME]
 */
#define _DEFAULT_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <simavr/avr_eeprom.h>
#include <simavr/avr_twi.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_io.h>

#include "simavr_boot.h"

#define F_CPU SIMAVR_BOOT_HZ
#define PAINT 0xA5u
#define POLL_EVERY 2048u     /* instructions between two looks at the socket */
#define OUT_MAX 4096u        /* UART bytes held for the client */
#define LINE_MAX_LEN 256u
#define BRIDGE_IN 3
#define BRIDGE_OUT 4
#define READ_CHUNK 2u
#define SLEEP_MAX_US 2000u   /* the longest wait for the socket while the core sleeps */
#define EEPROM_BYTES 1024u
#define UCSR0B_ADDR 0xC1u    /* USART0's control register B (data space), on the ATmega328P and ATmega2560 */
#define RXEN0_BIT 4u

static volatile sig_atomic_t stopping;
static avr_t *avr;
static unsigned long ramend;       /* the core's last RAM address */
static int listener = -1, client = -1;
static int xoff;
static uint8_t out_buf[OUT_MAX];
static size_t out_len;
static int bridge;
static int bridge_lost;

/* the TWI transaction in progress */
static uint8_t twi_addr;          /* 7-bit address, 0xFF: none selected */
static uint8_t wr_buf[32];
static size_t wr_len;
static uint8_t rd_buf[READ_CHUNK];
static size_t rd_len, rd_pos;
static avr_irq_t *twi_irq;
static int trace; /* UNO_BOARD_TRACE set: every TWI message and bus-model exchange on stderr */

static void on_signal(int sig)
{
    (void)sig;
    stopping = 1;
}

static uint64_t now_ns(void)
{
    return (uint64_t)avr->cycle * 125u / 2u; /* 62.5 ns per cycle at 16 MHz */
}

/* one request line to the bus model and its answer; 1 "OK ...", 0 "E ...", -1 the bus model is gone */
static int ask(const char *line, char *answer)
{
    size_t n = strlen(line), k = 0;
    if (bridge_lost) {
        return -1;
    }
    if (write(BRIDGE_IN, line, n) != (ssize_t)n || write(BRIDGE_IN, "\n", 1) != 1) {
        bridge_lost = 1;
        return -1;
    }
    for (;;) {
        char c;
        if (read(BRIDGE_OUT, &c, 1) != 1 || k + 1 >= LINE_MAX_LEN) {
            bridge_lost = 1;
            return -1;
        }
        if (c == '\n') {
            break;
        }
        answer[k++] = c;
    }
    answer[k] = 0;
    if (trace) {
        fprintf(stderr, "bridge: %s -> %s\n", line, answer);
    }
    return strncmp(answer, "OK", 2) == 0 ? 1 : 0;
}

static void sync_clock(void)
{
    char line[64], answer[LINE_MAX_LEN];
    snprintf(line, sizeof line, "T %llu", (unsigned long long)now_ns());
    (void)ask(line, answer);
}

static void twi_reply(uint8_t msg, uint8_t data)
{
    avr_raise_irq(twi_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(msg, (uint8_t)(twi_addr << 1), data));
}

/* the pending write (if any) and a read of n bytes (0: none) as one transfer; 1 when the chip took it */
static int transfer(size_t n_read)
{
    char line[LINE_MAX_LEN], answer[LINE_MAX_LEN];
    size_t n = 0, i;
    int r;
    n += (size_t)snprintf(line + n, sizeof line - n, "R %u %d", twi_addr, (wr_len ? 1 : 0) + (n_read ? 1 : 0));
    if (wr_len) {
        n += (size_t)snprintf(line + n, sizeof line - n, " 0 %zu ", wr_len);
        for (i = 0; i < wr_len; ++i) {
            n += (size_t)snprintf(line + n, sizeof line - n, "%02x", wr_buf[i]);
        }
    }
    if (n_read) {
        snprintf(line + n, sizeof line - n, " 1 %zu -", n_read);
    }
    wr_len = 0;
    sync_clock();
    r = ask(line, answer);
    rd_len = rd_pos = 0;
    if (r == 1 && n_read) {
        for (i = 0; i < n_read && answer[3 + 2 * i] && answer[4 + 2 * i]; ++i) {
            unsigned v;
            sscanf(answer + 3 + 2 * i, "%2x", &v);
            rd_buf[rd_len++] = (uint8_t)v;
        }
    }
    return r == 1;
}

static void twi_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    avr_twi_msg_irq_t v;
    (void)irq;
    (void)param;
    v.u.v = value;
    if (trace) {
        fprintf(stderr, "twi: msg %02x addr %02x data %02x (TWSR %02x TWCR %02x) at %llu\n", v.u.twi.msg, v.u.twi.addr,
                v.u.twi.data, avr->data[0xB9], avr->data[0xBC], (unsigned long long)avr->cycle);
    }
    if (v.u.twi.msg & TWI_COND_STOP) {
        if (twi_addr != 0xFFu && wr_len) {
            (void)transfer(0);
        }
        twi_addr = 0xFFu;
        wr_len = rd_len = rd_pos = 0;
    }
    if (v.u.twi.msg & TWI_COND_START) {
        const uint8_t addr = (uint8_t)(v.u.twi.addr >> 1);
        char line[32], answer[LINE_MAX_LEN];
        if (twi_addr != 0xFFu && wr_len && !((v.u.twi.addr & 1u) && addr == twi_addr)) {
            (void)transfer(0); /* a repeated start elsewhere: the write happens first */
        }
        if (!(v.u.twi.addr & 1u) || addr != twi_addr) {
            wr_len = 0;
        }
        rd_len = rd_pos = 0;
        twi_addr = 0xFFu;
        sync_clock();
        snprintf(line, sizeof line, "A %u", addr);
        if (ask(line, answer) == 1) {
            twi_addr = addr;
            twi_reply(TWI_COND_ACK, 1);
        }
        return;
    }
    if (twi_addr == 0xFFu) {
        return;
    }
    if (v.u.twi.msg & TWI_COND_WRITE) {
        if (wr_len < sizeof wr_buf) {
            wr_buf[wr_len++] = v.u.twi.data;
            twi_reply(TWI_COND_ACK, 1);
        }
    }
    if (v.u.twi.msg & TWI_COND_READ) {
        if (rd_pos >= rd_len) {
            (void)transfer(READ_CHUNK);
        }
        twi_reply(TWI_COND_READ, rd_pos < rd_len ? rd_buf[rd_pos++] : 0xFFu);
    }
}

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    if (client >= 0 && out_len < OUT_MAX) {
        out_buf[out_len++] = (uint8_t)value; /* no client: the bytes go nowhere, as on an unplugged line */
    }
}

static void uart_xoff(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    xoff = value != 0;
}

static void uart_xon(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    if (value) {
        xoff = 0;
    }
}

static void drop_client(void)
{
    if (client >= 0) {
        close(client);
    }
    client = -1;
    out_len = 0;
}

static void flush_out(void)
{
    while (client >= 0 && out_len) {
        const ssize_t k = send(client, out_buf, out_len, MSG_DONTWAIT | MSG_NOSIGNAL);
        if (k > 0) {
            memmove(out_buf, out_buf + k, out_len - (size_t)k);
            out_len -= (size_t)k;
        } else if (k < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
            return;
        } else {
            drop_client();
        }
    }
}

/* 1 when the program can take a byte now: its receiver on and the UART's FIFO not full */
static int rx_ready(void)
{
    return !xoff && (avr->data[UCSR0B_ADDR] & (1u << RXEN0_BIT)) != 0;
}

/* wait up to timeout_us for the socket (0: just look); accept a client, feed its bytes while the UART
 * takes them, send what the UART gave */
static void poll_socket(long timeout_us)
{
    fd_set rd;
    struct timeval tv;
    int top;
    flush_out();
    FD_ZERO(&rd);
    if (client < 0) {
        FD_SET(listener, &rd);
        top = listener;
    } else {
        if (!rx_ready()) {
            timeout_us = 0; /* nothing to take from the client now: its bytes wait in the socket */
        } else {
            FD_SET(client, &rd);
        }
        top = client;
    }
    tv.tv_sec = 0;
    tv.tv_usec = timeout_us;
    if (select(top + 1, &rd, NULL, NULL, &tv) <= 0) {
        return;
    }
    if (client < 0 && FD_ISSET(listener, &rd)) {
        const int one = 1;
        client = accept(listener, NULL, NULL);
        if (client >= 0) {
            setsockopt(client, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        }
        return;
    }
    if (client >= 0 && FD_ISSET(client, &rd)) {
        avr_irq_t *in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
        while (rx_ready()) {
            uint8_t b;
            const ssize_t k = recv(client, &b, 1, MSG_DONTWAIT);
            if (k == 1) {
                avr_raise_irq(in, b);
            } else {
                if (k == 0 || (errno != EAGAIN && errno != EWOULDBLOCK)) {
                    drop_client();
                }
                break;
            }
        }
    }
}

/* simavr's sleep: the core sleeps for how_long cycles; the board waits for the socket meanwhile */
static void board_sleep(avr_t *a, avr_cycle_count_t how_long)
{
    const uint64_t us = (uint64_t)how_long / (F_CPU / 1000000u);
    (void)a;
    poll_socket((long)(us < SLEEP_MAX_US ? us : SLEEP_MAX_US));
}

/* the EEPROM from or to FILE: 0, or -1 (a missing file to load is not an error: the EEPROM stays blank) */
static int eeprom_file(const char *path, int save)
{
    uint8_t image[EEPROM_BYTES];
    avr_eeprom_desc_t d;
    FILE *f;
    d.ee = image;
    d.offset = 0;
    d.size = EEPROM_BYTES;
    if (save) {
        char tmp[4096];
        snprintf(tmp, sizeof tmp, "%s.tmp", path);
        avr_ioctl(avr, AVR_IOCTL_EEPROM_GET, &d);
        f = fopen(tmp, "wb");
        if (f == NULL || fwrite(d.ee, 1, EEPROM_BYTES, f) != EEPROM_BYTES) {
            if (f != NULL) {
                fclose(f);
            }
            return -1;
        }
        return fclose(f) == 0 && rename(tmp, path) == 0 ? 0 : -1;
    }
    f = fopen(path, "rb");
    if (f == NULL) {
        return 0;
    }
    if (fread(image, 1, EEPROM_BYTES, f) != EEPROM_BYTES) {
        fclose(f);
        return -1;
    }
    fclose(f);
    avr_ioctl(avr, AVR_IOCTL_EEPROM_SET, &d);
    return 0;
}

static int listen_on(int port)
{
    struct sockaddr_in sa;
    const int one = 1;
    listener = socket(AF_INET, SOCK_STREAM, 0);
    if (listener < 0) {
        return -1;
    }
    setsockopt(listener, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    memset(&sa, 0, sizeof sa);
    sa.sin_family = AF_INET;
    sa.sin_port = htons((uint16_t)port);
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (bind(listener, (struct sockaddr *)&sa, sizeof sa) != 0 || listen(listener, 4) != 0) {
        return -1;
    }
    {
        socklen_t len = sizeof sa;
        if (getsockname(listener, (struct sockaddr *)&sa, &len) != 0) {
            return -1;
        }
    }
    return (int)ntohs(sa.sin_port);
}

int main(int argc, char **argv)
{
    unsigned long paint = 0;
    const char *eeprom = NULL;
    const char *mcu = "atmega328p";
    unsigned long count = 0;
    int port, i, state = cpu_Running, code = 0, hold = 0;
    struct sigaction sa;

    if (argc < 3) {
        fprintf(stderr, "usage: %s FILE.elf PORT [--bridge] [--eeprom FILE] [--paint ADDR] [--hold] [--mcu NAME]\n",
                argv[0]);
        return 2;
    }
    port = atoi(argv[2]);
    trace = getenv("UNO_BOARD_TRACE") != NULL;
    for (i = 3; i < argc; ++i) {
        if (strcmp(argv[i], "--bridge") == 0) {
            bridge = 1;
        } else if (strcmp(argv[i], "--eeprom") == 0 && i + 1 < argc) {
            eeprom = argv[++i];
        } else if (strcmp(argv[i], "--hold") == 0) {
            hold = 1;
        } else if (strcmp(argv[i], "--mcu") == 0 && i + 1 < argc) {
            mcu = argv[++i];
        } else if (strcmp(argv[i], "--paint") == 0 && i + 1 < argc) {
            paint = strtoul(argv[++i], NULL, 0);
        } else {
            fprintf(stderr, "unknown option %s\n", argv[i]);
            return 2;
        }
    }
    if (port < 0 || port > 65535) {
        fprintf(stderr, "bad port\n");
        return 2;
    }
    if (eeprom != NULL && strcmp(mcu, "atmega328p") != 0) { /* its image is the ATmega328P's 1 KB */
        fprintf(stderr, "--eeprom is the ATmega328P's, not %s's\n", mcu);
        return 2;
    }
    avr = simavr_boot(argv[1], mcu);
    if (avr == NULL) {
        return 2;
    }
    ramend = avr->ramend;
    if (paint && (paint <= avr->ioend || paint > ramend)) { /* RAM only: below it, the I/O registers */
        fprintf(stderr, "bad paint address\n");
        return 2;
    }
    avr->sleep = board_sleep;
    if (eeprom != NULL && eeprom_file(eeprom, 0) != 0) {
        fprintf(stderr, "cannot read the EEPROM image %s\n", eeprom);
        return 2;
    }
    {
        const int bound = listen_on(port);
        if (bound <= 0) {
            fprintf(stderr, "cannot listen on 127.0.0.1:%d: %s\n", port, strerror(errno));
            return 2;
        }
        port = bound;
    }
    {
        uint32_t flags = 0;
        avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
        flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
        avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    }
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), uart_xoff, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), uart_xon, NULL);
    if (bridge) {
        static const char *names[2] = { "8>board.twi.out", "32<board.twi.in" };
        twi_addr = 0xFFu;
        twi_irq = avr_alloc_irq(&avr->irq_pool, 0, 2, names);
        avr_irq_register_notify(twi_irq + TWI_IRQ_OUTPUT, twi_hook, NULL);
        avr_connect_irq(twi_irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
        avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), twi_irq + TWI_IRQ_OUTPUT);
    }
    if (paint) {
        memset(avr->data + paint, PAINT, ramend + 1u - paint);
    }
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    fprintf(stderr, "LISTENING %d\n", port);
    while (hold && client < 0 && !stopping) {
        poll_socket((long)SLEEP_MAX_US);
    }
    while (!stopping) {
        state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            break;
        }
        if (bridge_lost) {
            code = 4;
            break;
        }
        /* SP is the next free byte: the stack holds SP+1..RAMEND, so SP+1 < paint is a byte of .bss in it */
        if (paint && (unsigned long)(avr->data[R_SPL] | (avr->data[R_SPH] << 8)) + 1u < paint) {
            code = 6;
            break;
        }
        if (++count % POLL_EVERY == 0) {
            poll_socket(0);
        }
    }
    flush_out();
    if (eeprom != NULL && eeprom_file(eeprom, 1) != 0) {
        fprintf(stderr, "cannot write the EEPROM image %s\n", eeprom);
        code = code ? code : 5;
    }
    if (paint) {
        unsigned long a = paint;
        while (a <= ramend && avr->data[a] == PAINT) {
            ++a;
        }
        fprintf(stderr, "STACK %lu\n", code == 6 ? ramend + 1u - paint : ramend + 1u - a);
    }
    if (state == cpu_Crashed) {
        fprintf(stderr, "the AVR program crashed at cycle %llu\n", (unsigned long long)avr->cycle);
        code = 3;
    } else if (code == 4) {
        fprintf(stderr, "the bus model went away\n");
    } else if (code == 6) {
        fprintf(stderr, "the stack ran into static RAM (SP 0x%04x, .bss ends at 0x%04lx) at cycle %llu\n",
                avr->data[R_SPL] | (avr->data[R_SPH] << 8), paint, (unsigned long long)avr->cycle);
    }
    fprintf(stderr, "CYCLES %llu\n", (unsigned long long)avr->cycle);
    return code;
}
