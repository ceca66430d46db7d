/* ReadPose: the lines `tactile-host read --format csv` writes, over Serial at 115200 baud:
 *
 *   t,v1,..,vN,<outputs>,status
 *
 * t in seconds since reset (the board has no wall clock), v1..vN the element voltages (V, 6 decimals),
 * the model's outputs (mm, deg; 4 decimals) and its status (0 inside the fitted domain). The channel map,
 * its PGA and data rate are the library's (tactile_config.h, adc_map.h: tactile-host arduino-build --adc,
 * --pga, --data-rate); Wire runs at TACTILE_WIRE_CLOCK_HZ. A chip that does not answer stops the
 * readout with one line starting "error:". A library built with --tare (TACTILE_TARE) first averages
 * TACTILE_TARE_SAMPLES readings of the untouched sensor and maps them onto the model's rest readings
 * (TACTILE_REST), as tactile-host read --tare does; it prints one line before the header, "# tare: offsets
 * [mV] ...", and every line after carries the tared volts; a twin's library (TACTILE_UNIT_LIMIT) follows it with
 * a "# note:" line when the offsets look like another unit's rest. Leave the skin untouched at power-up; a 't' sent
 * over Serial (the serial monitor's input line) tares again, its line printed among the rows. The first
 * estimate far outside the pose box the model was fitted in (tm_far_outside) is followed by one line
 * starting "# note:": readings of another sensor than the model's, as tactile-host read counts them. */
#include <Wire.h>
#include <TactilePose.h>

static adc_i2c bus;
static adc_array adcs;
static bool running;
#if TM_HAS_POSE_BOX
static bool said_far; /* the note on estimates far outside the fitted pose box: once per reset */
#endif
#if TACTILE_TARE
#if TACTILE_FIXED_POINT
static int32_t offset_codes[TM_N_INPUTS]; /* added to each code: the model takes codes */
#else
static float offset_volts[TM_N_INPUTS]; /* added to each reading */
#endif
#endif

/* the board's I2C pins, as its silkscreen names them */
#if defined(__AVR_ATmega2560__)
#define I2C_PINS "20), SCL (21"
#elif defined(__AVR_ATmega32U4__)
#define I2C_PINS "D2), SCL (D3"
#else
#define I2C_PINS "A4), SCL (A5"
#endif

static void print_error(int st)
{
    Serial.print(F("error: "));
    Serial.print(adcs.failed_chip >= 0 ? ADC_MAP_LABELS[adcs.failed_chip] : "general-call reset");
    Serial.println(st == ADC_ERR_NOT_CHIP ? F(" answers as another part: is the chip type in the channel map right?")
                   : st == ADC_ERR_STUCK ? F(" never completes a conversion")
                   : F(" does not answer: check SDA (" I2C_PINS "), power and its ADDR pin"));
}

#if TACTILE_TARE
/* the mean of TACTILE_TARE_SAMPLES readings onto TACTILE_REST; false (the error said) when a chip fails */
static bool tare()
{
    int32_t codes[TM_N_INPUTS], sum[TM_N_INPUTS];
    int k, n, st;
#ifdef TACTILE_UNIT_LIMIT
    float sq = 0.0f;
#endif
    for (k = 0; k < TM_N_INPUTS; ++k) {
        sum[k] = 0;
    }
    for (n = 0; n < TACTILE_TARE_SAMPLES; ++n) {
        st = adc_read_codes(&adcs, codes);
        if (st != ADC_OK) {
            print_error(st);
            return false;
        }
        for (k = 0; k < TM_N_INPUTS; ++k) {
            sum[k] += codes[k]; /* 50 codes of at most 16 bits: far inside an int32 */
        }
    }
    Serial.print(F("# tare: offsets [mV]"));
    for (k = 0; k < TM_N_INPUTS; ++k) {
        const float mean = (float)sum[k] / (float)TACTILE_TARE_SAMPLES;
        float shift;
#if TACTILE_FIXED_POINT
        offset_codes[k] = (int32_t)lroundf(TACTILE_REST[k] / TACTILE_LSB[k] - mean);
        shift = (float)offset_codes[k] * TACTILE_LSB[k];
#else
        offset_volts[k] = TACTILE_REST[k] - mean * TACTILE_LSB[k];
        shift = offset_volts[k];
#endif
        Serial.print(-shift >= 0.0f ? F(" +") : F(" ")); /* as read prints them: measured less the rest, signed */
        Serial.print(-1000.0f * shift, 2);
#ifdef TACTILE_UNIT_LIMIT
        sq += shift * shift;
#endif
    }
    Serial.println();
#ifdef TACTILE_UNIT_LIMIT /* a twin's: another unit's rest is offsets to a tare (host/readout.py) */
    if (sqrtf(sq / (float)TM_N_INPUTS) > TACTILE_UNIT_LIMIT) {
        Serial.print(F("# note: the tare's offsets reach "));
        Serial.print(1000.0f * sqrtf(sq / (float)TM_N_INPUTS), 1);
        Serial.println(F(" mV rms, past what one unit drifts: is this the unit the model was fitted for?"));
    }
#endif
    return true;
}
#endif

