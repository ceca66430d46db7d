/* calstore_ram.c: see calstore.h; two RAM buffers (none in a fixed-point build). */
#include <string.h>

#include "calstore.h"

#if CALSTORE_CAPACITY > 0
static uint8_t active[CALSTORE_CAPACITY];
static uint8_t staged[CALSTORE_CAPACITY];
#else
static uint8_t active[1];
static uint8_t staged[1];
#endif
static uint32_t active_size;

uint32_t calstore_active_size(void)
{
    return active_size;
}

const uint8_t *calstore_active(void)
{
    return active;
}

void calstore_stage_write(uint32_t offset, const uint8_t *p, uint32_t n)
{
    if (offset <= CALSTORE_CAPACITY && n <= CALSTORE_CAPACITY - offset) {
        memcpy(staged + offset, p, n);
    }
}

const uint8_t *calstore_staged(void)
{
    return staged;
}

void calstore_commit(uint32_t size)
{
    if (size <= CALSTORE_CAPACITY) {
        memcpy(active, staged, size);
        active_size = size;
    }
}

void calstore_clear(void)
{
    active_size = 0;
}
