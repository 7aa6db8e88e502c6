#include "protocol.h"
#include <string.h>

uint8_t proto_crc8(const uint8_t *data, size_t n) {
  uint8_t crc = 0;
  for (size_t i = 0; i < n; i++) {
    crc ^= data[i];
    for (uint8_t b = 0; b < 8; b++) crc = (crc & 0x80) ? (uint8_t)((crc << 1) ^ 0x07) : (uint8_t)(crc << 1);
  }
  return crc;
}

void proto_decoder_init(Decoder *d) {
  d->n = 0;
  d->errors = 0;
}

// Drop the first `k` bytes of the buffer.
static void drop(Decoder *d, uint8_t k) {
  memmove(d->buf, d->buf + k, d->n - k);
  d->n -= k;
}

// Try to take a frame from the front of the buffer: 1 frame, 0 need more, -1 dropped bytes.
static int8_t try_frame(Decoder *d, Frame *out) {
  uint8_t i = 0;
  while (i < d->n && d->buf[i] != PROTO_SYNC) i++;
  if (i > 0) {
    drop(d, i);
    d->errors++;
    return -1;
  }
  if (d->n < 2) return 0;
  uint8_t len = d->buf[1] & 0x0F;
  uint8_t total = len + PROTO_OVERHEAD;
  if (d->n < total) return 0;
  uint8_t type = d->buf[1] >> 4;
  // the length first: it spares the CRC of most false starts
  if (proto_payload_len(type) != (int8_t)len || proto_crc8(d->buf + 1, total - 2) != d->buf[total - 1]) {
    drop(d, 1);  // only the start byte: a real frame may begin inside
    d->errors++;
    return -1;
  }
  out->type = type;
  out->len = len;
  out->seq = d->buf[2];
  memcpy(out->payload, d->buf + 3, len);
  drop(d, total);
  return 1;
}

void proto_decoder_push(Decoder *d, uint8_t byte) {
  if (d->n == sizeof(d->buf)) {  // only if the caller did not pop until 0; be safe
    drop(d, 1);
    d->errors++;
  }
  d->buf[d->n++] = byte;
}

// Each failed candidate drops at least one byte, so a pop ends within d->n rounds, and
// every byte is dropped or taken once: O(buffer) work per byte pushed, on average.
int proto_decoder_pop(Decoder *d, Frame *out) {
  for (;;) {
    int8_t r = try_frame(d, out);
    if (r >= 0) return r;
  }
}

uint8_t proto_encode(uint8_t type, uint8_t seq, const uint8_t *payload, uint8_t len, uint8_t *out) {
  out[0] = PROTO_SYNC;
  out[1] = (uint8_t)((type << 4) | (len & 0x0F));
  out[2] = seq;
  memcpy(out + 3, payload, len);
  out[3 + len] = proto_crc8(out + 1, 2 + len);
  return len + PROTO_OVERHEAD;
}
