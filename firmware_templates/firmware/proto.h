/* proto.h: framing of docs/protocol.md: COBS, CRC-32 (zlib's), a byte-wise frame receiver
 * and a frame builder. No allocation; every loop is bounded by a buffer size. The protocol's
 * numbers (message types, error codes, limits, records' offsets) are proto_defs.h's, rendered
 * from host/protocol.py with the firmware.
 */
#ifndef PROTO_H
#define PROTO_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "proto_defs.h"

#define PROTO_MAX_WIRE (PROTO_MAX_ENCODED + 1u) /* plus the delimiter */

/* constant tables: in flash on AVR (PROGMEM, read with memcpy_P: 2 KB of RAM), in place elsewhere */
#ifdef __AVR__
#include <avr/pgmspace.h>
#define PROTO_ROM PROGMEM
#define PROTO_ROM_COPY(dst, src, n) memcpy_P((dst), (src), (n))
#else
#define PROTO_ROM
#define PROTO_ROM_COPY(dst, src, n) memcpy((dst), (src), (n))
#endif
typedef char proto_assert_body[(PROTO_MAX_BODY == PROTO_HEADER_SIZE + PROTO_MAX_PAYLOAD + PROTO_CRC_SIZE) ? 1 : -1];

/* little-endian fields, at any alignment */
static inline void proto_put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static inline void proto_put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static inline void proto_put_u64(uint8_t *p, uint64_t v)
{
    proto_put_u32(p, (uint32_t)v);
    proto_put_u32(p + 4, (uint32_t)(v >> 32));
}

static inline uint16_t proto_get_u16(const uint8_t *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

static inline uint32_t proto_get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static inline uint64_t proto_get_u64(const uint8_t *p)
{
    return (uint64_t)proto_get_u32(p) | ((uint64_t)proto_get_u32(p + 4) << 32);
}

/* CRC-32 (IEEE 802.3, reflected), zlib.crc32 semantics: start with crc = 0, feed pieces in order */
uint32_t proto_crc32(uint32_t crc, const uint8_t *p, size_t n);

/* COBS-encode n bytes into out (room for n + n / 254 + 1 bytes); returns the encoded length (no delimiter) */
size_t proto_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);

/* COBS-decode n bytes (no delimiter) into out (cap bytes); returns the decoded length, or -1 when the
 * input holds a 0x00, a code runs past the end, or the result does not fit */
long proto_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap);

/* fill in the header and CRC of body, which holds a payload of len bytes at body + PROTO_HEADER_SIZE;
 * returns the body's length */
size_t proto_seal_frame(uint8_t body[PROTO_MAX_BODY], uint8_t type, uint8_t seq, size_t len);

/* COBS(in[0 .. n)) and its delimiter handed to emit piece by piece: a frame sent without a wire buffer
 * (the same bytes proto_cobs_encode gives, then 0x00) */
typedef void (*proto_emit_fn)(const uint8_t *p, size_t n);
void proto_cobs_emit(const uint8_t *in, size_t n, proto_emit_fn emit);

/* body holds a payload of len bytes at body + PROTO_HEADER_SIZE; fills in the header and CRC, then writes
 * COBS(body) 0x00 into wire (PROTO_MAX_WIRE bytes). Returns the wire length. len <= PROTO_MAX_PAYLOAD. */
size_t proto_finish_frame(uint8_t body[PROTO_MAX_BODY], uint8_t type, uint8_t seq, size_t len,
                          uint8_t wire[PROTO_MAX_WIRE]);

/* a checked request */
typedef struct {
    uint8_t type;
    uint8_t seq;
    uint16_t len;
    const uint8_t *payload;
} proto_msg;

/* decode one encoded frame (without its delimiter) into body and check it; 0 when good, else
 * PROTO_BAD_FRAME or PROTO_BAD_CRC */
int proto_parse_frame(const uint8_t *enc, size_t n, uint8_t body[PROTO_MAX_BODY], proto_msg *msg);

/* the receiver: feed it one byte at a time */
typedef struct {
    uint8_t buf[PROTO_MAX_ENCODED];
    uint16_t len;
    uint8_t dropping; /* after an oversize frame, until the next 0x00 */
    uint8_t done;     /* the last call returned PROTO_RX_FRAME: start afresh */
} proto_rx;

enum {
    PROTO_RX_NONE = 0,    /* nothing yet */
    PROTO_RX_FRAME = 1,   /* rx->buf[0 .. rx->len) holds an encoded frame, valid until the next call */
    PROTO_RX_OVERSIZE = 2 /* no delimiter within PROTO_MAX_ENCODED bytes: dropping to the next 0x00 */
};

void proto_rx_init(proto_rx *rx);
int proto_rx_feed(proto_rx *rx, uint8_t byte);

#endif /* PROTO_H */
