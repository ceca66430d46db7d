/* tm_pi.c: readings and pose estimates on a Raspberry Pi, in C: the ADC drivers (adc.c) over
 * i2c-dev, the channel map (adc_map.h) and the model (tm_model.h) rendered by `tactile-host pi-build`.
 * Writes the lines `tactile-host read` writes (t, v1..vN in V, the outputs, the model's status),
 * as CSV or JSONL on stdout; a summary on stderr. With a thermistor in the channel map it is read
 * every 0.25 s after the elements, and with PI_TEMPCOMP the readings are compensated (tm_tempcomp.h)
 * before the model, as `tactile-host read --temp-comp` does.
 *
 *   tm_pi [--bus N] [--count N] [--rate HZ] [--format csv|jsonl] [--retries N] [--tare [--tare-samples N]]
 *         [--auto-zero [--rest-band MM,DEG] [--rest-hold S]]
 *
 * --tare averages N (default PI_TARE_SAMPLES, as read's) samples of the untouched sensor first and maps them onto the rest readings
 * pi-build compiled in (PI_REST), as `tactile-host read --tare` does: its line on stderr, then every
 * reading less the offsets (after the temperature compensation, as read takes them).
 *
 * --auto-zero tares, then keeps the zero following slow drift while the sensor is at rest (autozero.h), as
 * `tactile-host read --auto-zero` does, with its --rest-band (default PI_AZ_BAND_MM,PI_AZ_BAND_DEG) and
 * --rest-hold (default PI_AZ_HOLD_S s); each update is a line on stderr, read's line.
 *
 * --bus N opens /dev/i2c-N; without it, the bus of the map file pi-build was given (`bus = N`), else 1.
 *
 * Ctrl-C (SIGINT) or SIGTERM ends the run after the sample under way, as tactile-host read ends: every
 * line whole, the summary, exit status 0.
 *
 * stdout is line-buffered: each line reaches a pipe's reader when it is written, as read flushes its lines.
 * Its reader gone (| head, with SIGPIPE ignored as systemd ignores it) ends the run as it ends read: no more
 * samples, nothing more said, exit status 141 (128 + SIGPIPE, a shell's status for a program SIGPIPE ends);
 * another write error (a full disk) is one line on stderr and exit status 2. A standard stream closed
 * before the start (>&-) goes nowhere, as read's does, rather than to the I2C device that would take its fd.
 *
 * Exit status 0, 1 when a chip stays silent (the samples so far are written), 2 for bad options
 * or a bus that cannot be opened (one line on stderr). */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "adc.h"
#include "adc_map.h"
#include "i2c_linux.h"
#include "pi_options.h"
#include "tm_model.h"
#include <math.h> /* NAN, sqrt, fabs, isfinite */
#include "autozero.h"
#if PI_TEMPCOMP
#include "tm_tempcomp.h"
typedef char tm_pi_assert_tempcomp_fits_model[(TM_TEMPCOMP_N == TM_N_INPUTS) ? 1 : -1];
#endif

#define TEMP_EVERY_NS 250000000u /* host/temperature.py READ_EVERY */
#define WAIT_SLICE_NS 100000000u /* how late a signal during a slow --rate's wait is seen (host/readout.py) */
/* the period, in ns, must fit the clock's counter with room for the grid: a sample at least every 11.6 days */
#define RATE_MIN_HZ (1.0 / 3600.0) /* a sample an hour, as tactile-host read (LONGEST_WAIT) */
#define RATE_MAX_HZ 100000.0
#define EXIT_PIPE (128 + SIGPIPE) /* read's status when its output's reader went away (fitgen/app/cliutil.py) */
/* a read of the elements that took over HELD_FACTOR times the quickest and HELD_MARGIN_NS more was held up
 * between its conversions (a loaded machine, I2C retries): host/readout.py HELD_FACTOR, HELD_MARGIN */
#define HELD_FACTOR 3u
#define HELD_MARGIN_NS 20000000u

/* set by SIGINT or SIGTERM: the loop ends after the sample under way, so that no line is cut off */
static volatile sig_atomic_t stop_signal = 0;

static void on_signal(int sig)
{
    stop_signal = sig;
}

typedef char tm_pi_assert_map_fits_model[(ADC_MAP_N_ELEMENTS == TM_N_INPUTS) ? 1 : -1];

