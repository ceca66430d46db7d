/* adc.c: TI ADS1115 and ADS7828 drivers and the element array (see adc.h; the Python twin is
 * host/adc.py, whose comments cite the datasheets, SBAS444 and SBAS181). */
#include "adc.h"

#include <math.h>
#include <stddef.h>

/* ADS1115 */
#define REG_CONVERSION 0x00u
#define REG_CONFIG 0x01u
#define OS_BIT 0x8000u
#define MODE_SINGLE 0x0100u
#define COMP_DISABLE 0x0003u
#define WAKE_NS 25000u             /* power-up from power-down before a single-shot conversion */
#define GENERAL_CALL 0x00u
#define RESET_COMMAND 0x06u
/* ADS7828 */
#define SD_SINGLE 0x80u
#define PD_REF_ON 0x08u
#define PD_ADC_ON 0x04u
/* polls of a conversion: its time limit ends them first; this bounds the loop whatever the clock does */
#define MAX_POLLS 100000u

static const uint16_t RATES[8] = { 8, 16, 32, 64, 128, 250, 475, 860 };
static const double PGA_VOLTS[6] = { 6.144, 4.096, 2.048, 1.024, 0.512, 0.256 };

adc_policy adc_default_policy(void)
{
    adc_policy p;
    p.attempts = 5;
    p.first_delay_ns = 1000000u;
    p.factor = 2;
    p.max_delay_ns = 50000000u;
    return p;
}

double adc_lsb_volts(const adc_chip *c)
{
    if (c->kind == ADC_ADS1115) {
        return PGA_VOLTS[c->pga] / 32768.0;
    }
    return (c->vref_internal ? 2.5 : c->vref) / 4096.0;
}

double adc_ntc_degc(double volts, double beta, double r25, double series, double vref)
{
    double r;
    if (!(volts > 0.0 && volts < vref)) {
        return (double)NAN; /* NAN is a float: widened on purpose, not by -Wdouble-promotion's implicit rule */
    }
    r = series * volts / (vref - volts);
    return 1.0 / (1.0 / 298.15 + log(r / r25) / beta) - 273.15;
}

double adc_code_degc(const adc_chip *c, int32_t code, double beta, double r25, double series, double vref)
{
    const int32_t top = c->kind == ADC_ADS1115 ? 32767 : 4095;
    double t;
    if (code >= top) { /* the divider past what the chip reads: a clipped code reads as another temperature */
        return (double)NAN;
    }
    t = adc_ntc_degc(code * adc_lsb_volts(c), beta, r25, series, vref);
    return t >= ADC_DEGC_MIN && t <= ADC_DEGC_MAX ? t : (double)NAN; /* NaN fails both: stays NaN */
}

/* the MUX code of an input: single-ended AINx 100..111, pairs 000 (0-1) 001 (0-3) 010 (1-3) 011 (2-3) */
static int ads1115_mux(uint8_t pos, uint8_t neg)
{
    if (neg == ADC_SINGLE_ENDED) {
        return pos <= 3 ? 4 + pos : -1;
    }
    if (pos == 0 && neg == 1) return 0;
    if (pos == 0 && neg == 3) return 1;
    if (pos == 1 && neg == 3) return 2;
    if (pos == 2 && neg == 3) return 3;
    return -1;
}

uint16_t adc_ads1115_config(const adc_array *a, uint8_t chip, uint8_t slot, int single, int start)
{
    const adc_chip *c = &a->chips[chip];
    const int mux = ads1115_mux(c->pos[slot], c->neg[slot]);
    return (uint16_t)((start ? OS_BIT : 0u) | ((unsigned)mux << 12) | a->config[chip] | (single ? MODE_SINGLE : 0u));
}

uint8_t adc_ads7828_command(const adc_chip *c, uint8_t slot)
{
    const unsigned ch = c->pos[slot];
    const unsigned code = ((ch & 1u) << 2) | (ch >> 1); /* interleaved: CH0 000, CH1 100, CH2 001, ... */
    return (uint8_t)(SD_SINGLE | (code << 4) | (c->vref_internal ? (PD_REF_ON | PD_ADC_ON) : PD_ADC_ON));
}

static uint64_t max_u64(uint64_t x, uint64_t y)
{
    return x > y ? x : y;
}

