/* i2c_linux.h: the ADC drivers' I2C port over Linux i2c-dev (ioctl I2C_RDWR), and a wall clock. */
#ifndef I2C_LINUX_H
#define I2C_LINUX_H

#include <stddef.h>
#include <stdint.h>

#include "adc.h"

typedef struct {
    int fd;
} i2c_linux;

/* open /dev/i2c-<bus>; 0, or -1 with a one-line reason in err */
int i2c_linux_open(i2c_linux *port, int bus, adc_i2c *out, char *err, size_t err_len);
void i2c_linux_close(i2c_linux *port);
/* Unix time in ns (the t column of tactile-host read) */
uint64_t i2c_linux_realtime_ns(void);

#endif /* I2C_LINUX_H */