#define TM_PI_USAGE "tm_pi [--bus N] [--count N] [--rate HZ] [--format csv|jsonl] [--retries N] " \
                    "[--tare [--tare-samples N]] [--auto-zero [--rest-band MM,DEG] [--rest-hold S]]"

static int usage(const char *msg, const char *arg)
{
    fprintf(stderr, "tm_pi: error: %s%s%s (usage: " TM_PI_USAGE ")\n", msg, arg ? ": " : "", arg ? arg : "");
    return 2;
}

/* a whole number in [lo, hi] */
static int parse_long(const char *s, long lo, long hi, long *out)
{
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || end == s || *end || v < lo || v > hi) {
        return -1;
    }
    *out = v;
    return 0;
}

/* a rate in Hz as tactile-host read takes it (2.5 is fine), within what the ns clock can pace */
static int parse_rate(const char *s, double *out)
{
    char *end;
    double v;
    errno = 0;
    v = strtod(s, &end);
    if (errno || end == s || *end || !(v >= RATE_MIN_HZ && v <= RATE_MAX_HZ)) { /* !(..) refuses nan too */
        return -1;
    }
    *out = v;
    return 0;
}

/* a number > 0 and at most 1e6 (--rest-hold; each of --rest-band's), up to `stop` (a ',' or the end) */
static int parse_positive(const char *s, char stop, double *out)
{
    char *end;
    double v;
    errno = 0;
    v = strtod(s, &end);
    if (errno || end == s || *end != stop || !(v > 0.0 && v <= 1e6)) {
        return -1;
    }
    *out = v;
    return 0;
}

/* --rest-band MM,DEG */
static int parse_band(const char *s, double *mm, double *deg)
{
    const char *comma = strchr(s, ',');
    return comma && !parse_positive(s, ',', mm) && !parse_positive(comma + 1, '\0', deg) ? 0 : -1;
}

/* sleep until the monotonic time `until` in slices, so that a signal ends the wait; 0 when one did */
static int wait_until(const adc_i2c *b, uint64_t until)
{
    uint64_t now;
    while (!stop_signal && (now = b->now_ns(b->ctx)) < until) {
        const uint64_t left = until - now;
        b->sleep_ns(b->ctx, left < WAIT_SLICE_NS ? left : WAIT_SLICE_NS);
    }
    return !stop_signal;
}

/* whether a read of the elements that took `took` ns, the quickest `quickest`, was held up between its
 * conversions: took > max(HELD_FACTOR x quickest, quickest + HELD_MARGIN), as read tests it (no overflow: a
 * quickest read of centuries holds up nothing) */
static int held_up(uint64_t took, uint64_t quickest)
{
    uint64_t limit;
    if (quickest > (UINT64_MAX - HELD_MARGIN_NS) / HELD_FACTOR) {
        return 0;
    }
    limit = HELD_FACTOR * quickest;
    return took > (limit > quickest + HELD_MARGIN_NS ? limit : quickest + HELD_MARGIN_NS);
}

/* a standard stream closed before the start (>&-) is opened onto the null device, as read's goes nowhere: left
 * closed, its fd would be the next open's, the I2C device's, and printf would write its lines onto the bus */
static void keep_standard_fds(void)
{
    int fd;
    for (fd = 0; fd <= 2; ++fd) { /* the lowest free fd is the one open takes: fds below are open by now */
        if (fcntl(fd, F_GETFD) == -1 && errno == EBADF) {
            (void)open("/dev/null", fd ? O_WRONLY : O_RDONLY);
        }
    }
}

/* 0 while stdout takes what is written; else the errno its write failed with (EPIPE: the reader went away).
 * errno is cleared before the writes it is to judge: printf leaves it as the failed write() set it */
static int stdout_failed(void)
{
    return ferror(stdout) ? (errno ? errno : EIO) : 0;
}

/* read's ending for a failed write: a reader gone ends it without a word (EXIT_PIPE), anything else in a line */
static int output_failed(int e)
{
    if (e == EPIPE) {
        return EXIT_PIPE;
    }
    fprintf(stderr, "tm_pi: error: cannot write standard output: %s\n", strerror(e));
    return 2;
}

static void catch_stop_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    /* a write to stdout or a transfer under way completes rather than fail; the pacing wait polls the flag */
    sa.sa_flags = SA_RESTART;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}


