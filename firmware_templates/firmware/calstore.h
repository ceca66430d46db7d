/* calstore.h: where a device keeps calibration blobs: a staging area that CAL_DATA fills and the active
 * blob that CAL_COMMIT replaces at once, so that a transfer that fails leaves the active blob as it was.
 * calstore_ram.c: two RAM buffers, lost at reset. calstore_eeprom.c (the ATmega328P): two slots of its
 * 1 KB EEPROM and a selector byte written last, so the active blob survives a reset and a power cut. */
#ifndef CALSTORE_H
#define CALSTORE_H

#include <stdint.h>

#include "cal.h"

#ifdef CAL_IN_EEPROM
#define CALSTORE_CAPACITY 508u /* half the EEPROM, less the selector and a slot's size field */
#elif defined(TM_FIXED_POINT)
#define CALSTORE_CAPACITY 0u   /* blobs carry reals: a fixed-point build holds none */
#else
#define CALSTORE_CAPACITY CAL_CAPACITY
#endif

/* bytes of the active blob (0: none; at boot, what an EEPROM store kept) and where it lies (cal.h) */
uint32_t calstore_active_size(void);
const uint8_t *calstore_active(void);
/* the staging area: n bytes at offset (offset + n <= CALSTORE_CAPACITY, checked by the caller) */
void calstore_stage_write(uint32_t offset, const uint8_t *p, uint32_t n);
const uint8_t *calstore_staged(void);
/* the first size bytes staged become the active blob */
void calstore_commit(uint32_t size);
/* no active blob (the compiled-in model answers) */
void calstore_clear(void);

#endif /* CALSTORE_H */
