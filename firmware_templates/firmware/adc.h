/* adc.h: TI ADS1115 and ADS7828 drivers over I2C, and the array that reads every sensor element.
 *
 * The same behaviour, defaults and channel-map semantics as host/adc.py (the Python drivers):
 * ADS1115 single-shot (OS bit polled under a time limit) or continuous, PGA and data rate,
 * single-ended or differential; ADS7828 with its interleaved channel codes and internal or
 * external reference; chips converting in parallel, round by round; transient I2C errors retried
 * with back-off and counted; a stuck conversion answered with a general-call reset. A chip that
 * stays silent is an error status, never a hang: every wait has a time limit and every loop a bound.
 *
 * A port implements adc_i2c: three transfers that return ADC_I2C_OK or an error kind, and a clock.
 * C99, no malloc, no globals.
 */
#ifndef ADC_H
#define ADC_H

#include <stdint.h>

/* what a port's transfers return */
#define ADC_I2C_OK 0
#define ADC_I2C_NACK 1    /* the address or a byte was not acknowledged (Linux: EREMOTEIO, ENXIO) */
#define ADC_I2C_TIMEOUT 2 /* the bus did not finish in time (Linux: ETIMEDOUT) */
#define ADC_I2C_OTHER 3   /* anything else */

typedef struct {
    void *ctx;
    /* a write of n bytes; a read of n bytes; a write then, after a repeated start, a read */
    int (*write)(void *ctx, uint8_t addr, const uint8_t *data, uint16_t n);
    int (*read)(void *ctx, uint8_t addr, uint8_t *data, uint16_t n);
    int (*write_read)(void *ctx, uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr);
    uint64_t (*now_ns)(void *ctx); /* monotonic */
    void (*sleep_ns)(void *ctx, uint64_t ns);
} adc_i2c;

/* a build may size the array for its channel map (hil/firmware.py does for the Uno) */
#ifndef ADC_MAX_CHIPS
#if defined(__AVR__)
/* an 8-bit core's 2 KB of RAM: four chips (every address the parts take) of four inputs (the array holds
 * about 550 bytes instead of 990) */
#define ADC_MAX_CHIPS 4
#define ADC_MAX_ELEMENTS 16
#else
#define ADC_MAX_CHIPS 8
#define ADC_MAX_ELEMENTS 32
#endif
#endif
#define ADC_SINGLE_ENDED 0xFFu /* adc_chip.neg[] of a single-ended input */

enum { ADC_ADS1115 = 0, ADC_ADS7828 = 1 };

typedef struct {
    uint8_t kind;          /* ADC_ADS1115 or ADC_ADS7828 */
    uint8_t address;       /* 0x48..0x4b */
    uint8_t n_inputs;      /* elements this chip reads, in element order */
    uint8_t pos[8];        /* per element: input (ADS1115 AIN0..3, ADS7828 CH0..7) */
    uint8_t neg[8];        /* ADS1115 differential: the negative input; else ADC_SINGLE_ENDED */
    uint8_t pga;           /* ADS1115: PGA code 0..5 (+-6.144 .. 0.256 V) */
    uint8_t rate;          /* ADS1115: data-rate code 0..7 (8 .. 860 SPS) */
    uint8_t continuous;    /* ADS1115: 1 continuous mode, 0 single-shot */
    uint8_t vref_internal; /* ADS7828: 1 the internal 2.5 V reference, 0 external */
    double vref;           /* ADS7828: the external reference, V (unused with the internal one); double, as the
                              host computes its LSB: 3.3 in float is not 3.3 */
} adc_chip;

typedef struct {
    uint32_t nack, timeout, stuck, other; /* failed transfers (and stuck conversions) by kind */
    uint32_t retries, resets;
} adc_counts;

typedef struct {
    uint8_t attempts;         /* tries per transfer and per conversion (host/adc.py RetryPolicy: 5) */
    uint64_t first_delay_ns;  /* back-off: first, first * factor, ... up to max (1 ms, x2, 50 ms) */
    uint32_t factor;
    uint64_t max_delay_ns;
} adc_policy;

