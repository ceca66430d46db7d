/* cal.c: see cal.h. Every length field is checked against the bytes left before it is used. */
#include "cal.h"

#include <math.h>

/* cal_estimate rounds as the header does only without contraction into fused multiply-adds
 * (GCC contracts by default in GNU modes on cores with an FMA); see tm_model.h */
#if defined(__clang__)
#pragma clang fp contract(off)
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#endif

#ifdef TM_FIXED_POINT

int cal_parse(cal_model *c, const uint8_t *blob, uint32_t size)
{
    (void)c;
    (void)blob;
    (void)size;
    return PROTO_CAL_INVALID; /* blobs carry reals; a fixed-point build takes none */
}

#else

/* exponent kinds in blob order: v, v^2, v^3, v^4, 1/v .. 1/v^4, v^(1/2), v^(1/3), v^(1/4) */
enum { K_P1, K_P2, K_P3, K_P4, K_M1, K_M2, K_M3, K_M4, K_R2, K_R3, K_R4 };
#define K_FIRST_NEEDING_POSITIVE K_M1 /* negative powers and roots: the input's minimum must be > 0 */
#define TERM_SIZE 4u
#define BARE_D 0xFFu /* element -1 as a byte */

/* printable ASCII, then NULs to the end of the field */
static int sensor_id_ok(const uint8_t *p)
{
    unsigned i = 0;
    while (i < CAL_SENSOR_SIZE && p[i] >= 0x20u && p[i] < 0x7Fu) {
        ++i;
    }
    for (; i < CAL_SENSOR_SIZE; ++i) {
        if (p[i] != 0) {
            return 0;
        }
    }
    return 1;
}

/* 1 when the term at t of an output's term list already appeared before it */
static int term_repeated(const uint8_t *terms, unsigned t)
{
    unsigned u;
    for (u = 0; u < t; ++u) {
        if (memcmp(terms + u * TERM_SIZE, terms + t * TERM_SIZE, TERM_SIZE) == 0) {
            return 1;
        }
    }
    return 0;
}

int cal_parse(cal_model *c, const uint8_t *b, uint32_t size)
{
    const uint32_t rs = (uint32_t)FW_REAL_SIZE;
    uint32_t end;
    uint32_t off;
    uint32_t total = 0;
    unsigned have_d = 0; /* bit s: d[s] has been output */
    int prev_pose = -1;
    unsigned k;
    unsigned j;

    if (size < 4u || size > CAL_CAPACITY) {
        return PROTO_CAL_INVALID;
    }
    end = size - 4u;
    if (proto_crc32(0, b, end) != proto_get_u32(b + end)) {
        return PROTO_CAL_CRC;
    }
    if (size < CAL_MIN_SIZE || !sensor_id_ok(b + CAL_SENSOR_OFFSET)) {
        return PROTO_CAL_INVALID;
    }
    if (memcmp(b, "TMCB", 4) != 0 || proto_get_u16(b + 4) != 1u || b[6] != FW_PRECISION || (b[7] & ~1u) != 0 ||
        b[56] != TM_N_INPUTS || b[57] != TM_N_OUTPUTS) {
        return PROTO_CAL_INVALID;
    }
    c->fma = (uint8_t)(b[7] & 1u);
    off = CAL_HEADER_SIZE;
    if (end - off < 2u * TM_N_INPUTS * rs) {
        return PROTO_CAL_INVALID;
    }
    for (k = 0; k < TM_N_INPUTS; ++k) {
        const tm_real lo = fw_get_real(b + off + k * rs);
        const tm_real hi = fw_get_real(b + off + (TM_N_INPUTS + k) * rs);
        if (!isfinite(lo) || !isfinite(hi) || !(lo <= hi)) {
            return PROTO_CAL_INVALID;
        }
        c->input_min[k] = lo;
        c->input_max[k] = hi;
        c->needed[k] = 0;
    }
    off += 2u * TM_N_INPUTS * rs;

    for (j = 0; j < TM_N_OUTPUTS; ++j) {
        cal_output *o = &c->out[j];
        unsigned pose;
        unsigned t;
        if (end - off < 4u + rs) {
            return PROTO_CAL_INVALID;
        }
        pose = b[off];
        o->d_slot = b[off + 1];
        o->n_terms = proto_get_u16(b + off + 2);
        o->intercept = fw_get_real(b + off + 4);
        if (pose > 4u || (int)pose <= prev_pose || !isfinite(o->intercept) ||
            (o->d_slot != 0 && (pose > 2u || o->d_slot != pose + 1u))) {
            return PROTO_CAL_INVALID;
        }
        prev_pose = (int)pose;
        off += 4u + rs;
        if ((uint32_t)o->n_terms * (TERM_SIZE + rs) > end - off) {
            return PROTO_CAL_INVALID;
        }
        o->terms = b + off;
        o->coefs = b + off + (uint32_t)o->n_terms * TERM_SIZE;
        for (t = 0; t < o->n_terms; ++t) {
            const uint8_t *term = o->terms + t * TERM_SIZE;
            const unsigned element = term[0];
            const unsigned exponent = term[1];
            const unsigned mult = term[2];
            if (term[3] != 0 || mult > 3u || (mult != 0 && !(have_d & (1u << mult))) ||
                (mult != 0 && exponent != K_P1) || term_repeated(o->terms, t) ||
                !isfinite(fw_get_real(o->coefs + t * rs))) {
                return PROTO_CAL_INVALID;
            }
            if (element == BARE_D) {
                if (mult == 0) {
                    return PROTO_CAL_INVALID;
                }
            } else {
                if (element >= TM_N_INPUTS || exponent >= CAL_N_KINDS ||
                    (exponent >= K_FIRST_NEEDING_POSITIVE && !(c->input_min[element] > 0))) {
                    return PROTO_CAL_INVALID;
                }
                c->needed[element] = (unsigned short)(c->needed[element] | (1u << exponent));
            }
        }
        off += (uint32_t)o->n_terms * (TERM_SIZE + rs);
        total += o->n_terms;
        if (o->d_slot) {
            have_d |= 1u << o->d_slot;
        }
    }
    if (off != end || total != proto_get_u16(b + 58)) {
        return PROTO_CAL_INVALID;
    }
    c->blob = b;
    c->size = size;
    return 0;
}