/* the mean of n samples' volts and how far they are from the rest: offsets[k] = mean - rest (read's Tare);
 * ADC_OK, or the error that stopped it */
static int tare(adc_array *array, const double lsb[TM_N_INPUTS], long n, double degc, double offsets[TM_N_INPUTS],
                double spreads[TM_N_INPUTS])
{
    double sum[TM_N_INPUTS] = {0}, sumsq[TM_N_INPUTS] = {0}, spread = 0.0;
    long s;
    int k, st;
    for (s = 0; s < n; ++s) {
        int32_t codes[TM_N_INPUTS];
        double v[TM_N_INPUTS];
        st = adc_read_codes(array, codes);
        if (st != ADC_OK) {
            return st;
        }
        for (k = 0; k < TM_N_INPUTS; ++k) {
            v[k] = codes[k] * lsb[k];
        }
#if PI_TEMPCOMP
        tm_tempcomp(v, degc); /* the offsets are taken off compensated readings: the rest's are compensated too */
#else
        (void)degc;
#endif
        for (k = 0; k < TM_N_INPUTS; ++k) {
            sum[k] += v[k];
            sumsq[k] += v[k] * v[k];
        }
    }
    fprintf(stderr, "tm_pi: tare: offsets [mV]");
    for (k = 0; k < TM_N_INPUTS; ++k) {
        const double mean = sum[k] / (double)n, var = sumsq[k] / (double)n - mean * mean;
        offsets[k] = mean - PI_REST[k];
        spreads[k] = var > 0.0 ? sqrt(var) : 0.0;
        spread = spreads[k] > spread ? spreads[k] : spread;
        fprintf(stderr, " %+.2f", offsets[k] * 1e3);
    }
    if (n > 1) {
        fprintf(stderr, " (spread up to %.2f mV rms), onto the rest readings of %s\n", spread * 1e3, PI_REST_FROM);
    } else { /* one sample has no spread: 0.00 would read as a sensor without noise (read says the same) */
        fprintf(stderr, " (one sample: no spread), onto the rest readings of %s\n", PI_REST_FROM);
    }
#ifdef PI_UNIT_LIMIT /* a twin's: another unit's rest is offsets to a tare (host/readout.py) */
    {
        double sq = 0.0;
        for (k = 0; k < TM_N_INPUTS; ++k) {
            sq += offsets[k] * offsets[k];
        }
        if (sqrt(sq / TM_N_INPUTS) > PI_UNIT_LIMIT) {
            fprintf(stderr, "tm_pi: " PI_UNIT_NOTE "\n", sqrt(sq / TM_N_INPUTS) * 1e3);
        }
    }
#endif
    return ADC_OK;
}

/* auto-zero's noise floor (host/readout.py Tare.noise_floor): the median element's tare spread, at least the
 * ADC's quantisation (the largest LSB / sqrt(12)) */
static double noise_floor(const double spreads[TM_N_INPUTS], const double lsb[TM_N_INPUTS])
{
    double s[TM_N_INPUTS], q = 0.0, median;
    int i, j;
    for (i = 0; i < TM_N_INPUTS; ++i) { /* insertion sort: a handful of elements */
        const double x = spreads[i];
        for (j = i; j > 0 && s[j - 1] > x; --j) {
            s[j] = s[j - 1];
        }
        s[j] = x;
        q = lsb[i] > q ? lsb[i] : q;
    }
    median = TM_N_INPUTS % 2 ? s[TM_N_INPUTS / 2] : (s[TM_N_INPUTS / 2 - 1] + s[TM_N_INPUTS / 2]) / 2.0;
    q /= sqrt(12.0);
    return median > q ? median : q;
}

/* read's update line (host/autozero.py ZoneUpdate.describe) */
static void print_update(const az_state *az, double t, const double shift[TM_N_INPUTS])
{
    int k, top = 0;
    for (k = 1; k < TM_N_INPUTS; ++k) {
        if (fabs(shift[k]) > fabs(shift[top])) {
            top = k;
        }
    }
    fprintf(stderr, "tm_pi: auto-zero update %ld at %.3f s: max shift %.3f mV (element %d)\n", az->updates,
            t - az->first, fabs(shift[top]) * 1e3, top + 1);
}

