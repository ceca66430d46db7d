/* calstore_eeprom.c: see calstore.h; the ATmega328P's 1 KB EEPROM:
 *   byte 0      selector: SELECT_SLOT | slot when that slot holds the active blob; else none
 *   byte 1      reserved
 *   2 .. 513    slot 0: size (u16, little-endian), then up to CALSTORE_CAPACITY blob bytes
 *   514 .. 1023 slot 1
 * A transfer writes the slot the selector does not name; CAL_COMMIT writes its size, then the selector: one
 * byte, so a reset or power cut at any moment leaves the old blob or the new one active, never half of one.
 * avr-libc's eeprom_update_* wait for each byte's write (about 3.4 ms, timed by the hardware) and skip
 * bytes that already hold their value. */
#include <avr/eeprom.h>

#include "calstore.h"

#define SELECT_SLOT 0xA0u
#define SLOT_BYTES (2u + CALSTORE_CAPACITY)
#define SLOT_BASE(s) ((uint16_t)(2u + (s) * SLOT_BYTES))

typedef char calstore_assert_fits[(SLOT_BASE(2) <= E2END + 1u) ? 1 : -1];

static uint8_t *at(uint16_t address)
{
    return (uint8_t *)(uintptr_t)address;
}

/* the active slot, or -1 */
static int active_slot(void)
{
    const uint8_t sel = eeprom_read_byte(at(0));
    return (sel & 0xFEu) == SELECT_SLOT ? (int)(sel & 1u) : -1;
}

static int staging_slot(void)
{
    return active_slot() == 0 ? 1 : 0;
}

uint32_t calstore_active_size(void)
{
    const int s = active_slot();
    uint16_t n;
    if (s < 0) {
        return 0;
    }
    n = eeprom_read_word((const uint16_t *)at(SLOT_BASE(s)));
    return n <= CALSTORE_CAPACITY ? n : 0u;
}

const uint8_t *calstore_active(void)
{
    const int s = active_slot();
    return at((uint16_t)(SLOT_BASE(s < 0 ? 0 : s) + 2u));
}

void calstore_stage_write(uint32_t offset, const uint8_t *p, uint32_t n)
{
    if (offset <= CALSTORE_CAPACITY && n <= CALSTORE_CAPACITY - offset) {
        eeprom_update_block(p, at((uint16_t)(SLOT_BASE(staging_slot()) + 2u + offset)), (size_t)n);
    }
}

const uint8_t *calstore_staged(void)
{
    return at((uint16_t)(SLOT_BASE(staging_slot()) + 2u));
}

void calstore_commit(uint32_t size)
{
    const int s = staging_slot();
    if (size <= CALSTORE_CAPACITY) {
        eeprom_update_word((uint16_t *)at(SLOT_BASE(s)), (uint16_t)size);
        eeprom_update_byte(at(0), (uint8_t)(SELECT_SLOT | (unsigned)s));
    }
}

void calstore_clear(void)
{
    eeprom_update_byte(at(0), 0xFFu);
}
