/* device.c: see device.h. Every request is answered by one reply or one ERROR; every length
 * field is checked before it is used, so no byte sequence can make the device hang or overrun. */
#include "device.h"

#include "hal.h"
#include "inputs.h"

enum {
    T_PING = 0x01,
    T_INFO = 0x02,
    T_EVAL = 0x03,
    T_STREAM = 0x04,
    T_CAL_BEGIN = 0x05,
    T_CAL_DATA = 0x06,
    T_CAL_COMMIT = 0x07,
    T_CAL_READ = 0x08,
    T_CAL_RESET = 0x09,
    T_BENCH = 0x0A,
    T_STREAM_SAMPLE = 0x85,
    T_ERROR = 0xFF
};

#define INFO_SIZE 68u
#define HASH_SIZE 32u
#define SENSOR_ID_SIZE 16u
#define FW_VERSION_SIZE 12u
#define EVAL_IN_SIZE ((size_t)TM_N_INPUTS * FW_INPUT_SIZE)
#define EVAL_OUT_SIZE (4u + (size_t)TM_N_OUTPUTS * FW_OUTPUT_SIZE)
#define SAMPLE_SIZE (10u + (size_t)TM_N_INPUTS * FW_INPUT_SIZE + (size_t)TM_N_OUTPUTS * FW_OUTPUT_SIZE)
#define CAL_DATA_MAX 248u
#define BENCH_MAX 1000000u

/* one vector in and one result out must fit a frame, and so must INFO with its ADC block */
typedef char device_assert_info_fits[(INFO_SIZE + INPUTS_INFO_MAX <= PROTO_MAX_PAYLOAD) ? 1 : -1];
typedef char device_assert_eval_fits[(EVAL_IN_SIZE <= PROTO_MAX_PAYLOAD && EVAL_OUT_SIZE <= PROTO_MAX_PAYLOAD) ? 1 : -1];

static volatile int bench_sink; /* keeps the BENCH loop's work observable */

static uint8_t *reply_payload(device *d)
{
    return d->out + PROTO_HEADER;
}

static void send(device *d, uint8_t type, uint8_t seq, size_t len)
{
    const size_t n = proto_finish_frame(d->out, type, seq, len, d->wire);
    hal_write(d->wire, n);
}

static void send_error(device *d, uint8_t seq, uint8_t code, uint8_t request_type)
{
    uint8_t *p = reply_payload(d);
    p[0] = code;
    p[1] = request_type;
    send(d, T_ERROR, seq, 2);
}

static void put_text(uint8_t *p, const char *s, size_t n)
{
    size_t i = 0;
    for (; i < n && s[i] != '\0'; ++i) {
        p[i] = (uint8_t)s[i];
    }
    for (; i < n; ++i) {
        p[i] = 0;
    }
}

static int estimate(device *d, const tm_input in[TM_N_INPUTS], tm_output out[TM_N_OUTPUTS])
{
#ifndef TM_FIXED_POINT
    if (d->use_blob) {
        return cal_estimate(&d->active, in, out);
    }
#else
    (void)d;
#endif
    return tm_estimate(in, out);
}

void device_init(device *d, const device_config *cfg)
{
    unsigned k;
    unsigned i;
    memset(d, 0, sizeof *d);
    d->cfg = cfg;
    proto_rx_init(&d->rx);
    /* BENCH vectors: input i of vector k at (2m + 1) / 32 of its range, m = (k + 5 i) mod 16 */
    for (k = 0; k < 16u; ++k) {
        for (i = 0; i < TM_N_INPUTS; ++i) {
            d->bench_in[k][i] = fw_input_at(i, 2u * ((k + 5u * i) % 16u) + 1u, 32u);
        }
    }
}

static void do_info(device *d, const proto_msg *m)
{
    uint8_t *p = reply_payload(d);
    if (m->len != 0) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    p[0] = PROTO_VERSION;
    p[1] = FW_PRECISION;
    p[2] = TM_N_INPUTS;
    p[3] = TM_N_OUTPUTS;
    p[4] = d->use_blob;
    p[5] = d->cfg->style;
    proto_put_u16(p + 6, PROTO_MAX_PAYLOAD);
    if (d->use_blob) {
        memcpy(p + 8, d->active_buf + CAL_HASH_OFFSET, HASH_SIZE);
        memcpy(p + 40, d->active_buf + CAL_SENSOR_OFFSET, SENSOR_ID_SIZE);
    } else {
        memcpy(p + 8, d->cfg->model_hash, HASH_SIZE);
        put_text(p + 40, d->cfg->sensor_id, SENSOR_ID_SIZE);
    }
    put_text(p + 56, d->cfg->fw_version, FW_VERSION_SIZE);
    send(d, (uint8_t)(m->type | 0x80u), m->seq, INFO_SIZE + inputs_info(p + INFO_SIZE));
}

