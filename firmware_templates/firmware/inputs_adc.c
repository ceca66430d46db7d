/* inputs_adc.c: a sample's inputs from the ADC drivers (adc.c) through the channel map (adc_map.h,
 * rendered from the same map file `tactile-host read --adc` takes), over the port's I2C (hal_i2c).
 * The chips are probed and set up on the first read, as tactile-host read does before its first
 * sample, and again after a read that failed before they were ready. Float and double builds get
 * volts (code times the chip's LSB, in double as host/adc.py computes it); a fixed-point build gets
 * the codes themselves, whose LSB the render step checked against the model's. A thermistor in the
 * map is read after the elements every 0.25 s (host/temperature.py), and with INPUTS_TEMPCOMP the
 * volts are compensated (tm_tempcomp.h, in double) before they become the model's inputs. */
#include "adc.h"
#include "adc_map.h"
#include "hal.h"
#include "inputs.h"
#include "inputs_options.h"
#if ADC_HAS_TEMPERATURE
#include <math.h> /* NAN */
#endif
#if INPUTS_TEMPCOMP
#include "tm_tempcomp.h"
typedef char inputs_assert_tempcomp_fits_model[(TM_TEMPCOMP_N == TM_N_INPUTS) ? 1 : -1];
#endif

typedef char inputs_assert_map_fits_model[(ADC_MAP_N_ELEMENTS == TM_N_INPUTS) ? 1 : -1];

static adc_array array;
static int stage; /* 0: nothing done, 1: array planned, 2: chips probed and set up */
#if ADC_HAS_TEMPERATURE
#define TEMP_EVERY_NS 250000000u /* host/temperature.py READ_EVERY */
static adc_array tarray;
static double degc = (double)NAN;
static uint64_t t_last;
static int t_read;

static int read_temperature(void)
{
    const adc_i2c *bus = hal_i2c();
    const uint64_t now = bus->now_ns(bus->ctx);
    if (!t_read || now - t_last >= TEMP_EVERY_NS) {
        int32_t code;
        const int st = adc_read_codes(&tarray, &code);
        if (st != ADC_OK) {
            return st;
        }
        t_read = 1;
        t_last = now;
        degc = adc_code_degc(&ADC_TEMP_CHIP[0], code, ADC_TEMP_BETA, ADC_TEMP_R25,
                             ADC_TEMP_SERIES, ADC_TEMP_VREF);
    }
    return ADC_OK;
}
#endif
#ifndef TM_FIXED_POINT
static double lsb[TM_N_INPUTS];
#endif

static int ready(void)
{
    int st;
    if (stage == 0) {
        unsigned i, j;
        if (adc_init(&array, hal_i2c(), ADC_MAP, ADC_MAP_N_CHIPS, adc_default_policy()) != ADC_OK) {
            return ADC_ERR_CONFIG;
        }
#if ADC_HAS_TEMPERATURE
        if (adc_init(&tarray, hal_i2c(), ADC_TEMP_CHIP, 1, adc_default_policy()) != ADC_OK) {
            return ADC_ERR_CONFIG;
        }
#endif
#ifndef TM_FIXED_POINT
        for (i = 0; i < ADC_MAP_N_CHIPS; ++i) {
            for (j = 0; j < ADC_MAP[i].n_inputs; ++j) {
                lsb[ADC_MAP_FIRST_ELEMENT[i] + j] = adc_lsb_volts(&ADC_MAP[i]);
            }
        }
#else
        (void)i;
        (void)j;
#endif
        stage = 1;
    }
    if (stage == 1) {
        st = adc_probe(&array);
        if (st == ADC_OK) {
            st = adc_setup(&array);
        }
        if (st != ADC_OK) {
            return st;
        }
        stage = 2;
    }
    return ADC_OK;
}

int inputs_read(tm_input in[TM_N_INPUTS])
{
    int32_t codes[TM_N_INPUTS];
    unsigned i;
    int st = ready();
    if (st == ADC_OK) {
        st = adc_read_codes(&array, codes);
    }
#if ADC_HAS_TEMPERATURE
    if (st == ADC_OK) {
        st = read_temperature();
    }
#endif
#if INPUTS_TEMPCOMP
    {
        double v[TM_N_INPUTS];
        for (i = 0; i < TM_N_INPUTS; ++i) {
            v[i] = st == ADC_OK ? (double)codes[i] * lsb[i] : 0.0;
        }
        if (st == ADC_OK) {
            tm_tempcomp(v, degc);
        }
        for (i = 0; i < TM_N_INPUTS; ++i) {
            in[i] = (tm_input)v[i];
        }
    }
#else
    for (i = 0; i < TM_N_INPUTS; ++i) {
#ifdef TM_FIXED_POINT
        in[i] = st == ADC_OK ? codes[i] : 0;
#else
        in[i] = st == ADC_OK ? (tm_input)((double)codes[i] * lsb[i]) : 0;
#endif
    }
#endif
    return st;
}

uint32_t inputs_failure_status(int read_status)
{
    const uint32_t chip = stage >= 1 && array.failed_chip >= 0 ? (uint32_t)array.failed_chip + 1u : 0u;
    return INPUTS_READ_FAILED | (chip << 8) | ((uint32_t)(-read_status) & 0xFFu);
}

size_t inputs_info(uint8_t *p)
{
    const adc_counts *k = &array.counts;
    size_t n = PROTO_ADC_BLOCK_SIZE;
    unsigned i;
    p[PROTO_ADC_BLOCK_CHIPS] = ADC_MAP_N_CHIPS;
    for (i = 0; i < ADC_MAP_N_CHIPS; ++i, n += PROTO_ADC_CHIP_SIZE) {
        const adc_chip *c = &ADC_MAP[i];
        p[n + PROTO_ADC_CHIP_KIND] = c->kind;
        p[n + PROTO_ADC_CHIP_ADDRESS] = c->address;
        p[n + PROTO_ADC_CHIP_INPUTS] = c->n_inputs;
        p[n + PROTO_ADC_CHIP_PGA] = c->pga;
        p[n + PROTO_ADC_CHIP_RATE] = c->rate;
        p[n + PROTO_ADC_CHIP_MODE] = c->continuous;
    }
    proto_put_u32(p + n + PROTO_I2C_COUNTS_NACK, stage ? k->nack : 0u);
    proto_put_u32(p + n + PROTO_I2C_COUNTS_TIMEOUT, stage ? k->timeout : 0u);
    proto_put_u32(p + n + PROTO_I2C_COUNTS_STUCK, stage ? k->stuck : 0u);
    proto_put_u32(p + n + PROTO_I2C_COUNTS_OTHER, stage ? k->other : 0u);
    proto_put_u32(p + n + PROTO_I2C_COUNTS_RETRIES, stage ? k->retries : 0u);
    proto_put_u32(p + n + PROTO_I2C_COUNTS_RESETS, stage ? k->resets : 0u);
    return n + PROTO_I2C_COUNTS_SIZE;
}
