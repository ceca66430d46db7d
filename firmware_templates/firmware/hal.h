/* hal.h: what a port provides (hal_posix.c: a host process; hal_mps2.c: QEMU's mps2-an386). */
#ifndef HAL_H
#define HAL_H

#include <stddef.h>
#include <stdint.h>

#include "model_api.h"

#define HAL_IDLE_FOREVER 0xFFFFFFFFu

/* set the port up; argc/argv are the process's on a host, (0, 0) on a board */
void hal_init(int argc, char **argv);
/* 0 once the port wants the firmware to stop (host: end of input, SIGTERM, SIGINT); a board never stops */
int hal_alive(void);
/* non-blocking: 1 and *b when a byte was read, else 0 */
int hal_poll_byte(uint8_t *b);
/* send n bytes (blocks until they are handed over) */
void hal_write(const uint8_t *p, size_t n);
/* milliseconds since hal_init, wrapping */
uint32_t hal_millis(void);
/* a free-running 64-bit count of hal_tick_hz() ticks per second */
uint64_t hal_ticks(void);
uint32_t hal_tick_hz(void);
/* the sensor: a simulated ADC on both ports, a deterministic slowly varying vector inside the domain */
void hal_read_inputs(tm_input in[TM_N_INPUTS]);
/* nothing to do for up to max_ms (HAL_IDLE_FOREVER: until input): wait for input or the time */
void hal_idle(uint32_t max_ms);

/* shared by the ports: the simulated inputs at time t_ms (triangle waves, one phase per input) */
void hal_sim_inputs(uint32_t t_ms, tm_input in[TM_N_INPUTS]);

#endif /* HAL_H */
