/* autozero.h: tm_pi --auto-zero, host/autozero.py's AutoZero (its "mean" test) in C, so that the Pi's zero
 * follows slow drift at rest as `tactile-host read --auto-zero` does and a recorded run of either gives the
 * same updates.
 *
 * The zero is the offset taken off each (temperature-compensated) reading; it starts at the tare's. The
 * sensor counts as at rest over the last PI_AZ_WINDOW samples when each element's spread there is within
 * PI_AZ_SPREAD times the tare's noise floor and the window's mean estimate lies within the rest band about
 * the estimate at rest. After hold_s seconds of rest without a break the zero moves PI_AZ_RATE of the way to
 * the window's mean offset, and the window starts again; a sample whose status is negative, a loud window or
 * a mean estimate outside the band starts it again too.
 *
 * The band per output is the one given (mm or deg) or PI_AZ_SIGMAS standard deviations of the window's mean
 * estimate at rest, whichever is wider. pi-build measured the single estimates' scatter at rest per volt of
 * noise (PI_AZ_SCATTER_PER_V: small noise moves an estimate linearly); here it is scaled by the tare's noise
 * floor. Included once, by tm_pi.c, after tm_model.h and pi_options.h. No allocation: the window is the
 * state's. */
#ifndef TM_PI_AUTOZERO_H
#define TM_PI_AUTOZERO_H

typedef struct { /* one sample of the window */
    double readings[TM_N_INPUTS];   /* compensated, the zero not taken off */
    double estimates[TM_N_OUTPUTS];
} az_sample;

typedef struct {
    double zero[TM_N_INPUTS];   /* V: taken off each compensated reading */
    double band[TM_N_OUTPUTS];  /* the window's mean estimate may lie this far from PI_AZ_REST_EST */
    double noise;               /* V rms: the tare's noise floor */
    double hold_s;
    az_sample window[PI_AZ_WINDOW];
    int filled, oldest;         /* samples in the window; the oldest one's slot */
    int resting;                /* the window was at rest at `since` */
    double since, first;        /* s: when the rest began; the first sample's time */
    int started;
    long updates;
} az_state;

/* the slot of the window's i-th sample, oldest first */
static int az_slot(const az_state *az, int i)
{
    return az->oldest + i < PI_AZ_WINDOW ? az->oldest + i : az->oldest + i - PI_AZ_WINDOW;
}

static void az_restart(az_state *az)
{
    az->filled = 0;
    az->oldest = 0;
    az->resting = 0;
}

/* the zero starts at `zero` (the tare's offsets), the spread test at `noise` (its floor); the band: band_mm
 * for dx, dy, dz and band_deg for thx, thy, or PI_AZ_SIGMAS standard deviations of the window's mean
 * estimate at rest, whichever is wider (host/autozero.py AutoZero.__post_init__ with scatter =
 * PI_AZ_SCATTER_PER_V x noise, operation for operation; its centre, PI_AZ_REST_EST, pi-build measured) */
static void az_init(az_state *az, const double zero[TM_N_INPUTS], double noise, double band_mm, double band_deg,
                    double hold_s)
{
    int k;
    memset(az, 0, sizeof *az);
    for (k = 0; k < TM_N_INPUTS; ++k) {
        az->zero[k] = zero[k];
    }
    for (k = 0; k < TM_N_OUTPUTS; ++k) {
        const double given = PI_AZ_DEG[k] ? band_deg : band_mm;
        const double mean_sd = PI_AZ_SCATTER_PER_V[k] * noise / sqrt((double)PI_AZ_WINDOW);
        az->band[k] = given > PI_AZ_SIGMAS * mean_sd ? given : PI_AZ_SIGMAS * mean_sd;
    }
    az->noise = noise;
    az->hold_s = hold_s;
    az_restart(az);
}

/* one sample at time t (s): `comp` before the zero is taken off, `out` and `status` the model's on comp less
 * the zero. 1 when the zero moved (`shift`: by how much, V per element), else 0. Sums run from the oldest
 * sample to the newest, row by row, as numpy's reductions over the window's rows do. */
static int az_observe(az_state *az, double t, const double comp[TM_N_INPUTS], const tm_real out[TM_N_OUTPUTS],
                      int status, double shift[TM_N_INPUTS])
{
    double mean[TM_N_INPUTS], sum[TM_N_INPUTS] = {0}, sq[TM_N_INPUTS] = {0}, est[TM_N_OUTPUTS] = {0};
    int i, k, s;
    if (!az->started) {
        az->started = 1;
        az->first = t;
    }
    for (k = 0; k < TM_N_OUTPUTS; ++k) {
        if (!isfinite((double)out[k])) {
            status = -1;
        }
    }
    if (status < 0) {
        az_restart(az);
        return 0;
    }
    if (az->filled < PI_AZ_WINDOW) {
        s = az->filled++; /* a window started again fills from slot 0 */
    } else {
        s = az->oldest;
        az->oldest = (az->oldest + 1) % PI_AZ_WINDOW;
    }
    for (k = 0; k < TM_N_INPUTS; ++k) {
        az->window[s].readings[k] = comp[k];
    }
    for (k = 0; k < TM_N_OUTPUTS; ++k) {
        az->window[s].estimates[k] = (double)out[k];
    }
    if (az->filled < PI_AZ_WINDOW) {
        return 0;
    }
    /* row by row, oldest first, each element's sum in that order (numpy's reduction over the window's rows) */
    for (i = 0; i < PI_AZ_WINDOW; ++i) {
        const az_sample *row = &az->window[az_slot(az, i)];
        for (k = 0; k < TM_N_INPUTS; ++k) {
            sum[k] += row->readings[k];
        }
        for (k = 0; k < TM_N_OUTPUTS; ++k) {
            est[k] += row->estimates[k];
        }
    }
    for (k = 0; k < TM_N_INPUTS; ++k) {
        mean[k] = sum[k] / (double)PI_AZ_WINDOW;
    }
    for (i = 0; i < PI_AZ_WINDOW; ++i) {
        const double *row = az->window[az_slot(az, i)].readings;
        for (k = 0; k < TM_N_INPUTS; ++k) {
            const double d = row[k] - mean[k];
            sq[k] += d * d;
        }
    }
    for (k = 0; k < TM_N_INPUTS; ++k) {
        if (sqrt(sq[k] / (double)PI_AZ_WINDOW) > PI_AZ_SPREAD * az->noise) {
            az_restart(az);
            return 0;
        }
    }
    for (k = 0; k < TM_N_OUTPUTS; ++k) {
        if (fabs(est[k] / (double)PI_AZ_WINDOW - PI_AZ_REST_EST[k]) > az->band[k]) {
            az_restart(az);
            return 0;
        }
    }
    if (!az->resting) {
        az->resting = 1;
        az->since = t;
        return 0;
    }
    if (t - az->since < az->hold_s) {
        return 0;
    }
    for (k = 0; k < TM_N_INPUTS; ++k) {
        shift[k] = PI_AZ_RATE * ((mean[k] - PI_REST[k]) - az->zero[k]);
        az->zero[k] = az->zero[k] + shift[k];
    }
    ++az->updates;
    az_restart(az);
    return 1;
}

#endif