static void do_eval(device *d, const proto_msg *m)
{
    uint8_t *p = reply_payload(d);
    const size_t k = m->len / EVAL_IN_SIZE;
    size_t v;
    if (m->len == 0 || m->len % EVAL_IN_SIZE != 0 || k * EVAL_OUT_SIZE > PROTO_MAX_PAYLOAD) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    for (v = 0; v < k; ++v) {
        tm_input in[TM_N_INPUTS];
        tm_output out[TM_N_OUTPUTS];
        const uint8_t *src = m->payload + v * EVAL_IN_SIZE;
        uint8_t *dst = p + v * EVAL_OUT_SIZE;
        unsigned i;
        int status;
        for (i = 0; i < TM_N_INPUTS; ++i) {
            in[i] = fw_get_input(src + i * FW_INPUT_SIZE);
        }
        status = estimate(d, in, out);
        proto_put_u32(dst, (uint32_t)status);
        for (i = 0; i < TM_N_OUTPUTS; ++i) {
            fw_put_output(dst + 4 + i * FW_OUTPUT_SIZE, out[i]);
        }
    }
    send(d, (uint8_t)(m->type | 0x80u), m->seq, k * EVAL_OUT_SIZE);
}

static void do_stream(device *d, const proto_msg *m)
{
    uint16_t period;
    uint16_t count;
    if (m->len != 4) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    period = proto_get_u16(m->payload);
    count = proto_get_u16(m->payload + 2);
    if (count != 0 && (period == 0 || SAMPLE_SIZE > PROTO_MAX_PAYLOAD)) {
        send_error(d, m->seq, PROTO_BAD_ARG, m->type);
        return;
    }
    send(d, (uint8_t)(m->type | 0x80u), m->seq, 0);
    if (count != 0) {
        d->stream_on = 1;
        d->stream_seq = m->seq;
        d->stream_period = period;
        d->stream_count = count;
        d->stream_index = 0;
        d->stream_next_ms = hal_millis() + period; /* the first sample one period from now */
    }
}

static void do_cal_begin(device *d, const proto_msg *m)
{
    uint32_t size;
    if (m->len != 8) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    d->stage_open = 0; /* an unfinished transfer is abandoned, whatever follows */
#ifdef TM_FIXED_POINT
    send_error(d, m->seq, PROTO_CAL_INVALID, m->type); /* blobs carry reals: none fits this build */
    return;
#endif
    size = proto_get_u32(m->payload);
    if (size == 0 || size > CAL_CAPACITY) {
        send_error(d, m->seq, PROTO_BAD_ARG, m->type);
        return;
    }
    d->stage_open = 1;
    d->stage_size = size;
    d->stage_crc = proto_get_u32(m->payload + 4);
    d->stage_received = 0;
    send(d, (uint8_t)(m->type | 0x80u), m->seq, 0);
}

static void do_cal_data(device *d, const proto_msg *m)
{
    uint32_t n;
    if (m->len < 5u || m->len > 4u + CAL_DATA_MAX) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    n = (uint32_t)m->len - 4u;
    if (!d->stage_open || proto_get_u32(m->payload) != d->stage_received || n > d->stage_size - d->stage_received) {
        send_error(d, m->seq, PROTO_CAL_SEQUENCE, m->type);
        return;
    }
    memcpy(d->stage_buf + d->stage_received, m->payload + 4, n);
    d->stage_received += n;
    proto_put_u32(reply_payload(d), d->stage_received);
    send(d, (uint8_t)(m->type | 0x80u), m->seq, 4);
}

static void do_cal_commit(device *d, const proto_msg *m)
{
    cal_model check;
    int rc;
    if (m->len != 0) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    if (!d->stage_open || d->stage_received != d->stage_size) {
        d->stage_open = 0;
        send_error(d, m->seq, PROTO_CAL_SEQUENCE, m->type);
        return;
    }
    d->stage_open = 0; /* whatever the verdict, the next transfer starts with CAL_BEGIN */
    if (proto_crc32(0, d->stage_buf, d->stage_size) != d->stage_crc) {
        send_error(d, m->seq, PROTO_CAL_CRC, m->type);
        return;
    }
    rc = cal_parse(&check, d->stage_buf, d->stage_size);
    if (rc != 0) {
        send_error(d, m->seq, (uint8_t)rc, m->type);
        return;
    }
    /* only now does the active calibration change */
    memcpy(d->active_buf, d->stage_buf, d->stage_size);
    d->active_size = d->stage_size;
    d->use_blob = cal_parse(&d->active, d->active_buf, d->active_size) == 0;
    memcpy(reply_payload(d), d->active_buf + CAL_HASH_OFFSET, HASH_SIZE);
    send(d, (uint8_t)(m->type | 0x80u), m->seq, HASH_SIZE);
}

static void do_cal_read(device *d, const proto_msg *m)
{
    uint32_t offset;
    uint32_t n;
    if (m->len != 6) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    offset = proto_get_u32(m->payload);
    n = proto_get_u16(m->payload + 4);
    if (!d->use_blob) {
        send_error(d, m->seq, PROTO_NO_CAL, m->type);
        return;
    }
    if (n == 0 || n > PROTO_MAX_PAYLOAD) {
        send_error(d, m->seq, PROTO_BAD_ARG, m->type);
        return;
    }
    if (offset >= d->active_size) {
        n = 0;
    } else if (n > d->active_size - offset) {
        n = d->active_size - offset;
    }
    if (n != 0) {
        memcpy(reply_payload(d), d->active_buf + offset, n);
    }
    send(d, (uint8_t)(m->type | 0x80u), m->seq, n);
}

