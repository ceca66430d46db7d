/* model_api.h: the generated estimator tm_model.h, as every firmware file includes it.
 * TM_API becomes static inline so that the files that do not call tm_estimate compile
 * warning-free (an unused static function is a warning). Also the wire form of
 * tm_input / tm_output / tm_real: little-endian IEEE bytes (integers in a fixed-point build).
 */
#ifndef MODEL_API_H
#define MODEL_API_H

#ifndef TM_API
#define TM_API static inline
#endif
#include "tm_model.h"

#include <stdint.h>
#include <string.h>

#include "proto.h"

#ifdef TM_FIXED_POINT
#define FW_PRECISION PROTO_PRECISION_FIXED
#elif TM_PRECISION_FLOAT
#define FW_PRECISION PROTO_PRECISION_FLOAT
#else
#define FW_PRECISION PROTO_PRECISION_DOUBLE
#endif

#define FW_INPUT_SIZE (sizeof(tm_input))
#define FW_OUTPUT_SIZE (sizeof(tm_output))
typedef char fw_assert_wire_size[(sizeof(tm_input) == 4 || sizeof(tm_input) == 8) ? 1 : -1];

#ifdef TM_FIXED_POINT
/* int32 codes in, int32 Q-format outputs out */
static inline void fw_put_input(uint8_t *p, tm_input v)
{
    proto_put_u32(p, (uint32_t)v);
}

static inline tm_input fw_get_input(const uint8_t *p)
{
    return (tm_input)proto_get_u32(p);
}

#define fw_put_output fw_put_input

/* num/den of the way from input i's minimum to its maximum (num <= den); the bounds through TM_RD_I32: on AVR
 * they live in flash, where a plain load reads RAM at the same address */
static inline tm_input fw_input_at(unsigned i, uint32_t num, uint32_t den)
{
    const int64_t lo = TM_RD_I32(&tm_input_min[i]), span = (int64_t)TM_RD_I32(&tm_input_max[i]) - lo;
    return (tm_input)(lo + span * (int64_t)num / (int64_t)den);
}
#else
#define FW_REAL_SIZE (sizeof(tm_real))

/* a real's bytes go through an unsigned integer of its size: the order is the integer's (little-endian) */
#if TM_PRECISION_FLOAT
typedef uint32_t fw_real_bits;
#define fw_put_bits proto_put_u32
#define fw_get_bits proto_get_u32
#else
typedef uint64_t fw_real_bits;
#define fw_put_bits proto_put_u64
#define fw_get_bits proto_get_u64
#endif
typedef char fw_assert_real_bits[(sizeof(fw_real_bits) == sizeof(tm_real)) ? 1 : -1];

static inline void fw_put_real(uint8_t *p, tm_real v)
{
    fw_real_bits u;
    memcpy(&u, &v, sizeof u);
    fw_put_bits(p, u);
}

static inline tm_real fw_get_real(const uint8_t *p)
{
    const fw_real_bits u = fw_get_bits(p);
    tm_real v;
    memcpy(&v, &u, sizeof v);
    return v;
}

#define fw_put_input fw_put_real
#define fw_get_input fw_get_real
#define fw_put_output fw_put_real

/* num/den of the way from input i's minimum to its maximum (num <= den); the bounds through TM_RD_REAL (flash
 * on AVR) */
static inline tm_input fw_input_at(unsigned i, uint32_t num, uint32_t den)
{
    const tm_real frac = (tm_real)num / (tm_real)den, lo = TM_RD_REAL(&tm_input_min[i]);
    return lo + (TM_RD_REAL(&tm_input_max[i]) - lo) * frac;
}
#endif

#endif /* MODEL_API_H */
