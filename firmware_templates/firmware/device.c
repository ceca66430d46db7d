/* device.c: see device.h. Every request is answered by one reply or one ERROR; every length
 * field is checked before it is used, so no byte sequence can make the device hang or overrun.
 * The protocol's numbers and offsets are proto_defs.h's (rendered from host/protocol.py). */
#include "device.h"

#include "hal.h"
#include "inputs.h"
#ifdef DEVICE_BENCH_INPUTS
#include "bench_inputs.h" /* BENCH's vectors given at the render (hil.firmware): readings a pose gives */
#endif

#define EVAL_IN_SIZE ((size_t)TM_N_INPUTS * FW_INPUT_SIZE)
#define EVAL_OUT_SIZE (PROTO_EVAL_RESULT_SIZE + (size_t)TM_N_OUTPUTS * FW_OUTPUT_SIZE)
#define SAMPLE_SIZE (PROTO_SAMPLE_SIZE + EVAL_IN_SIZE + (size_t)TM_N_OUTPUTS * FW_OUTPUT_SIZE)

/* one vector in and one result out must fit a frame, and so must INFO with its ADC block */
typedef char device_assert_info_fits[(PROTO_INFO_SIZE + INPUTS_INFO_MAX <= PROTO_MAX_PAYLOAD) ? 1 : -1];
typedef char device_assert_eval_fits[(EVAL_IN_SIZE <= PROTO_MAX_PAYLOAD && EVAL_OUT_SIZE <= PROTO_MAX_PAYLOAD) ? 1 : -1];

static volatile int bench_sink; /* keeps the BENCH loop's work observable */

static uint8_t *reply_payload(device *d)
{
    return d->out + PROTO_HEADER_SIZE;
}

static void send(device *d, uint8_t type, uint8_t seq, size_t len)
{
    /* encoded straight onto the link: no wire buffer (an ATmega328P has 2 KB of RAM) */
    proto_cobs_emit(d->out, proto_seal_frame(d->out, type, seq, len), hal_write);
}

static void send_error(device *d, uint8_t seq, uint8_t code, uint8_t request_type)
{
    uint8_t *p = reply_payload(d);
    p[PROTO_ERROR_CODE] = code;
    p[PROTO_ERROR_REQUEST_TYPE] = request_type;
    send(d, PROTO_MSG_ERROR, seq, PROTO_ERROR_SIZE);
}

/* the reply to m: len bytes at reply_payload(d) */
static void reply(device *d, const proto_msg *m, size_t len)
{
    send(d, (uint8_t)(m->type | PROTO_REPLY), m->seq, len);
}

static void refuse(device *d, const proto_msg *m, int code)
{
    send_error(d, m->seq, (uint8_t)code, m->type);
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
    memset(d, 0, sizeof *d);
    d->cfg = cfg;
    proto_rx_init(&d->rx);
    d->use_blob = calstore_active_size() != 0 &&
                  cal_parse(&d->active, calstore_active(), calstore_active_size()) == 0;
#ifdef DEVICE_BENCH_INPUTS
    memcpy(d->bench_in, device_bench_inputs, sizeof d->bench_in);
#else
    {
        /* BENCH vectors: input i of vector k at (2m + 1) / 32 of its range, m = (k + 5 i) mod 16. Each input moves
         * apart from the others: readings no pose gives, which cost the equations what any reading does, but stop
         * a refinement's step part-way (its forward model is undefined at their far-off first estimate) */
        unsigned k;
        unsigned i;
        for (k = 0; k < DEVICE_BENCH_VECTORS; ++k) {
            for (i = 0; i < TM_N_INPUTS; ++i) {
                d->bench_in[k][i] = fw_input_at(i, 2u * ((k + 5u * i) % 16u) + 1u, 32u);
            }
        }
    }
#endif
}

/* The handlers: each runs on a payload whose length lies in its row of `requests` below. */

static void do_ping(device *d, const proto_msg *m)
{
    memcpy(reply_payload(d), m->payload, m->len);
    reply(d, m, m->len);
}

static void do_info(device *d, const proto_msg *m)
{
    uint8_t *p = reply_payload(d);
    p[PROTO_INFO_VERSION] = PROTO_VERSION;
    p[PROTO_INFO_PRECISION] = FW_PRECISION;
    p[PROTO_INFO_N_INPUTS] = TM_N_INPUTS;
    p[PROTO_INFO_N_OUTPUTS] = TM_N_OUTPUTS;
    p[PROTO_INFO_CAL_SOURCE] = d->use_blob;
    p[PROTO_INFO_STYLE] = d->cfg->style;
    proto_put_u16(p + PROTO_INFO_MAX_PAYLOAD, PROTO_MAX_PAYLOAD);
    if (d->use_blob) {
        cal_copy(p + PROTO_INFO_HASH, calstore_active() + CAL_HASH_OFFSET, PROTO_HASH_SIZE);
        cal_copy(p + PROTO_INFO_SENSOR_ID, calstore_active() + CAL_SENSOR_OFFSET, PROTO_SENSOR_ID_SIZE);
    } else {
        PROTO_ROM_COPY(p + PROTO_INFO_HASH, d->cfg->model_hash, PROTO_HASH_SIZE);
        put_text(p + PROTO_INFO_SENSOR_ID, d->cfg->sensor_id, PROTO_SENSOR_ID_SIZE);
    }
    put_text(p + PROTO_INFO_FW_VERSION, d->cfg->fw_version, PROTO_FW_VERSION_SIZE);
    reply(d, m, PROTO_INFO_SIZE + inputs_info(p + PROTO_INFO_SIZE));
}

