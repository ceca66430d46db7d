/* hal_sim.c: the simulated ADC both ports read: per input a triangle wave of period 16.384 s
 * between 6 % and 94 % of the compiled-in domain, each input at its own phase. */
#include "hal.h"

void hal_sim_inputs(uint32_t t_ms, tm_input in[TM_N_INPUTS])
{
    unsigned i;
    for (i = 0; i < TM_N_INPUTS; ++i) {
        const uint32_t u = (t_ms / 8u + 331u * i) % 2048u;
        const uint32_t tri = u < 1024u ? u : 2048u - u; /* 0 .. 1024 */
        in[i] = fw_input_at(i, tri + 64u, 1152u);
    }
}
