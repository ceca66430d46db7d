/* tactile_wire.h: the ADC drivers' I2C port (adc.h's adc_i2c) over the Arduino Wire library. */
#ifndef TACTILE_WIRE_H
#define TACTILE_WIRE_H

#ifdef __cplusplus
extern "C" {
#endif
#include "adc.h"
#ifdef __cplusplus
}
#endif

/* Fill `out` with transfers on Wire (Wire.begin() first). `timeout_us` bounds every bus transaction
 * (Wire.setWireTimeout, which also resets the TWI unit after a timeout). */
void tactile_wire_bus(adc_i2c *out, uint32_t timeout_us);

#endif /* TACTILE_WIRE_H */
