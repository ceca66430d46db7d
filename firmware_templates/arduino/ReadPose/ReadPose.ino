/* ReadPose: the lines `tactile-host read --format csv` writes, over Serial at 115200 baud:
 *
 *   t,v1,..,vN,<outputs>,status
 *
 * t in seconds since reset (the board has no wall clock), v1..vN the element voltages (V, 6 decimals),
 * the model's outputs (mm, deg; 4 decimals) and its status (0 inside the fitted domain). The channel map,
 * its PGA and data rate are the library's (tactile_config.h, adc_map.h: tactile-host arduino-build --adc,
 * --pga, --data-rate); Wire runs at TACTILE_WIRE_CLOCK_HZ. A chip that does not answer stops the
 * readout with one line starting "error:". */
#include <Wire.h>
#include <TactilePose.h>

static adc_i2c bus;
static adc_array adcs;
static bool running;

static void print_error(int st)
{
    Serial.print(F("error: "));
    Serial.print(adcs.failed_chip >= 0 ? ADC_MAP_LABELS[adcs.failed_chip] : "general-call reset");
    Serial.println(st == ADC_ERR_NOT_CHIP ? F(" answers as another part: is the chip type in the channel map right?")
                   : st == ADC_ERR_STUCK ? F(" never completes a conversion")
                   : F(" does not answer: check SDA (A4), SCL (A5), power and its ADDR pin"));
}

void setup()
{
    static const char *const names[TM_N_OUTPUTS] = TM_OUTPUT_NAMES;
    int st, k;
    Serial.begin(115200);
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
    ns = bus.now_ns(bus.ctx);
    st = adc_read_codes(&adcs, codes);
    if (st != ADC_OK) {
        print_error(st);
        running = false;
        return;
    }
    /* t as whole seconds and microseconds: a float would lose the microseconds after a few minutes */
    Serial.print((unsigned long)(ns / 1000000000u));
    frac = (uint32_t)((ns % 1000000000u) / 1000u);
    snprintf(buf, sizeof buf, ".%06lu", (unsigned long)frac);
    Serial.print(buf);
    for (k = 0; k < TM_N_INPUTS; ++k) {
        Serial.print(',');
        Serial.print((float)codes[k] * TACTILE_LSB[k], 6);
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
            in[k] = (tm_real)codes[k] * TACTILE_LSB[k];
        }
        status = tm_estimate(in, out);
        for (k = 0; k < TM_N_OUTPUTS; ++k) {
            Serial.print(',');
            Serial.print(out[k], 4);
        }
#endif
        Serial.print(',');
        Serial.println(status);
    }
}
