/* proto.c: see proto.h */
#include "proto.h"

#include <string.h>

/* CRC-32 of one nibble, reflected polynomial 0xEDB88320: 16 entries instead of 256 */
static const uint32_t crc_nibble[16] PROTO_ROM = {
    0x00000000u, 0x1DB71064u, 0x3B6E20C8u, 0x26D930ACu, 0x76DC4190u, 0x6B6B51F4u, 0x4DB26158u, 0x5005713Cu,
    0xEDB88320u, 0xF00F9344u, 0xD6D6A3E8u, 0xCB61B38Cu, 0x9B64C2B0u, 0x86D3D2D4u, 0xA00AE278u, 0xBDBDF21Cu
};

static uint32_t nibble(uint32_t crc)
{
#ifdef __AVR__
    return pgm_read_dword(&crc_nibble[crc & 15u]);
#else
    return crc_nibble[crc & 15u];
#endif
}

uint32_t proto_crc32(uint32_t crc, const uint8_t *p, size_t n)
{
    size_t i;
    crc = ~crc;
    for (i = 0; i < n; ++i) {
        crc ^= p[i];
        crc = (crc >> 4) ^ nibble(crc);
        crc = (crc >> 4) ^ nibble(crc);
    }
    return ~crc;
}

size_t proto_cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0; /* where the current block's code byte goes */
    size_t o = 1;
    uint8_t code = 1;
    size_t i;
    for (i = 0; i < n; ++i) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            if (++code == 0xFF) {
                out[code_at] = code;
                if (i + 1 == n) {
                    return o; /* canonical: no empty block after a full one at the end */
                }
                code_at = o++;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    return o;
}

long proto_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap)
{
    size_t i = 0;
    size_t o = 0;
    while (i < n) {
        const uint8_t code = in[i++];
        uint8_t j;
        if (code == 0) {
            return -1;
        }
        for (j = 1; j < code; ++j) {
            if (i >= n || in[i] == 0 || o >= cap) {
                return -1;
            }
            out[o++] = in[i++];
        }
        if (code != 0xFF && i < n) {
            if (o >= cap) {
                return -1;
            }
            out[o++] = 0;
        }
    }
    return (long)o;
}

size_t proto_seal_frame(uint8_t body[PROTO_MAX_BODY], uint8_t type, uint8_t seq, size_t len)
{
    body[PROTO_HEADER_TYPE] = type;
    body[PROTO_HEADER_SEQ] = seq;
    proto_put_u16(body + PROTO_HEADER_LEN, (uint16_t)len);
    proto_put_u32(body + PROTO_HEADER_SIZE + len, proto_crc32(0, body, PROTO_HEADER_SIZE + len));
    return PROTO_HEADER_SIZE + len + PROTO_CRC_SIZE;
}

void proto_cobs_emit(const uint8_t *in, size_t n, proto_emit_fn emit)
{
    static const uint8_t delimiter = 0;
    size_t i = 0;
    for (;;) {
        /* one block: up to 254 bytes before the next zero, led by its code byte */
        size_t run = 0;
        uint8_t code;
        while (i + run < n && in[i + run] != 0 && run < 254u) {
            ++run;
        }
        code = (uint8_t)(run + 1u);
        emit(&code, 1);
        emit(in + i, run);
        i += run;
        if (i < n && run < 254u) {
            ++i; /* the zero this block stands for */
        } else if (i >= n) {
            break; /* canonical: no empty block after a full one at the end */
        }
    }
    emit(&delimiter, 1);
}

size_t proto_finish_frame(uint8_t body[PROTO_MAX_BODY], uint8_t type, uint8_t seq, size_t len,
                          uint8_t wire[PROTO_MAX_WIRE])
{
    size_t n = proto_cobs_encode(body, proto_seal_frame(body, type, seq, len), wire);
    wire[n++] = 0;
    return n;
}

int proto_parse_frame(const uint8_t *enc, size_t n, uint8_t body[PROTO_MAX_BODY], proto_msg *msg)
{
    const long got = proto_cobs_decode(enc, n, body, PROTO_MAX_BODY);
    size_t size;
    if (got < (long)(PROTO_HEADER_SIZE + PROTO_CRC_SIZE)) {
        return PROTO_BAD_FRAME;
    }
    size = (size_t)got;
    msg->type = body[PROTO_HEADER_TYPE];
    msg->seq = body[PROTO_HEADER_SEQ];
    msg->len = proto_get_u16(body + PROTO_HEADER_LEN);
    msg->payload = body + PROTO_HEADER_SIZE;
    if ((size_t)msg->len != size - PROTO_HEADER_SIZE - PROTO_CRC_SIZE) {
        return PROTO_BAD_FRAME;
    }
    if (proto_crc32(0, body, size - PROTO_CRC_SIZE) != proto_get_u32(body + size - PROTO_CRC_SIZE)) {
        return PROTO_BAD_CRC;
    }
    return 0;
}

void proto_rx_init(proto_rx *rx)
{
    memset(rx, 0, sizeof *rx);
}

int proto_rx_feed(proto_rx *rx, uint8_t byte)
{
    if (rx->done) {
        rx->done = 0;
        rx->len = 0;
    }
    if (byte == 0) {
        if (rx->dropping) {
            rx->dropping = 0;
            rx->len = 0;
            return PROTO_RX_NONE;
        }
        if (rx->len == 0) {
            return PROTO_RX_NONE; /* empty frame: ignored */
        }
        rx->done = 1;
        return PROTO_RX_FRAME;
    }
    if (rx->dropping) {
        return PROTO_RX_NONE;
    }
    if (rx->len >= PROTO_MAX_ENCODED) {
        rx->dropping = 1;
        rx->len = 0;
        return PROTO_RX_OVERSIZE;
    }
    rx->buf[rx->len++] = byte;
    return PROTO_RX_NONE;
}
