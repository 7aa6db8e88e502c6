// The few Arduino core declarations servo_control.ino uses, for building the sketch's
// logic on the host (fuzz/). The fuzz harness defines them: `Serial` reads the bytes the
// fuzzer feeds and records what the sketch writes; `millis()` is a clock the harness
// advances. Nothing here is used by the AVR build.
#pragma once
#include <stddef.h>
#include <stdint.h>
#include <string.h>

typedef uint8_t byte;

unsigned long millis(void);

struct HostSerial {
  void begin(unsigned long baud);
  int available();
  int read();
  size_t write(const uint8_t *data, size_t n);
};
extern HostSerial Serial;