/* the band auto-zero tests the window's mean estimate against, and the noise floor */
static void print_band(const az_state *az)
{
    static const char *const names[TM_N_OUTPUTS] = TM_OUTPUT_NAMES;
    int k;
    fprintf(stderr, "tm_pi: auto-zero: noise floor %.3f mV; the %d-sample mean's rest band", az->noise * 1e3,
            PI_AZ_WINDOW);
    for (k = 0; k < TM_N_OUTPUTS; ++k) {
        fprintf(stderr, "%s %s +-%.3g %s", k ? "," : "", names[k], az->band[k], PI_AZ_DEG[k] ? "deg" : "mm");
    }
    fprintf(stderr, "\n");
}

static void print_line(int jsonl, double t, const double v[TM_N_INPUTS], const tm_real out[TM_N_OUTPUTS], int status)
{
    static const char *const names[TM_N_OUTPUTS] = TM_OUTPUT_NAMES;
    int k;
    if (jsonl) {
        printf("{\"t\":%.6f,\"v\":[", t);
        for (k = 0; k < TM_N_INPUTS; ++k) {
            printf(k ? ",%.6f" : "%.6f", v[k]);
        }
        printf("]");
        for (k = 0; k < TM_N_OUTPUTS; ++k) {
            printf(",\"%s\":%.4f", names[k], (double)out[k]);
        }
        printf(",\"status\":%d}\n", status);
    } else {
        printf("%.6f", t);
        for (k = 0; k < TM_N_INPUTS; ++k) {
            printf(",%.6f", v[k]);
        }
        for (k = 0; k < TM_N_OUTPUTS; ++k) {
            printf(",%.4f", (double)out[k]);
        }
        printf(",%d\n", status);
    }
}