/* statuses of the array's calls (negative: the read failed, no code is valid) */
#define ADC_OK 0
#define ADC_ERR_CONFIG (-1)    /* a bad channel map: too many chips or inputs, an input that does not exist */
#define ADC_ERR_SILENT (-2)    /* a chip kept failing on every try (failed_chip says which) */
#define ADC_ERR_STUCK (-3)     /* a conversion never completed, resets between the tries */
#define ADC_ERR_NOT_CHIP (-4)  /* probe: the chip at that address answers as another part */

typedef struct {
    uint8_t chip, slot, element;
} adc_item;

typedef struct {
    adc_item single[ADC_MAX_CHIPS];   /* single-shot conversions started this round */
    adc_item change[ADC_MAX_CHIPS];   /* continuous mode, input changed each round */
    adc_item fixed[ADC_MAX_CHIPS];    /* continuous mode on its only input: read only */
    adc_item direct[ADC_MAX_ELEMENTS]; /* ADS7828: converted inside the read */
    uint8_t n_single, n_change, n_fixed, n_direct;
    uint64_t wait_ns;
} adc_round;

typedef struct {
    const adc_i2c *bus;
    const adc_chip *chips;
    uint8_t n_chips, n_elements, n_rounds;
    adc_policy policy;
    adc_counts counts;
    int failed_chip;  /* the chip of the last error status, -1 for the general call */
    adc_round rounds[4];
    uint64_t period_ns[ADC_MAX_CHIPS], timeout_ns[ADC_MAX_CHIPS], poll_ns[ADC_MAX_CHIPS];
    uint16_t config[ADC_MAX_CHIPS]; /* ADS1115: PGA, data rate and comparator bits */
} adc_array;

/* the Python drivers' defaults */
adc_policy adc_default_policy(void);
/* check the map and plan the rounds; ADC_OK or ADC_ERR_CONFIG */
int adc_init(adc_array *a, const adc_i2c *bus, const adc_chip *chips, uint8_t n_chips, adc_policy policy);
/* every chip answers as the part it is said to be */
int adc_probe(adc_array *a);
/* continuous-mode chips with one input: select it and wait for the first conversion */
int adc_setup(adc_array *a);
/* one code per element (ADS1115: signed 16-bit, ADS7828: 0..4095) */
int adc_read_codes(adc_array *a, int32_t codes[]);
/* volts per code of an element's chip */
double adc_lsb_volts(const adc_chip *c);
/* the temperature (degC) of an NTC divider's voltage: the NTC (beta model, r25 ohms at 25 degC) to ground,
 * `series` ohms to `vref`, as host/temperature.py computes it; NAN for an open or shorted NTC */
double adc_ntc_degc(double volts, double beta, double r25, double series, double vref);
/* a thermistor's rated range (degC, host/temperature.py's T_RANGE): outside it a reading is a fault, not a
 * temperature (an open NTC against an ADS1115's input reads about -72) */
#define ADC_DEGC_MIN (-40.0)
#define ADC_DEGC_MAX 125.0
/* adc_ntc_degc of a code of chip c; NaN where the code is the chip's full scale (the divider's voltage past what
 * the chip reads at its gain: clipped, it would read as another temperature) or the temperature lies outside
 * ADC_DEGC_MIN..ADC_DEGC_MAX, where a compensation would be extrapolated by as much */
double adc_code_degc(const adc_chip *c, int32_t code, double beta, double r25, double series, double vref);
/* the ADS1115 config word and the ADS7828 command byte (for tests and the docs) */
uint16_t adc_ads1115_config(const adc_array *a, uint8_t chip, uint8_t slot, int single, int start);
uint8_t adc_ads7828_command(const adc_chip *c, uint8_t slot);

#endif /* ADC_H */
