/* simavr_run.c: runs an ATmega328P ELF in libsimavr at 16 MHz (fitgen/c/avr.py builds it).
 * USART0's bytes go to stdout; each write of 2 to GPIOR0 after a write of 1 prints
 * "CYCLES n" (the cycles between the two writes, simavr's count) to stderr.
 * usage: simavr_run FILE.elf MAX_CYCLES. Exit 0 when the program went to sleep with interrupts
 * off (its end), 3 when it crashed, 4 when it ran past MAX_CYCLES. */
#include <stdio.h>
#include <stdlib.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_io.h>

#include "simavr_boot.h"
#include <simavr/avr_uart.h>

/* GPIOR0: I/O register 0x1E, data address 0x3E on the ATmega328P (no peripheral behind it) */
#define GPIOR0_DATA 0x3E

static avr_cycle_count_t start;

static void gpior_write(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
    (void)addr;
    (void)param;
    avr->data[GPIOR0_DATA] = v;
    if (v == 1) {
        start = avr->cycle;
    } else if (v == 2) {
        fprintf(stderr, "CYCLES %llu\n", (unsigned long long)(avr->cycle - start));
    }
}

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    putchar((int)(value & 0xFFu));
}

int main(int argc, char **argv)
{
    avr_t *avr;
    uint32_t flags = 0;
    unsigned long long limit;
    int state;

    if (argc != 3) {
        fprintf(stderr, "usage: %s FILE.elf MAX_CYCLES\n", argv[0]);
        return 2;
    }
    limit = strtoull(argv[2], NULL, 10);
    avr = simavr_boot(argv[1], "atmega328p");
    if (avr == NULL) {
        return 2;
    }
    /* the bytes come here only, not also as simavr's console lines */
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(uint32_t)AVR_UART_FLAG_STDIO;
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    avr_register_io_write(avr, GPIOR0_DATA, gpior_write, NULL);
    do {
        state = avr_run(avr);
    } while (state != cpu_Done && state != cpu_Crashed && avr->cycle < limit);
    fflush(stdout);
    if (state == cpu_Crashed) {
        fprintf(stderr, "the AVR program crashed at cycle %llu\n", (unsigned long long)avr->cycle);
        return 3;
    }
    if (state != cpu_Done) {
        fprintf(stderr, "the AVR program ran past %llu cycles\n", limit);
        return 4;
    }
    return 0;
}