/* The table branch of model.h.j2, statement for statement: the same clamp, the same powers, the same
 * summation order, so the same roundings. */
int cal_estimate(const cal_model *c, const tm_input in[TM_N_INPUTS], tm_output out[TM_N_OUTPUTS])
{
    const uint32_t rs = (uint32_t)FW_REAL_SIZE;
    int status = 0;
    int k;
    unsigned j;
    tm_real x[TM_N_INPUTS];
    tm_real pw[TM_N_INPUTS][CAL_N_KINDS];
    tm_real d[4];

    for (k = 0; k < TM_N_INPUTS; ++k) {
        tm_real v = in[k];
        if (!(v >= c->input_min[k] && v <= c->input_max[k])) {
            if (!isfinite(v)) {
                for (k = 0; k < TM_N_OUTPUTS; ++k) {
                    out[k] = 0;
                }
                return TM_STATUS_NONFINITE;
            }
            v = v < c->input_min[k] ? c->input_min[k] : c->input_max[k];
            status |= 1 << k;
        }
        x[k] = v;
    }

    for (k = 0; k < TM_N_INPUTS; ++k) {
        const unsigned need = c->needed[k];
        const tm_real v = x[k];
        const tm_real v2 = v * v;
        if (need & (1u << K_P1)) pw[k][K_P1] = v;
        if (need & (1u << K_P2)) pw[k][K_P2] = v2;
        if (need & (1u << K_P3)) pw[k][K_P3] = v2 * v;
        if (need & (1u << K_P4)) pw[k][K_P4] = v2 * v2;
        if (need & (1u << K_M1)) pw[k][K_M1] = TM_ONE / v;
        if (need & (1u << K_M2)) pw[k][K_M2] = TM_ONE / v2;
        if (need & (1u << K_M3)) pw[k][K_M3] = TM_ONE / (v2 * v);
        if (need & (1u << K_M4)) pw[k][K_M4] = TM_ONE / (v2 * v2);
        if (need & (1u << K_R2)) pw[k][K_R2] = TM_SQRT(v);
        if (need & (1u << K_R3)) pw[k][K_R3] = TM_CBRT(v);
        if (need & (1u << K_R4)) pw[k][K_R4] = TM_SQRT(TM_SQRT(v));
    }

    d[0] = TM_ONE;
    d[1] = d[2] = d[3] = 0;
    for (j = 0; j < TM_N_OUTPUTS; ++j) {
        const cal_output *o = &c->out[j];
        tm_real acc = o->intercept;
        unsigned t;
        for (t = 0; t < o->n_terms; ++t) {
            const uint8_t *term = o->terms + t * TERM_SIZE;
            const tm_real coef = fw_get_real(o->coefs + t * rs);
            const tm_real base = term[0] == BARE_D ? TM_ONE : pw[term[0]][term[1]];
            if (c->fma) {
                acc = TM_FMA_OP(coef, base * d[term[2]], acc);
            } else {
                acc += coef * (base * d[term[2]]);
            }
        }
        out[j] = acc;
        if (o->d_slot) {
            d[o->d_slot] = acc;
        }
    }
    return status;
}

#endif /* TM_FIXED_POINT */