int main(int argc, char **argv)
{
    static const char *const names[TM_N_OUTPUTS] = TM_OUTPUT_NAMES;
    long bus = PI_DEFAULT_BUS, count = 0, retries = 5, tare_n = 0;
    int tared = 0, auto_zero = 0, band_given = 0, hold_given = 0;
    double offsets[TM_N_INPUTS] = {0}, spreads[TM_N_INPUTS] = {0};
    double band_mm = PI_AZ_BAND_MM, band_deg = PI_AZ_BAND_DEG, hold_s = PI_AZ_HOLD_S;
    static az_state az; /* the window: a few kB, not on the stack */
    double rate_hz = 0.0;
    int jsonl = 0, i, st = ADC_OK;
    long n = 0, late = 0, far = 0, far_held = 0; /* far_held: from a read held up (not counted in far) */
    char err[200], late_text[40] = "", far_text[200] = "", held_text[320] = "", pace_text[40] = "";
    uint64_t start_ns = 0, began_ns = 0, first_ns = 0, last_ns = 0;
    uint64_t quickest = UINT64_MAX; /* ns: the quickest read of the elements so far, what a read takes */
    int out_err = 0; /* the errno a write to stdout failed with: the run ends after that line */
    double elapsed;
    i2c_linux port;
    adc_i2c i2c;
    adc_array array;
    adc_policy policy = adc_default_policy();
    double lsb[TM_N_INPUTS];
    uint64_t next = 0, period = 0;
    const char *failed = NULL; /* the chip that stopped the readout, when the map's table does not name it */
    adc_counts total;
    double degc = (double)NAN; /* the thermistor's last reading */
#if ADC_HAS_TEMPERATURE
    adc_array tarray;
    uint64_t t_last = 0;
    int t_read = 0;
#endif

    keep_standard_fds();
    setvbuf(stdout, NULL, _IOLBF, BUFSIZ); /* each line out when written, not 4 kB later (~30 s at --rate 1) */
    for (i = 1; i < argc; ++i) {
        const char *opt = argv[i];
        const char *val = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(opt, "--format") == 0 && val) {
            if (strcmp(val, "csv") && strcmp(val, "jsonl")) {
                return usage("--format must be csv or jsonl, got", val);
            }
            jsonl = strcmp(val, "jsonl") == 0;
        } else if (strcmp(opt, "--bus") == 0 && val) {
            if (parse_long(val, 0, 255, &bus)) return usage("--bus must be 0..255, got", val);
        } else if (strcmp(opt, "--count") == 0 && val) {
            if (parse_long(val, 1, LONG_MAX, &count)) return usage("--count must be a whole number >= 1, got", val);
        } else if (strcmp(opt, "--rate") == 0 && val) {
            if (parse_rate(val, &rate_hz)) {
                return usage("--rate must be a number of Hz in 1/3600 (a sample an hour)..100000, got", val);
            }
        } else if (strcmp(opt, "--retries") == 0 && val) {
            if (parse_long(val, 1, 100, &retries)) return usage("--retries must be 1..100, got", val);
        } else if (strcmp(opt, "--tare") == 0) {
            tared = 1;
            continue; /* a flag: no value */
        } else if (strcmp(opt, "--tare-samples") == 0 && val) {
            if (parse_long(val, 1, 100000, &tare_n)) return usage("--tare-samples must be 1..100000, got", val);
        } else if (strcmp(opt, "--auto-zero") == 0) {
            auto_zero = 1;
            continue;
        } else if (strcmp(opt, "--rest-band") == 0 && val) {
            if (parse_band(val, &band_mm, &band_deg)) {
                return usage("--rest-band must be MM,DEG, each in (0, 1e6], e.g. 0.08,1.5, got", val);
            }
            band_given = 1;
        } else if (strcmp(opt, "--rest-hold") == 0 && val) {
            if (parse_positive(val, '\0', &hold_s)) return usage("--rest-hold must be seconds in (0, 1e6], got", val);
            hold_given = 1;
        } else if (strcmp(opt, "--help") == 0 || strcmp(opt, "-h") == 0) {
            printf("usage: " TM_PI_USAGE "\n"
                   "Reads the sensor's ADCs over /dev/i2c-N and prints the model's estimate per sample (without "
                   "--count, until Ctrl-C); see docs/readout.md.\n");
            return 0;
        } else {
            return usage("unknown or incomplete option", opt);
        }
        ++i;
    }
    if (tare_n && !tared && !auto_zero) {
        return usage("--tare-samples needs", "--tare or --auto-zero");
    }
    if ((band_given || hold_given) && !auto_zero) {
        return usage(band_given ? "--rest-band needs" : "--rest-hold needs", "--auto-zero");
    }
    tare_n = tare_n ? tare_n : PI_TARE_SAMPLES;
    if (auto_zero && tare_n < PI_AZ_MIN_TARE) { /* read's MIN_AUTOZERO_TARE, and its words */
        fprintf(stderr, "tm_pi: error: --auto-zero takes its noise floor from the tare's spread: give --tare-samples "
                        "%d or more (got %ld)\n", PI_AZ_MIN_TARE, tare_n);
        return 2;
    }
    if ((tared || auto_zero) && !PI_HAS_REST) {
        fprintf(stderr, "tm_pi: error: %s: this build has no rest readings to map onto (tactile-host pi-build "
                        "--rest SENSOR|DATASET.csv)\n", auto_zero ? "--auto-zero" : "--tare");
        return 2;
    }
    if (auto_zero && !PI_HAS_AUTOZERO) {
        fprintf(stderr, "tm_pi: error: --auto-zero: the model's outputs are not all a pose's (dx, dy, dz, thx, thy): "
                        "no rest band to test them against\n");
        return 2;
    }
    tared = tared || auto_zero;
    policy.attempts = (uint8_t)retries;
    catch_stop_signals();
    if (i2c_linux_open(&port, (int)bus, &i2c, err, sizeof err) != 0) {
        fprintf(stderr, "tm_pi: error: %s\n", err);
        return 2;
    }
    if (adc_init(&array, &i2c, ADC_MAP, ADC_MAP_N_CHIPS, policy) != ADC_OK) {
        fprintf(stderr, "tm_pi: error: the channel map %s is not one the drivers take\n", ADC_MAP_DESCRIPTION);
        i2c_linux_close(&port);
        return 2;
    }
    for (i = 0; i < ADC_MAP_N_CHIPS; ++i) {
        int j;
        for (j = 0; j < ADC_MAP[i].n_inputs; ++j) {
            lsb[ADC_MAP_FIRST_ELEMENT[i] + j] = adc_lsb_volts(&ADC_MAP[i]);
        }
    }
    st = adc_probe(&array);
    if (st == ADC_OK) {
        st = adc_setup(&array);
    }
    if (st != ADC_OK) {
        fprintf(stderr, "tm_pi: error: %s %s\n", array.failed_chip >= 0 ? ADC_MAP_LABELS[array.failed_chip] :
                "general-call reset", st == ADC_ERR_NOT_CHIP ? "answers as another part: is the chip type in the "
                "channel map right?" : "does not answer: check the wiring, its address pins and i2cdetect");
        i2c_linux_close(&port);
        return 2;
    }
