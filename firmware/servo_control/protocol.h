// The servo link's frames (PROTOCOL.md): 0xA5 | type<<4|len | seq | payload | crc8.
#pragma once
#include <stdint.h>
#include <stddef.h>

// generated: frame constants
// Written from libs/servo_protocol/src/frame.rs, the one source of these values; after
// a change there: EEZYBOT_BLESS=1 cargo test -p servo_protocol --test firmware_header
#define PROTOCOL_VERSION 3
#define PROTO_SYNC 0xA5
#define PROTO_MAX_PAYLOAD 15
#define PROTO_OVERHEAD 4

enum MsgType {
  MSG_HELLO = 0x1,
  MSG_HELLO_ACK = 0x2,
  MSG_SET_PULSES = 0x3,
  MSG_HEARTBEAT = 0x4,
  MSG_STATE = 0x5,
  MSG_ESTOP = 0x6,
  MSG_CONFIG = 0x7,
  MSG_ROLE = 0x8,
  MSG_LEADER_STATE = 0x9,
};

// The state byte of a STATE payload.
enum DeviceState {
  STATE_IDLE = 0,
  STATE_RUNNING = 1,
  STATE_WATCHDOG_HOLD = 2,
  STATE_WATCHDOG_DETACHED = 3,
  STATE_ESTOP = 4,
  STATE_LEADER = 5,
};

// The role byte of a ROLE payload.
enum DeviceRole {
  ROLE_FOLLOWER = 0,
  ROLE_LEADER = 1,
};

// The leader role's sampling: a LEADER_STATE every LEADER_PERIOD_US, each channel
// the sum of LEADER_OVERSAMPLING samples.
#define LEADER_CHANNELS 4
#define LEADER_OVERSAMPLING 16
#define LEADER_PERIOD_US 9600

// Payload length each type must have, or -1 for an unknown type.
static inline int8_t proto_payload_len(uint8_t type) {
  switch (type) {
    case MSG_HELLO: return 1;
    case MSG_HELLO_ACK: return 6;
    case MSG_SET_PULSES: return 8;
    case MSG_HEARTBEAT: return 0;
    case MSG_STATE: return 12;
    case MSG_ESTOP: return 1;
    case MSG_CONFIG: return 3;
    case MSG_ROLE: return 1;
    case MSG_LEADER_STATE: return 11;
    default: return -1;
  }
}
// end generated: frame constants

struct Frame {
  uint8_t type;
  uint8_t len;
  uint8_t seq;
  uint8_t payload[PROTO_MAX_PAYLOAD];
};

uint8_t proto_crc8(const uint8_t *data, size_t n);

// Streaming decoder (PROTOCOL.md's receiver). Push each byte received, then pop until
// it returns 0:
//
//   proto_decoder_push(&d, byte);
//   while (proto_decoder_pop(&d, &f)) handle(&f);
//
// One byte can complete several frames: when it makes a candidate fail (bad CRC or
// length), only that start byte is dropped and the frames already received behind it
// come out, in order, each once. Invalid bytes are dropped and counted in `errors`.
// Drained after each push, the buffer holds at most one incomplete candidate
// (< PROTO_MAX_PAYLOAD + PROTO_OVERHEAD bytes), so the next push always fits.
struct Decoder {
  uint8_t buf[PROTO_MAX_PAYLOAD + PROTO_OVERHEAD];
  uint8_t n;
  uint8_t errors;
};
void proto_decoder_init(Decoder *d);
void proto_decoder_push(Decoder *d, uint8_t byte);
// 1: `out` holds the next complete frame (taken from the buffer); 0: none is complete.
int proto_decoder_pop(Decoder *d, Frame *out);

// Encode a frame into `out` (at least len + PROTO_OVERHEAD bytes); returns its size.
uint8_t proto_encode(uint8_t type, uint8_t seq, const uint8_t *payload, uint8_t len, uint8_t *out);
