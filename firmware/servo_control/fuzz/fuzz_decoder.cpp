// libFuzzer target: the firmware's frame parser (protocol.cpp, compiled for the host)
// against the protocol as PROTOCOL.md describes it (spec.h).
//
// For any byte stream:
//  - the decoder's buffer never holds more than its size (ASan cannot see an overrun
//    into the neighbouring fields of the struct, so this is checked after every byte);
//  - after each byte, popping until 0 yields exactly the frames the reference decoder
//    finds with that byte: same type, sequence number and payload, in the same order,
//    none late, missing, repeated or invented (one byte can complete several frames:
//    the one that makes a false start fail), each well formed (a known type with its
//    length); then the buffer holds less than its size, so the next byte fits;
//  - after the stream and 19 filler bytes, a valid frame is decoded, exactly;
//  - proto_crc8 is CRC-8/SMBUS and proto_encode's frames decode to what was encoded.
#include <stdint.h>
#include <stddef.h>
#include "protocol.h"
#include "spec.h"

static std::vector<spec::Frame> fw_frames, ref_frames;

static void push_both(Decoder *d, spec::Decoder &ref, uint8_t byte, Frame *out) {
  proto_decoder_push(d, byte);
  SPEC_CHECK(d->n <= sizeof(d->buf), "decoder holds %u bytes in a %u-byte buffer", d->n, (unsigned)sizeof(d->buf));
  size_t before = fw_frames.size();
  for (;;) {
    int r = proto_decoder_pop(d, out);
    SPEC_CHECK(d->n <= sizeof(d->buf), "decoder holds %u bytes in a %u-byte buffer", d->n, (unsigned)sizeof(d->buf));
    SPEC_CHECK(r == 0 || r == 1, "proto_decoder_pop returned %d", r);
    if (r == 0) break;
    SPEC_CHECK(out->len <= PROTO_MAX_PAYLOAD && spec::payload_len(out->type) == out->len,
               "decoded a frame of type %u with %u payload bytes", out->type, out->len);
    // a frame takes at least PROTO_OVERHEAD bytes of a buffer the byte was pushed into
    SPEC_CHECK(fw_frames.size() - before < sizeof(d->buf) / PROTO_OVERHEAD, "more frames out of one byte than fit in the buffer");
    spec::Frame f;
    f.type = out->type;
    f.seq = out->seq;
    f.payload.assign(out->payload, out->payload + out->len);
    fw_frames.push_back(f);
  }
  SPEC_CHECK(proto_decoder_pop(d, out) == 0, "proto_decoder_pop returned a frame after returning 0");
  SPEC_CHECK(d->n < sizeof(d->buf), "drained, the decoder holds %u bytes: the next byte would not fit", d->n);
  ref.feed(byte, ref_frames);
  // every frame as soon as its byte is in: none late, missing, invented, repeated or reordered
  bool same = fw_frames == ref_frames;
  if (!same) {
    spec::describe("firmware decoded", fw_frames);
    spec::describe("PROTOCOL.md decodes", ref_frames);
  }
  SPEC_CHECK(same, "after this byte the firmware has decoded other frames than PROTOCOL.md (%zu, %zu)",
             fw_frames.size(), ref_frames.size());
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
  // resolves any partial candidate, so that the frame below starts on a clean buffer
  for (int i = 0; i < PROTO_MAX_PAYLOAD + PROTO_OVERHEAD; i++) push_both(d, ref, 0x00, out);
  SPEC_CHECK(d->n == 0, "after 19 zero bytes the decoder still holds %u bytes", d->n);

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
