/* hal.h: what a port provides (hal_posix.c: a host process; hal_mps2.c: QEMU's mps2-an386). */
#ifndef HAL_H
#define HAL_H

#include <stddef.h>
#include <stdint.h>

#include "adc.h"
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
/* nothing to do for up to max_ms (HAL_IDLE_FOREVER: until input): wait for input or the time */
void hal_idle(uint32_t max_ms);

/* ADC builds (inputs_adc.c): the I2C bus and clock the drivers use. A board implements it against its
 * I2C peripheral; the emulated ports take i2c_bridge.c's, which talks over the byte channel below */
const adc_i2c *hal_i2c(void);
/* the bridge's byte channel (emulated ports): send n bytes; a byte within timeout_ms (1) or none (0) */
void hal_bridge_write(const uint8_t *p, size_t n);
int hal_bridge_read_byte(uint8_t *b, uint32_t timeout_ms);

#endif /* HAL_H */