#if ADC_HAS_TEMPERATURE
    if (adc_init(&tarray, &i2c, ADC_TEMP_CHIP, 1, policy) != ADC_OK) {
        fprintf(stderr, "tm_pi: error: the thermistor's input %s is not one the drivers take\n", ADC_TEMP_LABEL);
        i2c_linux_close(&port);
        return 2;
    }
#endif
#if PI_TEMPCOMP
    if (tared) { /* the tare's temperature, read first as read reads it (host/session.py) */
        int32_t tcode;
        t_last = i2c.now_ns(i2c.ctx);
        t_read = 1;
        if (adc_read_codes(&tarray, &tcode) != ADC_OK) {
            fprintf(stderr, "tm_pi: error: the thermistor %s stays silent before the tare\n", ADC_TEMP_LABEL);
            i2c_linux_close(&port);
            return 1;
        }
        degc = adc_code_degc(&ADC_TEMP_CHIP[0], tcode, ADC_TEMP_BETA, ADC_TEMP_R25, ADC_TEMP_SERIES,
                             ADC_TEMP_VREF);
    }
#endif
    if (tared && (st = tare(&array, lsb, tare_n, degc, offsets, spreads)) != ADC_OK) {
        fprintf(stderr, "tm_pi: error: %s %s during the tare\n", array.failed_chip >= 0 ?
                ADC_MAP_LABELS[array.failed_chip] : "general-call reset",
                st == ADC_ERR_STUCK ? "never completes a conversion" : "stays silent");
        i2c_linux_close(&port);
        return 1;
    }
    if (auto_zero) {
        az_init(&az, offsets, noise_floor(spreads, lsb), band_mm, band_deg, hold_s);
        print_band(&az);
    }
    errno = 0;
    if (!jsonl) {
        printf("t");
        for (i = 1; i <= TM_N_INPUTS; ++i) {
            printf(",v%d", i);
        }
        for (i = 0; i < TM_N_OUTPUTS; ++i) {
            printf(",%s", names[i]);
        }
        printf(",status\n");
    }
    if ((out_err = stdout_failed()) != 0) {
        i2c_linux_close(&port);
        return output_failed(out_err);
    }
    start_ns = i2c.now_ns(i2c.ctx);
    if (rate_hz > 0.0) {
        period = (uint64_t)(1e9 / rate_hz + 0.5);
        next = start_ns;
    }
    while ((count == 0 || n < count) && !stop_signal) {
        int32_t codes[TM_N_INPUTS];
        double v[TM_N_INPUTS], comp[TM_N_INPUTS], shift[TM_N_INPUTS];
        tm_real in[TM_N_INPUTS], out[TM_N_OUTPUTS];
        double t, t_mono;
        uint64_t took;
        int status, held;
        if (period) {
            const uint64_t now = i2c.now_ns(i2c.ctx);
            if (now < next && !wait_until(&i2c, next)) {
                break; /* stopped during the wait: no sample after it */
            }
            /* as tactile-host read paces: a sample more than a period late restarts the grid from itself,
             * so that a stall is not caught up with a burst of back-to-back samples */
            if (now > next && now - next > period) {
                ++late;
                next = now;
            }
            next += period;
        }
        t = (double)i2c_linux_realtime_ns() * 1e-9;
        /* auto-zero's hold runs on the monotonic clock: a Pi without a clock battery sets its wall clock from
         * the network after boot, a jump of months that would end a hold at once or stall it */
        began_ns = i2c.now_ns(i2c.ctx);
        t_mono = (double)began_ns * 1e-9;
        st = adc_read_codes(&array, codes);
        if (st != ADC_OK) {
            break;
        }
        took = i2c.now_ns(i2c.ctx) - began_ns; /* as read times it: the elements' read, not the thermistor's */
        quickest = took < quickest ? took : quickest;
        held = held_up(took, quickest);
        for (i = 0; i < TM_N_INPUTS; ++i) {
            v[i] = codes[i] * lsb[i];
        }
#if ADC_HAS_TEMPERATURE
        {
            const uint64_t now = i2c.now_ns(i2c.ctx);
            if (!t_read || now - t_last >= TEMP_EVERY_NS) {
                int32_t tcode;
                t_read = 1;
                t_last = now;
                st = adc_read_codes(&tarray, &tcode);
                if (st != ADC_OK) {
                    failed = ADC_TEMP_LABEL;
                    break;
                }
                degc = adc_code_degc(&ADC_TEMP_CHIP[0], tcode, ADC_TEMP_BETA, ADC_TEMP_R25,
                                     ADC_TEMP_SERIES, ADC_TEMP_VREF);
            }
        }
#endif
#if PI_TEMPCOMP
        tm_tempcomp(v, degc);
#elif ADC_HAS_TEMPERATURE
        (void)degc; /* read as the Python readout reads it (same transfers), not applied */
#endif
        for (i = 0; i < TM_N_INPUTS; ++i) {
            comp[i] = v[i];
            if (tared) {
                v[i] -= auto_zero ? az.zero[i] : offsets[i];
            }
        }
        for (i = 0; i < TM_N_INPUTS; ++i) {
            in[i] = (tm_real)v[i];
        }
        status = tm_estimate(in, out);
        if (auto_zero && az_observe(&az, t_mono, comp, out, status, shift)) {
            print_update(&az, t_mono, shift);
        }
        errno = 0;
        print_line(jsonl, t, v, out, status);
        if (status >= 0 && tm_far_outside(out)) { /* the header's test: read's bounds */
            if (held) { /* a read held up is not the model's fault, nor another sensor's */
                ++far_held;
            } else {
                ++far;
            }
        }
        first_ns = n == 0 ? began_ns : first_ns; /* read's pace: from the first sample's start to the last's */
        last_ns = began_ns;
        ++n;
        if ((out_err = stdout_failed()) != 0) {
            break; /* no more samples for a reader that is gone: read's ending, no summary */
        }
    }
    errno = 0;
    if (out_err || (fflush(stdout) == EOF && (out_err = errno ? errno : EIO) != 0)) {
        i2c_linux_close(&port);
        return output_failed(out_err);
    }
    elapsed = (double)(i2c.now_ns(i2c.ctx) - start_ns) * 1e-9;
    total = array.counts;