static void do_cal_reset(device *d, const proto_msg *m)
{
    if (m->len != 0) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    d->use_blob = 0;
    send(d, (uint8_t)(m->type | 0x80u), m->seq, 0);
}

static void do_bench(device *d, const proto_msg *m)
{
    uint8_t *p = reply_payload(d);
    uint32_t n;
    uint32_t i;
    uint64_t t0;
    uint64_t t1;
    int acc = 0;
    if (m->len != 4) {
        send_error(d, m->seq, PROTO_BAD_LENGTH, m->type);
        return;
    }
    n = proto_get_u32(m->payload);
    if (n == 0 || n > BENCH_MAX) {
        send_error(d, m->seq, PROTO_BAD_ARG, m->type);
        return;
    }
    t0 = hal_ticks();
    for (i = 0; i < n; ++i) {
        acc += estimate(d, d->bench_in[i & 15u], d->bench_out);
    }
    t1 = hal_ticks();
    bench_sink = acc;
    proto_put_u64(p, t1 - t0);
    proto_put_u32(p + 8, hal_tick_hz());
    proto_put_u32(p + 12, n);
    send(d, (uint8_t)(m->type | 0x80u), m->seq, 16);
}

static void dispatch(device *d, const proto_msg *m)
{
    d->stream_on = 0; /* any request stops a running stream */
    switch (m->type) {
    case T_PING:
        memcpy(reply_payload(d), m->payload, m->len);
        send(d, (uint8_t)(m->type | 0x80u), m->seq, m->len);
        break;
    case T_INFO:
        do_info(d, m);
        break;
    case T_EVAL:
        do_eval(d, m);
        break;
    case T_STREAM:
        do_stream(d, m);
        break;
    case T_CAL_BEGIN:
        do_cal_begin(d, m);
        break;
    case T_CAL_DATA:
        do_cal_data(d, m);
        break;
    case T_CAL_COMMIT:
        do_cal_commit(d, m);
        break;
    case T_CAL_READ:
        do_cal_read(d, m);
        break;
    case T_CAL_RESET:
        do_cal_reset(d, m);
        break;
    case T_BENCH:
        do_bench(d, m);
        break;
    default:
        send_error(d, m->seq, PROTO_UNKNOWN_TYPE, m->type);
        break;
    }
}

void device_feed(device *d, uint8_t byte)
{
    const int r = proto_rx_feed(&d->rx, byte);
    if (r == PROTO_RX_OVERSIZE) {
        send_error(d, 0, PROTO_OVERSIZE, 0);
    } else if (r == PROTO_RX_FRAME) {
        proto_msg m;
        const int rc = proto_parse_frame(d->rx.buf, d->rx.len, d->body, &m);
        if (rc != 0) {
            send_error(d, 0, (uint8_t)rc, 0);
        } else {
            dispatch(d, &m);
        }
    }
}

void device_tick(device *d)
{
    uint8_t *p = reply_payload(d);
    tm_input in[TM_N_INPUTS];
    tm_output out[TM_N_OUTPUTS];
    uint32_t now;
    unsigned i;
    int status;
    if (!d->stream_on) {
        return;
    }
    now = hal_millis();
    if ((int32_t)(now - d->stream_next_ms) < 0) {
        return;
    }
    status = inputs_read(in);
    if (status < 0) {
        /* a failed read: flagged, and the model is not run on readings it did not get */
        status = (int)inputs_failure_status(status);
        for (i = 0; i < TM_N_OUTPUTS; ++i) {
            out[i] = 0;
        }
    } else {
        status = estimate(d, in, out);
    }
    proto_put_u16(p, d->stream_index);
    proto_put_u32(p + 2, now);
    proto_put_u32(p + 6, (uint32_t)status);
    for (i = 0; i < TM_N_INPUTS; ++i) {
        fw_put_input(p + 10 + i * FW_INPUT_SIZE, in[i]);
    }
    for (i = 0; i < TM_N_OUTPUTS; ++i) {
        fw_put_output(p + 10 + EVAL_IN_SIZE + i * FW_OUTPUT_SIZE, out[i]);
    }
    send(d, T_STREAM_SAMPLE, d->stream_seq, SAMPLE_SIZE);
    if (++d->stream_index >= d->stream_count) {
        d->stream_on = 0;
        return;
    }
    d->stream_next_ms += d->stream_period;
    if ((int32_t)(now - d->stream_next_ms) >= 0) {
        d->stream_next_ms = now + d->stream_period; /* fell behind by a whole period: no burst */
    }
}

uint32_t device_idle_ms(const device *d)
{
    int32_t left;
    if (!d->stream_on) {
        return HAL_IDLE_FOREVER;
    }
    left = (int32_t)(d->stream_next_ms - hal_millis());
    return left > 0 ? (uint32_t)left : 0u;
}