int adc_init(adc_array *a, const adc_i2c *bus, const adc_chip *chips, uint8_t n_chips, adc_policy policy)
{
    unsigned i, j, el = 0, n_rounds = 1;
    a->bus = bus;
    a->chips = chips;
    a->n_chips = n_chips;
    a->policy = policy;
    a->counts.nack = a->counts.timeout = a->counts.stuck = a->counts.other = 0;
    a->counts.retries = a->counts.resets = 0;
    a->failed_chip = -1;
    if (n_chips == 0 || n_chips > ADC_MAX_CHIPS || policy.attempts < 1 || policy.factor < 1) {
        return ADC_ERR_CONFIG;
    }
    for (i = 0; i < 4; ++i) {
        a->rounds[i].n_single = a->rounds[i].n_change = a->rounds[i].n_fixed = a->rounds[i].n_direct = 0;
        a->rounds[i].wait_ns = 0;
    }
    for (i = 0; i < n_chips; ++i) {
        const adc_chip *c = &chips[i];
        if (c->address < 0x48 || c->address > 0x4B || c->n_inputs == 0) {
            return ADC_ERR_CONFIG;
        }
        if (c->kind == ADC_ADS1115) {
            if (c->n_inputs > 4 || c->pga > 5 || c->rate > 7) {
                return ADC_ERR_CONFIG;
            }
            a->period_ns[i] = (1000000000u + RATES[c->rate] / 2u) / RATES[c->rate];
            a->timeout_ns[i] = 2u * a->period_ns[i] + 2000000u;
            a->poll_ns[i] = max_u64(50000u, a->period_ns[i] / 50u);
            a->config[i] = (uint16_t)(((unsigned)c->pga << 9) | ((unsigned)c->rate << 5) | COMP_DISABLE);
            for (j = 0; j < c->n_inputs; ++j) {
                if (ads1115_mux(c->pos[j], c->neg[j]) < 0) {
                    return ADC_ERR_CONFIG;
                }
            }
            if (c->n_inputs > n_rounds) {
                n_rounds = c->n_inputs;
            }
        } else if (c->kind == ADC_ADS7828) {
            if (c->n_inputs > 8) {
                return ADC_ERR_CONFIG;
            }
            for (j = 0; j < c->n_inputs; ++j) {
                if (c->pos[j] > 7 || c->neg[j] != ADC_SINGLE_ENDED) {
                    return ADC_ERR_CONFIG;
                }
            }
            a->period_ns[i] = a->timeout_ns[i] = a->poll_ns[i] = 0;
            a->config[i] = 0;
        } else {
            return ADC_ERR_CONFIG;
        }
        el += c->n_inputs;
    }
    if (el > ADC_MAX_ELEMENTS) {
        return ADC_ERR_CONFIG;
    }
    a->n_elements = (uint8_t)el;
    /* the rounds, as host/adc.py AdcArray plans them */
    el = 0;
    for (i = 0; i < n_chips; ++i) {
        const adc_chip *c = &chips[i];
        for (j = 0; j < c->n_inputs; ++j, ++el) {
            adc_item it;
            adc_round *r;
            it.chip = (uint8_t)i;
            it.slot = (uint8_t)j;
            it.element = (uint8_t)el;
            if (c->kind == ADC_ADS7828) {
                r = &a->rounds[0];
                r->direct[r->n_direct++] = it;
            } else if (!c->continuous) {
                r = &a->rounds[j];
                r->single[r->n_single++] = it;
                r->wait_ns = max_u64(r->wait_ns, a->period_ns[i] + WAKE_NS);
            } else if (c->n_inputs == 1) {
                r = &a->rounds[0];
                r->fixed[r->n_fixed++] = it;
            } else {
                r = &a->rounds[j];
                r->change[r->n_change++] = it;
                /* a change of input waits for the conversion under way (oscillator up to 10 % slow) */
                r->wait_ns = max_u64(r->wait_ns, (22u * a->period_ns[i] + 5u) / 10u + WAKE_NS);
            }
        }
    }
    /* drop empty rounds */
    a->n_rounds = 0;
    for (i = 0; i < n_rounds; ++i) {
        const adc_round *r = &a->rounds[i];
        if (r->n_single || r->n_change || r->n_fixed || r->n_direct) {
            a->rounds[a->n_rounds++] = *r;
        }
    }
    return ADC_OK;
}

