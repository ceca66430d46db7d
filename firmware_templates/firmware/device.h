/* device.h: the request dispatcher of docs/protocol.md. One static device; no allocation. */
#ifndef DEVICE_H
#define DEVICE_H

#include <stddef.h>
#include <stdint.h>

#include "cal.h"
#include "calstore.h"
#include "proto.h"

typedef struct {
    const char *sensor_id;      /* at most 16 characters */
    const char *fw_version;     /* at most 12 characters */
    const uint8_t *model_hash;  /* 32 bytes: the compiled-in model's Model.sha256 (PROTO_ROM) */
    uint8_t style;              /* the compiled-in model: 0 table, 1 unrolled */
} device_config;

/* BENCH cycles through this many fixed vectors (an ATmega328P keeps 2: 16 would take a quarter of its RAM); a
 * render given readings sets it to their number (DEVICE_BENCH_INPUTS) */
#ifndef DEVICE_BENCH_VECTORS
#define DEVICE_BENCH_VECTORS 16u
#endif

typedef struct {
    const device_config *cfg;
    proto_rx rx;                  /* a request arrives here, and is decoded in place */
    uint8_t out[PROTO_MAX_BODY];  /* a reply being built (payload at out + PROTO_HEADER_SIZE) */
    /* calibration: the store's active blob when use_blob, else the compiled-in tm_estimate */
    uint8_t use_blob;
    cal_model active;             /* the active blob parsed (its size among it) */
    uint8_t stage_open;           /* CAL_BEGIN seen, no COMMIT yet */
    uint32_t stage_size;
    uint32_t stage_crc;
    uint32_t stage_received;
    /* STREAM */
    uint8_t stream_on;
    uint8_t stream_seq;
    uint16_t stream_period;
    uint16_t stream_count;
    uint16_t stream_index;
    uint32_t stream_next_ms;
    /* BENCH: fixed vectors inside the compiled-in domain, and where results go */
    tm_input bench_in[DEVICE_BENCH_VECTORS][TM_N_INPUTS];
    tm_output bench_out[TM_N_OUTPUTS];
} device;

void device_init(device *d, const device_config *cfg);
/* one received byte; replies go out through hal_write */
void device_feed(device *d, uint8_t byte);
/* send a STREAM sample when one is due */
void device_tick(device *d);
/* milliseconds until device_tick has something to do (HAL_IDLE_FOREVER: nothing planned) */
uint32_t device_idle_ms(const device *d);

#endif /* DEVICE_H */
