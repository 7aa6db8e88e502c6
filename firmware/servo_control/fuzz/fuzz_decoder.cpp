// libFuzzer target: the firmware's frame parser (protocol.cpp, compiled for the host)
// against the protocol as PROTOCOL.md describes it (spec.h).
//
// For any byte stream:
//  - the decoder's buffer never holds more than its size (ASan cannot see an overrun
//    into the neighbouring fields of the struct, so this is checked after every byte);
//  - every frame it returns is well formed (a known type with its length) and is the
//    next frame the reference decoder found: same type, sequence number and payload,
//    in the same order, none missing once 19 filler bytes have pushed the last one out
//    (proto_decoder_push returns at most one frame per byte, so a frame may come out a
//    few bytes late, never lost or invented);
//  - after the stream and the filler, a valid frame is decoded, exactly;
//  - proto_crc8 is CRC-8/SMBUS and proto_encode's frames decode to what was encoded.
#include <stdint.h>
#include <stddef.h>
#include "protocol.h"
#include "spec.h"

static std::vector<spec::Frame> fw_frames, ref_frames;

static void push_both(Decoder *d, spec::Decoder &ref, uint8_t byte, Frame *out) {
  int r = proto_decoder_push(d, byte, out);
  SPEC_CHECK(d->n <= sizeof(d->buf), "decoder holds %u bytes in a %u-byte buffer", d->n, (unsigned)sizeof(d->buf));
  SPEC_CHECK(r == 0 || r == 1, "proto_decoder_push returned %d", r);
  if (r == 1) {
    SPEC_CHECK(out->len <= PROTO_MAX_PAYLOAD && spec::payload_len(out->type) == out->len,
               "decoded a frame of type %u with %u payload bytes", out->type, out->len);
    spec::Frame f;
    f.type = out->type;
    f.seq = out->seq;
    f.payload.assign(out->payload, out->payload + out->len);
    fw_frames.push_back(f);
  }
  ref.feed(byte, ref_frames);
  // the firmware may lag (one frame per byte) but never get ahead or differ
  bool prefix = fw_frames.size() <= ref_frames.size();
  if (prefix && r == 1) prefix = fw_frames.back() == ref_frames[fw_frames.size() - 1];
  if (!prefix) {
    spec::describe("firmware decoded", fw_frames);
    spec::describe("PROTOCOL.md decodes", ref_frames);
  }
  SPEC_CHECK(prefix, "the firmware decoded a frame PROTOCOL.md does not (or in another order)");
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  static bool once = false;
  if (!once) {
    once = true;
    SPEC_CHECK(proto_crc8((const uint8_t *)"123456789", 9) == 0xF4, "CRC-8/SMBUS check value");
  }
  SPEC_CHECK(proto_crc8(data, size) == spec::crc8(data, size), "proto_crc8 differs from CRC-8/SMBUS");

  // heap-allocated at their exact sizes, so ASan sees any access past them
  Decoder *d = new Decoder;
  Frame *out = new Frame;
  proto_decoder_init(d);
  spec::Decoder ref;
  fw_frames.clear();
  ref_frames.clear();
  for (size_t i = 0; i < size; i++) push_both(d, ref, data[i], out);
  for (int i = 0; i < PROTO_MAX_PAYLOAD + PROTO_OVERHEAD; i++) push_both(d, ref, 0x00, out);
  if (fw_frames.size() != ref_frames.size()) {
    spec::describe("firmware decoded", fw_frames);
    spec::describe("PROTOCOL.md decodes", ref_frames);
  }
  SPEC_CHECK(fw_frames.size() == ref_frames.size(), "%zu frames decoded, PROTOCOL.md decodes %zu",
             fw_frames.size(), ref_frames.size());

  // a valid frame after whatever came before (and the filler) is decoded exactly
  uint8_t payload[8];
  for (int i = 0; i < 8; i++) payload[i] = size > (size_t)i ? data[size - 1 - i] : (uint8_t)i;
  uint8_t enc[PROTO_MAX_PAYLOAD + PROTO_OVERHEAD];
  uint8_t n = proto_encode(MSG_SET_PULSES, 0x77, payload, 8, enc);
  std::vector<uint8_t> want = spec::encode(spec::SET_PULSES, 0x77, payload, 8);
  SPEC_CHECK(n == want.size() && memcmp(enc, want.data(), n) == 0, "proto_encode differs from PROTOCOL.md's frame");
  size_t before = fw_frames.size();
  for (uint8_t i = 0; i < n; i++) push_both(d, ref, enc[i], out);
  SPEC_CHECK(fw_frames.size() == before + 1 && fw_frames.back().type == MSG_SET_PULSES && fw_frames.back().seq == 0x77 &&
                 memcmp(fw_frames.back().payload.data(), payload, 8) == 0,
             "a valid SET_PULSES after the input was not decoded (%zu frames)", fw_frames.size() - before);
  delete out;
  delete d;
  return 0;
}