static void do_eval(device *d, const proto_msg *m)
{
    uint8_t *p = reply_payload(d);
    const size_t k = m->len / EVAL_IN_SIZE;
    size_t v;
    if (m->len % EVAL_IN_SIZE != 0 || k * EVAL_OUT_SIZE > PROTO_MAX_PAYLOAD) {
        refuse(d, m, PROTO_BAD_LENGTH);
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
        proto_put_u32(dst + PROTO_EVAL_RESULT_STATUS, (uint32_t)status);
        for (i = 0; i < TM_N_OUTPUTS; ++i) {
            fw_put_output(dst + PROTO_EVAL_RESULT_SIZE + i * FW_OUTPUT_SIZE, out[i]);
        }
    }
    reply(d, m, k * EVAL_OUT_SIZE);
}

static void do_stream(device *d, const proto_msg *m)
{
    const uint16_t period = proto_get_u16(m->payload + PROTO_STREAM_PERIOD_MS);
    const uint16_t count = proto_get_u16(m->payload + PROTO_STREAM_COUNT);
    if (count != 0 && (period == 0 || SAMPLE_SIZE > PROTO_MAX_PAYLOAD)) {
        refuse(d, m, PROTO_BAD_ARG);
        return;
    }
    reply(d, m, 0);
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
    d->stage_open = 0; /* an unfinished transfer is abandoned, whatever follows */
#ifdef TM_FIXED_POINT
    refuse(d, m, PROTO_CAL_INVALID); /* blobs carry reals: none fits this build */
    return;
#endif
    size = proto_get_u32(m->payload + PROTO_CAL_BEGIN_TOTAL);
    if (size == 0 || size > CALSTORE_CAPACITY) {
        refuse(d, m, PROTO_BAD_ARG);
        return;
    }
    d->stage_open = 1;
    d->stage_size = size;
    d->stage_crc = proto_get_u32(m->payload + PROTO_CAL_BEGIN_CRC);
    d->stage_received = 0;
    reply(d, m, 0);
}

static void do_cal_data(device *d, const proto_msg *m)
{
    const uint32_t n = (uint32_t)m->len - PROTO_CAL_DATA_SIZE;
    if (!d->stage_open || proto_get_u32(m->payload + PROTO_CAL_DATA_OFFSET) != d->stage_received ||
        n > d->stage_size - d->stage_received) {
        refuse(d, m, PROTO_CAL_SEQUENCE);
        return;
    }
    calstore_stage_write(d->stage_received, m->payload + PROTO_CAL_DATA_SIZE, n);
    d->stage_received += n;
    proto_put_u32(reply_payload(d) + PROTO_CAL_DATA_REPLY_RECEIVED, d->stage_received);
    reply(d, m, PROTO_CAL_DATA_REPLY_SIZE);
}

static void do_cal_commit(device *d, const proto_msg *m)
{
    cal_model check;
    int rc;
    if (!d->stage_open || d->stage_received != d->stage_size) {
        d->stage_open = 0;
        refuse(d, m, PROTO_CAL_SEQUENCE);
        return;
    }
    d->stage_open = 0; /* whatever the verdict, the next transfer starts with CAL_BEGIN */
    if (cal_crc32(calstore_staged(), d->stage_size) != d->stage_crc) {
        refuse(d, m, PROTO_CAL_CRC);
        return;
    }
    rc = cal_parse(&check, calstore_staged(), d->stage_size);
    if (rc != 0) {
        refuse(d, m, rc);
        return;
    }
    /* only now does the active calibration change */
    calstore_commit(d->stage_size);
    d->use_blob = cal_parse(&d->active, calstore_active(), d->stage_size) == 0;
    cal_copy(reply_payload(d), calstore_active() + CAL_HASH_OFFSET, PROTO_HASH_SIZE);
    reply(d, m, PROTO_HASH_SIZE);
}

static void do_cal_read(device *d, const proto_msg *m)
{
    const uint32_t offset = proto_get_u32(m->payload + PROTO_CAL_READ_OFFSET);
    uint32_t n = proto_get_u16(m->payload + PROTO_CAL_READ_LENGTH);
    if (!d->use_blob) {
        refuse(d, m, PROTO_NO_CAL);
        return;
    }
    if (n == 0 || n > PROTO_CAL_READ_MAX) {
        refuse(d, m, PROTO_BAD_ARG);
        return;
    }
    if (offset >= d->active.size) {
        n = 0;
    } else if (n > d->active.size - offset) {
        n = d->active.size - offset;
    }
    if (n != 0) {
        cal_copy(reply_payload(d), calstore_active() + offset, n);
    }
    reply(d, m, n);
}