static void count_error(adc_counts *k, int status)
{
    if (status == ADC_I2C_NACK) {
        ++k->nack;
    } else if (status == ADC_I2C_TIMEOUT) {
        ++k->timeout;
    } else {
        ++k->other;
    }
}

/* one transfer with the retry policy: wr then rd (either may be empty); ADC_OK or ADC_ERR_SILENT */
static int xfer(adc_array *a, int chip, uint8_t addr, const uint8_t *wr, uint16_t nw, uint8_t *rd, uint16_t nr)
{
    const adc_i2c *b = a->bus;
    uint64_t delay = a->policy.first_delay_ns;
    unsigned attempt;
    int st = ADC_I2C_OTHER;
    for (attempt = 0; attempt < a->policy.attempts; ++attempt) {
        if (attempt > 0) {
            count_error(&a->counts, st);
            ++a->counts.retries;
            b->sleep_ns(b->ctx, delay);
            delay = delay * a->policy.factor;
            if (delay > a->policy.max_delay_ns) {
                delay = a->policy.max_delay_ns;
            }
        }
        if (nw && nr) {
            st = b->write_read(b->ctx, addr, wr, nw, rd, nr);
        } else if (nr) {
            st = b->read(b->ctx, addr, rd, nr);
        } else {
            st = b->write(b->ctx, addr, wr, nw);
        }
        if (st == ADC_I2C_OK) {
            return ADC_OK;
        }
    }
    count_error(&a->counts, st);
    a->failed_chip = chip;
    return ADC_ERR_SILENT;
}

static int write_config(adc_array *a, uint8_t chip, uint16_t word)
{
    const uint8_t out[3] = { REG_CONFIG, (uint8_t)(word >> 8), (uint8_t)(word & 0xFFu) };
    return xfer(a, chip, a->chips[chip].address, out, 3, NULL, 0);
}

static int read_register(adc_array *a, uint8_t chip, uint8_t reg, uint16_t *word)
{
    uint8_t in[2] = { 0, 0 }; /* a failed transfer leaves it unread: a word of 0, not of the stack's bytes */
    const int st = xfer(a, chip, a->chips[chip].address, &reg, 1, in, 2);
    *word = (uint16_t)(((unsigned)in[0] << 8) | in[1]);
    return st;
}

static int fetch_code(adc_array *a, uint8_t chip, int32_t *code)
{
    uint16_t w = 0;
    const int st = read_register(a, chip, REG_CONVERSION, &w);
    *code = (w & 0x8000u) ? (int32_t)w - 0x10000 : (int32_t)w;
    return st;
}

static int ads7828_read(adc_array *a, uint8_t chip, uint8_t slot, uint8_t in[2])
{
    const uint8_t cmd = adc_ads7828_command(&a->chips[chip], slot);
    return xfer(a, chip, a->chips[chip].address, &cmd, 1, in, 2);
}

int adc_probe(adc_array *a)
{
    unsigned i;
    for (i = 0; i < a->n_chips; ++i) {
        int st;
        if (a->chips[i].kind == ADC_ADS1115) {
            const uint16_t word = adc_ads1115_config(a, (uint8_t)i, 0, 1, 0);
            uint16_t back = 0;
            st = write_config(a, (uint8_t)i, word);
            if (st == ADC_OK) {
                st = read_register(a, (uint8_t)i, REG_CONFIG, &back);
            }
            if (st == ADC_OK && (back & 0x7FFFu) != (word & 0x7FFFu)) {
                a->failed_chip = (int)i;
                st = ADC_ERR_NOT_CHIP;
            }
        } else {
            uint8_t in[2];
            st = ads7828_read(a, (uint8_t)i, 0, in);
            if (st == ADC_OK && (in[0] & 0xF0u)) {
                a->failed_chip = (int)i;
                st = ADC_ERR_NOT_CHIP;
            }
        }
        if (st != ADC_OK) {
            return st;
        }
    }
    return ADC_OK;
}

