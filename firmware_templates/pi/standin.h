/* standin.h: a stand-in for the kernel's i2c-dev and clocks, for tests (see standin.c). */
#ifndef STANDIN_H
#define STANDIN_H

#include <stdint.h>

int standin_open(const char *path, int flags);
int standin_ioctl(int fd, unsigned long request, void *arg);
int standin_close(int fd);
uint64_t standin_monotonic_ns(void);
uint64_t standin_realtime_ns(void);
void standin_sleep_ns(uint64_t ns);

#endif /* STANDIN_H */