void setup()
{
    static const char *const names[TM_N_OUTPUTS] = TM_OUTPUT_NAMES;
    int st, k;
    Serial.begin(115200);
#if defined(USBCON)
    /* Serial is USB here (Leonardo, Micro): what is written before the port is opened is lost, and the board does
     * not restart when it opens; wait for it up to 3 s, then go on (a board on its own runs without a host) */
    while (!Serial && millis() < 3000u) {
    }
#endif
    Wire.begin();
    Wire.setClock(TACTILE_WIRE_CLOCK_HZ);
    tactile_wire_bus(&bus, TACTILE_WIRE_TIMEOUT_US);
    if (adc_init(&adcs, &bus, ADC_MAP, ADC_MAP_N_CHIPS, adc_default_policy()) != ADC_OK) {
        Serial.println(F("error: the channel map " ADC_MAP_DESCRIPTION " is not one the drivers take"));
        return;
    }
    st = adc_probe(&adcs);
    if (st == ADC_OK) {
        st = adc_setup(&adcs);
    }
    if (st != ADC_OK) {
        print_error(st);
        return;
    }
#if TACTILE_TARE
    if (!tare()) {
        return;
    }
#endif
    Serial.print('t');
    for (k = 1; k <= TM_N_INPUTS; ++k) {
        Serial.print(F(",v"));
        Serial.print(k);
    }
    for (k = 0; k < TM_N_OUTPUTS; ++k) {
        Serial.print(',');
        Serial.print(names[k]);
    }
    Serial.println(F(",status"));
    running = true;
}

/* element k's volts from its code: what the line prints and, in float, what the model takes */
static float volts(const int32_t *codes, int k)
{
#if TACTILE_TARE && !TACTILE_FIXED_POINT
    return (float)codes[k] * TACTILE_LSB[k] + offset_volts[k];
#else
    return (float)codes[k] * TACTILE_LSB[k];
#endif
}

void loop()
{
    int32_t codes[TM_N_INPUTS];
    int k, st;
    uint64_t ns;
    uint32_t frac;
    char buf[8];
    if (!running) {
        return;
    }
#if TACTILE_TARE
    if (Serial.available() > 0 && Serial.read() == 't') { /* the skin untouched again: a new tare */
        running = tare();
        return;
    }
#endif
    ns = bus.now_ns(bus.ctx);
    st = adc_read_codes(&adcs, codes);
    if (st != ADC_OK) {
        print_error(st);
        running = false;
        return;
    }
#if TACTILE_TARE && TACTILE_FIXED_POINT
    for (k = 0; k < TM_N_INPUTS; ++k) {
        codes[k] += offset_codes[k];
    }
#endif
    /* t as whole seconds and microseconds: a float would lose the microseconds after a few minutes */
    Serial.print((unsigned long)(ns / 1000000000u));
    frac = (uint32_t)((ns % 1000000000u) / 1000u);
    snprintf(buf, sizeof buf, ".%06lu", (unsigned long)frac);
    Serial.print(buf);
    for (k = 0; k < TM_N_INPUTS; ++k) {
        Serial.print(',');
        Serial.print(volts(codes, k), 6);
    }
    {
#if TACTILE_FIXED_POINT
        static const int frac_bits[TM_N_OUTPUTS] = TM_OUT_FRAC_BITS;
        tm_output out[TM_N_OUTPUTS];
        const int status = tm_estimate(codes, out);
        for (k = 0; k < TM_N_OUTPUTS; ++k) {
            Serial.print(',');
            Serial.print(ldexpf((float)out[k], -frac_bits[k]), 4);
        }
#else
        tm_real in[TM_N_INPUTS], out[TM_N_OUTPUTS];
        int status;
        for (k = 0; k < TM_N_INPUTS; ++k) {
            in[k] = volts(codes, k);
        }
        status = tm_estimate(in, out);
        for (k = 0; k < TM_N_OUTPUTS; ++k) {
            Serial.print(',');
            Serial.print(out[k], 4);
        }
#endif
        Serial.print(',');
        Serial.println(status);
#if TM_HAS_POSE_BOX
        /* the estimate far outside the box the model was fitted in, clamped readings or not: another sensor's
         * readings (the drawing's model on a built unit), which the status cannot tell */
        if (status >= 0 && !said_far && tm_far_outside(out)) {
            said_far = true;
            Serial.println(F("# note: an estimate far outside the pose box the model was fitted in: "
                             "another sensor than the model's? calibrate this unit (docs/calibration.md)"));
        }
#endif
    }
}
