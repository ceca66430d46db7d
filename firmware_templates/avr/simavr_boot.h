/* simavr_boot.h: an AVR at 16 MHz in libsimavr with an ELF loaded, for the two programs that run one
 * (simavr_run.c: the header's cycles, on the ATmega328P; uno_board.c: the board the HIL tools talk to). */
#ifndef SIMAVR_BOOT_H
#define SIMAVR_BOOT_H

#include <stdio.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

#define SIMAVR_BOOT_HZ 16000000u

/* the core mcu (simavr's name, e.g. atmega328p) with the ELF at path loaded, simavr's own log off; NULL (said
 * on stderr) when it cannot be */
static avr_t *simavr_boot(const char *path, const char *mcu)
{
    static elf_firmware_t fw;
    avr_t *avr;
    if (elf_read_firmware(path, &fw) != 0) {
        fprintf(stderr, "cannot read %s\n", path);
        return NULL;
    }
    avr = avr_make_mcu_by_name(mcu);
    if (avr == NULL) {
        fprintf(stderr, "simavr has no %s\n", mcu);
        return NULL;
    }
    avr_init(avr);
    avr->log = 0;
    avr_load_firmware(avr, &fw);
    avr->frequency = SIMAVR_BOOT_HZ;
    return avr;
}

#endif /* SIMAVR_BOOT_H */
