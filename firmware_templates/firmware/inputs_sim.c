/* inputs_sim.c: the simulated ADC (no hardware): per input a triangle wave of period 16.384 s
 * between 6 % and 94 % of the compiled-in domain, each input at its own phase. */
#include "hal.h"
#include "inputs.h"

int inputs_read(tm_input in[TM_N_INPUTS])
{
    const uint32_t t_ms = hal_millis();
    unsigned i;
    for (i = 0; i < TM_N_INPUTS; ++i) {
        const uint32_t u = (t_ms / 8u + 331u * i) % 2048u;
        const uint32_t tri = u < 1024u ? u : 2048u - u; /* 0 .. 1024 */
        in[i] = fw_input_at(i, tri + 64u, 1152u);
    }
    return 0;
}

uint32_t inputs_failure_status(int read_status)
{
    (void)read_status;
    return INPUTS_READ_FAILED;
}

size_t inputs_info(uint8_t *p)
{
    const size_t n = PROTO_ADC_BLOCK_SIZE + PROTO_I2C_COUNTS_SIZE;
    memset(p, 0, n); /* no chips, no I2C errors */
    return n;
}
