/* cal.h: calibration blobs (format version 1 of docs/protocol.md): validation and an interpreter
 * that computes exactly what the table style of tm_model.h computes.
 */
#ifndef CAL_H
#define CAL_H

#include <stdint.h>

#include "model_api.h"

#define CAL_CAPACITY 4096u  /* the largest blob the format allows a device (calstore.h: what a store holds) */
#define CAL_HEADER_SIZE 60u /* up to n_terms_total */
#define CAL_MIN_SIZE (CAL_HEADER_SIZE + 4u)
#define CAL_HASH_OFFSET 8u
#define CAL_SENSOR_OFFSET 40u
#define CAL_SENSOR_SIZE 16u

/* A blob is read where it lies: in RAM, or with CAL_IN_EEPROM (the ATmega328P) at EEPROM addresses, its
 * pointers then EEPROM addresses as avr-libc's eeprom_read_* take them. */
#ifdef CAL_IN_EEPROM
#include <avr/eeprom.h>
#define CAL_U8(p) eeprom_read_byte(p)
#else
#define CAL_U8(p) (*(p))
#endif

/* n bytes of a blob into RAM; the CRC-32 of a blob's first n bytes (proto_crc32's) */
void cal_copy(uint8_t *dst, const uint8_t *blob, uint32_t n);
uint32_t cal_crc32(const uint8_t *blob, uint32_t n);

#ifndef TM_FIXED_POINT
typedef struct {
    uint8_t d_slot;         /* 1..3: this output's value is d[d_slot] for the terms after it */
    uint16_t n_terms;
    tm_real intercept;
    const uint8_t *terms;   /* n_terms x {element i8, exponent u8, mult u8, reserved u8} */
    const uint8_t *coefs;   /* n_terms reals */
} cal_output;

typedef struct {
    const uint8_t *blob;
    uint32_t size;
    uint8_t fma;            /* flags bit 0 */
    tm_real input_min[TM_N_INPUTS];
    tm_real input_max[TM_N_INPUTS];
    unsigned short needed[TM_N_INPUTS]; /* bit e: some term needs exponent kind e of this input */
    cal_output out[TM_N_OUTPUTS];
} cal_model;
#else
typedef struct {
    const uint8_t *blob;
    uint32_t size;
} cal_model;
#endif

/* Check a whole blob (blob[0 .. size)) and describe it in c, which points into blob.
 * Returns 0, PROTO_CAL_CRC (its trailer) or PROTO_CAL_INVALID; c is meaningless unless 0.
 * A fixed-point build accepts no blob. */
int cal_parse(cal_model *c, const uint8_t *blob, uint32_t size);

#ifndef TM_FIXED_POINT
/* tm_estimate with the blob's numbers: same status, same outputs, bit for bit */
int cal_estimate(const cal_model *c, const tm_input in[TM_N_INPUTS], tm_output out[TM_N_OUTPUTS]);
#endif

#endif /* CAL_H */