static void do_cal_reset(device *d, const proto_msg *m)
{
    d->use_blob = 0;
    calstore_clear();
    reply(d, m, 0);
}

static void do_bench(device *d, const proto_msg *m)
{
    uint8_t *p = reply_payload(d);
    const uint32_t n = proto_get_u32(m->payload + PROTO_BENCH_N);
    uint32_t i;
    uint64_t t0;
    uint64_t t1;
    int acc = 0;
    if (n == 0 || n > PROTO_BENCH_MAX) {
        refuse(d, m, PROTO_BAD_ARG);
        return;
    }
    t0 = hal_ticks();
    for (i = 0; i < n; ++i) {
        acc += estimate(d, d->bench_in[i % DEVICE_BENCH_VECTORS], d->bench_out);
    }
    t1 = hal_ticks();
    bench_sink = acc;
    proto_put_u64(p + PROTO_BENCH_REPLY_TICKS, t1 - t0);
    proto_put_u32(p + PROTO_BENCH_REPLY_TICK_HZ, hal_tick_hz());
    proto_put_u32(p + PROTO_BENCH_REPLY_N, n);
    reply(d, m, PROTO_BENCH_REPLY_SIZE);
}

/* every request type: the payload lengths it takes (any other: BAD_LENGTH) and its handler */
typedef struct {
    uint8_t type;
    uint16_t min_len;
    uint16_t max_len;
    void (*run)(device *d, const proto_msg *m);
} request_row;

static const request_row requests[] PROTO_ROM = {
    { PROTO_MSG_PING, 0u, PROTO_MAX_PAYLOAD, do_ping },
    { PROTO_MSG_INFO, 0u, 0u, do_info },
    { PROTO_MSG_EVAL, 1u, PROTO_MAX_PAYLOAD, do_eval },
    { PROTO_MSG_STREAM, PROTO_STREAM_SIZE, PROTO_STREAM_SIZE, do_stream },
    { PROTO_MSG_CAL_BEGIN, PROTO_CAL_BEGIN_SIZE, PROTO_CAL_BEGIN_SIZE, do_cal_begin },
    { PROTO_MSG_CAL_DATA, PROTO_CAL_DATA_SIZE + 1u, PROTO_CAL_DATA_SIZE + PROTO_CAL_DATA_MAX, do_cal_data },
    { PROTO_MSG_CAL_COMMIT, 0u, 0u, do_cal_commit },
    { PROTO_MSG_CAL_READ, PROTO_CAL_READ_SIZE, PROTO_CAL_READ_SIZE, do_cal_read },
    { PROTO_MSG_CAL_RESET, 0u, 0u, do_cal_reset },
    { PROTO_MSG_BENCH, PROTO_BENCH_SIZE, PROTO_BENCH_SIZE, do_bench }
};

static void dispatch(device *d, const proto_msg *m)
{
    size_t r;
    d->stream_on = 0; /* any request stops a running stream */
    for (r = 0; r < sizeof requests / sizeof requests[0]; ++r) {
        request_row row;
        PROTO_ROM_COPY(&row, &requests[r], sizeof row);
        if (row.type == m->type) {
            if (m->len < row.min_len || m->len > row.max_len) {
                refuse(d, m, PROTO_BAD_LENGTH);
            } else {
                row.run(d, m);
            }
            return;
        }
    }
    refuse(d, m, PROTO_UNKNOWN_TYPE);
}

void device_feed(device *d, uint8_t byte)
{
    const int r = proto_rx_feed(&d->rx, byte);
    if (r == PROTO_RX_OVERSIZE) {
        send_error(d, 0, PROTO_OVERSIZE, 0);
    } else if (r == PROTO_RX_FRAME) {
        proto_msg m;
        /* decoded in place: COBS decoding never writes ahead of what it reads */
        const int rc = proto_parse_frame(d->rx.buf, d->rx.len, d->rx.buf, &m);
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
    int32_t status; /* a failed read's status word needs 32 bits (int has 16 on AVR) */
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
        status = (int32_t)inputs_failure_status((int)status);
        for (i = 0; i < TM_N_OUTPUTS; ++i) {
            out[i] = 0;
        }
    } else {
        status = estimate(d, in, out);
    }
    proto_put_u16(p + PROTO_SAMPLE_INDEX, d->stream_index);
    proto_put_u32(p + PROTO_SAMPLE_TIME_MS, now);
    proto_put_u32(p + PROTO_SAMPLE_STATUS, (uint32_t)status);
    for (i = 0; i < TM_N_INPUTS; ++i) {
        fw_put_input(p + PROTO_SAMPLE_SIZE + i * FW_INPUT_SIZE, in[i]);
    }
    for (i = 0; i < TM_N_OUTPUTS; ++i) {
        fw_put_output(p + PROTO_SAMPLE_SIZE + EVAL_IN_SIZE + i * FW_OUTPUT_SIZE, out[i]);
    }
    send(d, PROTO_MSG_STREAM_SAMPLE, d->stream_seq, SAMPLE_SIZE);
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