#if ADC_HAS_TEMPERATURE
    /* one bus: the thermistor's errors count with the elements', as the Python readout counts them */
    total.nack += tarray.counts.nack;
    total.timeout += tarray.counts.timeout;
    total.stuck += tarray.counts.stuck;
    total.other += tarray.counts.other;
    total.retries += tarray.counts.retries;
    total.resets += tarray.counts.resets;
#endif
    if (late) {
        snprintf(late_text, sizeof late_text, "; %ld late", late);
    }
    if (far) {
        snprintf(far_text, sizeof far_text, "; %ld estimated outside the pose box the model was fitted in by more "
                 "than its width: another sensor than the model's?", far);
    }
    if (far_held) { /* read's words (host/readout.py FAR_HELD) */
        snprintf(held_text, sizeof held_text, "; %ld estimated outside the pose box the model was fitted in by more "
                 "than its width, from a read held up between its conversions (a loaded machine, or I2C retries): a "
                 "sensor that moved meanwhile gives readings of two poses, which no pose gives", far_held);
    }
    if (n > 1 && last_ns > first_ns) {
        snprintf(pace_text, sizeof pace_text, " (%.1f Hz)", (double)(n - 1) / ((double)(last_ns - first_ns) * 1e-9));
    }
    fprintf(stderr, "tm_pi: %s%ld samples in %.2f s%s; I2C errors %lu (nack %lu, timeout %lu, stuck %lu, other %lu; "
                    "%lu retries, %lu resets)%s%s%s\n", stop_signal ? "stopped: " : "", n, elapsed, pace_text,
            (unsigned long)(total.nack + total.timeout + total.stuck + total.other),
            (unsigned long)total.nack, (unsigned long)total.timeout, (unsigned long)total.stuck,
            (unsigned long)total.other, (unsigned long)total.retries, (unsigned long)total.resets, late_text,
            far_text, held_text);
    if (st != ADC_OK) {
        fprintf(stderr, "tm_pi: error: %s %s; stopped after %ld samples\n",
                failed ? failed : array.failed_chip >= 0 ? ADC_MAP_LABELS[array.failed_chip] : "general-call reset",
                st == ADC_ERR_STUCK ? "never completes a conversion" : "stays silent", n);
    }
    i2c_linux_close(&port);
    return st == ADC_OK ? 0 : 1;
}