int adc_setup(adc_array *a)
{
    const adc_i2c *b = a->bus;
    uint64_t wait = 0;
    unsigned i;
    for (i = 0; i < a->rounds[0].n_fixed; ++i) {
        const adc_item *it = &a->rounds[0].fixed[i];
        const int st = write_config(a, it->chip, adc_ads1115_config(a, it->chip, it->slot, 0, 0));
        if (st != ADC_OK) {
            return st;
        }
        wait = max_u64(wait, (11u * a->period_ns[it->chip] + 5u) / 10u + WAKE_NS);
    }
    if (wait) {
        b->sleep_ns(b->ctx, wait);
    }
    return ADC_OK;
}

static int general_call_reset(adc_array *a)
{
    const uint8_t cmd = RESET_COMMAND;
    int st;
    ++a->counts.resets;
    st = xfer(a, -1, GENERAL_CALL, &cmd, 1, NULL, 0);
    return st == ADC_OK ? adc_setup(a) : st;
}

/* one round: ADC_OK, ADC_ERR_SILENT, or ADC_ERR_STUCK (a conversion past its time limit) */
static int read_round(adc_array *a, const adc_round *r, int32_t codes[])
{
    const adc_i2c *b = a->bus;
    uint64_t t0, now;
    unsigned i;
    int st = ADC_OK;
    for (i = 0; i < r->n_single && st == ADC_OK; ++i) {
        st = write_config(a, r->single[i].chip, adc_ads1115_config(a, r->single[i].chip, r->single[i].slot, 1, 1));
    }
    for (i = 0; i < r->n_change && st == ADC_OK; ++i) {
        st = write_config(a, r->change[i].chip, adc_ads1115_config(a, r->change[i].chip, r->change[i].slot, 0, 0));
    }
    t0 = b->now_ns(b->ctx); /* the last conversion started now */
    for (i = 0; i < r->n_direct && st == ADC_OK; ++i) {
        uint8_t in[2] = { 0, 0 };
        st = ads7828_read(a, r->direct[i].chip, r->direct[i].slot, in);
        codes[r->direct[i].element] = (int32_t)((((unsigned)in[0] & 0x0Fu) << 8) | in[1]);
    }
    for (i = 0; i < r->n_fixed && st == ADC_OK; ++i) {
        st = fetch_code(a, r->fixed[i].chip, &codes[r->fixed[i].element]);
    }
    if (st != ADC_OK) {
        return st;
    }
    now = b->now_ns(b->ctx);
    if (r->wait_ns && t0 + r->wait_ns > now) {
        b->sleep_ns(b->ctx, t0 + r->wait_ns - now);
    }
    for (i = 0; i < r->n_single; ++i) {
        const uint8_t chip = r->single[i].chip;
        uint32_t polls; /* MAX_POLLS is past a 16-bit unsigned (AVR) */
        for (polls = 0; polls < MAX_POLLS; ++polls) {
            uint16_t cfg = 0;
            st = read_register(a, chip, REG_CONFIG, &cfg);
            if (st != ADC_OK) {
                return st;
            }
            if (cfg & OS_BIT) {
                break; /* idle: the conversion is done */
            }
            if (b->now_ns(b->ctx) - t0 > a->timeout_ns[chip]) {
                a->failed_chip = chip;
                return ADC_ERR_STUCK;
            }
            b->sleep_ns(b->ctx, a->poll_ns[chip]);
        }
        if (polls == MAX_POLLS) {
            a->failed_chip = chip;
            return ADC_ERR_STUCK;
        }
        st = fetch_code(a, chip, &codes[r->single[i].element]);
        if (st != ADC_OK) {
            return st;
        }
    }
    for (i = 0; i < r->n_change; ++i) {
        st = fetch_code(a, r->change[i].chip, &codes[r->change[i].element]);
        if (st != ADC_OK) {
            return st;
        }
    }
    return ADC_OK;
}

int adc_read_codes(adc_array *a, int32_t codes[])
{
    unsigned k;
    for (k = 0; k < a->n_rounds; ++k) {
        unsigned tries = 0;
        for (;;) {
            const int st = read_round(a, &a->rounds[k], codes);
            if (st == ADC_OK) {
                break;
            }
            if (st != ADC_ERR_STUCK) {
                return st;
            }
            ++tries;
            ++a->counts.stuck;
            if (tries >= a->policy.attempts) {
                return ADC_ERR_STUCK;
            }
            ++a->counts.retries;
            if (general_call_reset(a) != ADC_OK) {
                return ADC_ERR_SILENT;
            }
        }
    }
    return ADC_OK;
}
