/* inputs.h: where a sample's inputs come from. inputs_sim.c: simulated triangle waves, no hardware;
 * inputs_adc.c: the ADC drivers (adc.c) through the channel map (adc_map.h) over the port's I2C. */
#ifndef INPUTS_H
#define INPUTS_H

#include <stddef.h>
#include <stdint.h>

#include "model_api.h"

/* STREAM_SAMPLE status of a sample whose read failed (docs/protocol.md): this bit, the failed
 * chip + 1 in bits 8..15 (0: the general-call reset), and the adc.h status negated in bits 0..7;
 * its inputs and outputs are then 0: the model never sees a stale or made-up reading */
#define INPUTS_READ_FAILED 0x40000000u
/* the INFO block's largest size: the chip count, 8 chips, the I2C counts */
#define INPUTS_INFO_MAX (PROTO_ADC_BLOCK_SIZE + 8u * PROTO_ADC_CHIP_SIZE + PROTO_I2C_COUNTS_SIZE)

/* a sample's inputs: 0, or a negative adc.h status (then in[] holds zeros) */
int inputs_read(tm_input in[TM_N_INPUTS]);
/* the status word of a failed read (for STREAM_SAMPLE) */
uint32_t inputs_failure_status(int read_status);
/* the INFO block: number of chips (u8); per chip kind, address, inputs, PGA code, rate code, mode
 * (u8 each); the I2C counts nack, timeout, stuck, other, retries, resets (u32 each, little-endian).
 * Returns its length. */
size_t inputs_info(uint8_t *p);

#endif /* INPUTS_H */
