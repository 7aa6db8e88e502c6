// The servo link as PROTOCOL.md describes it, written again from the document (not from
// protocol.cpp), for the fuzz targets to compare the firmware with. Host-only C++11.
#pragma once
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <vector>

namespace spec {

// A finding: say what broke and abort, so that libFuzzer saves the input.
#define SPEC_CHECK(cond, ...)                                              \
  do {                                                                     \
    if (!(cond)) {                                                         \
      fprintf(stderr, "\nINVARIANT BROKEN at %s:%d: %s\n  ", __FILE__, __LINE__, #cond); \
      fprintf(stderr, __VA_ARGS__);                                        \
      fprintf(stderr, "\n");                                               \
      abort();                                                             \
    }                                                                      \
  } while (0)

const uint8_t SYNC = 0xA5;
enum { HELLO = 1, HELLO_ACK = 2, SET_PULSES = 3, HEARTBEAT = 4, STATE = 5, ESTOP = 6, CONFIG = 7,
       ROLE = 8, LEADER_STATE = 9 };
enum { IDLE = 0, RUNNING = 1, WATCHDOG_HOLD = 2, WATCHDOG_DETACHED = 3, E_STOP = 4, LEADER = 5 };
enum { FOLLOWER_ROLE = 0, LEADER_ROLE = 1 };

// CRC-8/SMBUS: polynomial 0x07, init 0, no reflection, no final xor.
inline uint8_t crc8(const uint8_t *p, size_t n) {
  uint8_t c = 0;
  for (size_t i = 0; i < n; i++) {
    c ^= p[i];
    for (int b = 0; b < 8; b++) c = (uint8_t)((c & 0x80) ? (c << 1) ^ 0x07 : c << 1);
  }
  return c;
}

// The payload length of each type (the message table), -1 unknown.
inline int payload_len(int type) {
  switch (type) {
    case HELLO: return 1;
    case HELLO_ACK: return 6;
    case SET_PULSES: return 8;
    case HEARTBEAT: return 0;
    case STATE: return 12;
    case ESTOP: return 1;
    case CONFIG: return 3;
    case ROLE: return 1;
    case LEADER_STATE: return 11;
    default: return -1;
  }
}

struct Frame {
  uint8_t type, seq;
  std::vector<uint8_t> payload;
  bool operator==(const Frame &o) const { return type == o.type && seq == o.seq && payload == o.payload; }
};

inline std::vector<uint8_t> encode(uint8_t type, uint8_t seq, const uint8_t *payload, uint8_t len) {
  std::vector<uint8_t> f;
  f.push_back(SYNC);
  f.push_back((uint8_t)((type << 4) | (len & 0x0F)));
  f.push_back(seq);
  f.insert(f.end(), payload, payload + len);
  f.push_back(crc8(f.data() + 1, f.size() - 1));
  return f;
}

// "A receiver scans for 0xA5, waits for len + 4 bytes and checks the CRC and that len is
// the length of that type. On any failure it drops only the start byte and scans again."
// Every frame comes out as soon as the byte that makes it decodable is in: its last byte,
// or the byte that makes a candidate before it fail (then several can come out at once).
struct Decoder {
  std::vector<uint8_t> buf;
  void clear() { buf.clear(); }
  void feed(uint8_t byte, std::vector<Frame> &out) {
    buf.push_back(byte);
    for (;;) {
      size_t i = 0;
      while (i < buf.size() && buf[i] != SYNC) i++;
      buf.erase(buf.begin(), buf.begin() + i);
      if (buf.size() < 2) return;
      size_t len = buf[1] & 0x0F, total = len + 4;
      if (buf.size() < total) return;
      if (crc8(buf.data() + 1, total - 2) != buf[total - 1] || payload_len(buf[1] >> 4) != (int)len) {
        buf.erase(buf.begin());
        continue;
      }
      Frame f;
      f.type = buf[1] >> 4;
      f.seq = buf[2];
      f.payload.assign(buf.begin() + 3, buf.begin() + 3 + len);
      out.push_back(f);
      buf.erase(buf.begin(), buf.begin() + total);
    }
  }
};

inline void describe(const char *what, const std::vector<Frame> &v) {
  fprintf(stderr, "  %s:", what);
  for (const Frame &f : v) {
    fprintf(stderr, " [type %u seq %u:", f.type, f.seq);
    for (uint8_t b : f.payload) fprintf(stderr, " %02X", b);
    fprintf(stderr, "]");
  }
  fprintf(stderr, "\n");
}

}  // namespace spec
