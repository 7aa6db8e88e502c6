// libFuzzer target: the whole servo_control sketch (servo_control.ino + protocol.cpp,
// compiled for the host with stub/Arduino.h; the Timer1 pulse driver replaced by a table)
// against a model of the device written from PROTOCOL.md.
//
// The fuzzer's input is a script of operations on the device:
//   00kkkkkk  the next k+1 input bytes arrive on the UART, then loop() runs
//   010-tttt  a valid frame of type t (0..15, unknown types too) with the next bytes
//             as sequence number and payload (its type's length; else the low nibble of
//             the next byte), correct CRC, then loop()
//   10dddddd  the clock advances (d < 32: d ms; else (d - 31) * 25 ms, up to 800 ms),
//             then loop()
//   011-----  a leader sampling window ends (if the sketch samples: leader role) with the
//             next 10 bytes as its four sums, deadman bit (bit 0) and overruns, then
//             loop()
//   11------  a pause longer than FRAME_GAP_MS, then a HEARTBEAT with the next byte as
//             sequence number: the device must answer it
// and every run ends with that pause and HEARTBEAT.
//
// Checked after every step:
//  - no pulse width the sketch sets is outside config.h's table for its channel (0 = off);
//  - the widths output are the model's: they change only on a SET_PULSES outside the
//    e-stop (to its values clamped into the table) or when the watchdog detaches;
//  - every reply is the model's: HELLO_ACK for HELLO, a STATE (acknowledged sequence
//    number, state, clamped flag, widths) for every other host frame, an unsolicited
//    STATE when the watchdog fires, nothing for device-to-host types, a LEADER_STATE
//    (the window's sums, deadman bit, number and overruns) for each sampling window in
//    the leader role; transmit sequence numbers count up by one;
//  - the sampler (leader_adc.h) runs exactly while the model is in the leader role;
//    begin and end alternate; no pulses in the leader role;
//  - a valid frame after garbage and a pause longer than FRAME_GAP_MS is handled, and a
//    frame is handled in the loop() that reads the byte making it decodable (its last
//    byte, or the one that makes a false start before it fail: then several are handled
//    at once), never left waiting and dropped as a partial frame.

// The sketch, its statics in sections of their own: every run starts from them as they
// were at power-up (restored byte for byte), whatever statics the sketch has.
#pragma clang section bss = "sketch_bss" data = "sketch_data"
#include "../servo_control.ino"
#pragma clang section bss = "" data = ""
#include "spec.h"

extern "C" char __start_sketch_bss[], __stop_sketch_bss[], __start_sketch_data[], __stop_sketch_data[];
static std::vector<char> power_up_bss, power_up_data;

// not instrumented: the sections hold ASan's red zones between the variables
__attribute__((no_sanitize("address"))) static void copy_raw(char *to, const char *from, size_t n) {
  for (size_t i = 0; i < n; i++) to[i] = from[i];
}

// ---- the host side of stub/Arduino.h and servo_pwm.h -------------------------------
static unsigned long now_ms;
static std::vector<uint8_t> rx;  // bytes the host sent, not yet read
static size_t rx_next;
static std::vector<uint8_t> tx;  // bytes the sketch wrote
static uint16_t width[SERVO_COUNT];
// the sampler of leader_adc.h: running, and a window ended but not taken
static bool sampling, window_ready;
static LeaderWindow window_data;
static uint8_t windows;

HostSerial Serial;
void HostSerial::begin(unsigned long) {}
int HostSerial::available() { return (int)(rx.size() - rx_next); }
int HostSerial::read() { return rx_next < rx.size() ? rx[rx_next++] : -1; }
size_t HostSerial::write(const uint8_t *p, size_t n) {
  tx.insert(tx.end(), p, p + n);
  return n;
}
unsigned long millis(void) { return now_ms; }

void servo_pwm_begin() { memset(width, 0, sizeof(width)); }
void servo_pwm_set(uint8_t i, uint16_t ticks) {
  SPEC_CHECK(i < SERVO_COUNT, "servo_pwm_set on channel %u", i);
  SPEC_CHECK(ticks == 0 || (ticks >= SERVO_MIN_TICKS[i] && ticks <= SERVO_MAX_TICKS[i]),
             "channel %u (pin %u) set to %u ticks, outside config.h's %u..%u", i, 8 + i, ticks,
             SERVO_MIN_TICKS[i], SERVO_MAX_TICKS[i]);
  width[i] = ticks;
}
void servo_pwm_sync() {}  // frame timing only: no width changes
// every width set is on the pins at once in this model: nothing waits to be shown
void servo_pwm_hold() {}
uint16_t servo_pwm_get(uint8_t i) { return i < SERVO_COUNT ? width[i] : 0; }

void leader_adc_begin() {
  SPEC_CHECK(!sampling, "leader_adc_begin() while sampling");
  sampling = true;
  window_ready = false;
  windows = 0;
}
void leader_adc_end() {
  SPEC_CHECK(sampling, "leader_adc_end() while not sampling");
  sampling = false;
  window_ready = false;
}
uint8_t leader_adc_take(LeaderWindow *out) {
  SPEC_CHECK(sampling, "leader_adc_take() while not sampling");
  if (!window_ready) return 0;
  *out = window_data;
  window_ready = false;
  return 1;
}

extern "C" int LLVMFuzzerInitialize(int *, char ***) {
  power_up_bss.resize(__stop_sketch_bss - __start_sketch_bss);
  power_up_data.resize(__stop_sketch_data - __start_sketch_data);
  copy_raw(power_up_bss.data(), __start_sketch_bss, power_up_bss.size());
  copy_raw(power_up_data.data(), __start_sketch_data, power_up_data.size());
  return 0;
}

// Power-on: the sketch's statics as they were before the first run, then setup().
static void boot() {
  now_ms = 0;
  rx.clear();
  rx_next = 0;
  tx.clear();
  sampling = window_ready = false;
  copy_raw(__start_sketch_bss, power_up_bss.data(), power_up_bss.size());
  copy_raw(__start_sketch_data, power_up_data.data(), power_up_data.size());
  setup();
}

// ---- the device as PROTOCOL.md describes it ----------------------------------------
struct Reply {
  uint8_t type;
  std::vector<uint8_t> payload;  // STATE: rx_errors (byte 3) is not compared
};

// Version 1 of the page and version 2 (ESTOP 2 stops the pulses; STATE reports the
// commanded widths, or the hold pose of config.h before the first command) are both
// modelled: the one the sketch's PROTOCOL_VERSION names is checked. Version 3's leader
// role (ROLE, LEADER_STATE) is modelled as the page says it.
struct Model {
  spec::Decoder dec;
  unsigned long last_byte = 0, last_rx = 0;
  uint8_t st = spec::IDLE, clamped = 0, last_seq = 0;
  uint8_t role = spec::FOLLOWER_ROLE;
  bool window_due = false;  // a sampling window ended: a LEADER_STATE is due
  uint8_t window_payload[11] = {0};
  uint16_t applied[SERVO_COUNT] = {0}, out[SERVO_COUNT] = {0};
  bool output = false;  // pulses going out
  uint16_t watchdog_ms = WATCHDOG_MS_DEFAULT;
  bool detach = WATCHDOG_DETACH_DEFAULT;
  std::vector<Reply> replies;

  Model() {
#if PROTOCOL_VERSION >= 2
    for (int i = 0; i < SERVO_COUNT; i++) {
      SPEC_CHECK(HOLD_TICKS[i] >= SERVO_MIN_TICKS[i] && HOLD_TICKS[i] <= SERVO_MAX_TICKS[i],
                 "config.h's hold pose %u of channel %d is outside its limits", HOLD_TICKS[i], i);
      applied[i] = HOLD_TICKS[i];
    }
#endif
  }

  void stop_pulses() {
    output = false;
    memset(out, 0, sizeof(out));
  }

  // "Taking the role the device has changes nothing." Leader: the pulses stop, whatever
  // the state (the e-stop too); follower again: idle.
  void set_role(uint8_t r) {
    if (r == role) return;
    role = r;
    if (r == spec::LEADER_ROLE) {
      stop_pulses();
      st = spec::LEADER;
    } else {
      st = spec::IDLE;
      window_due = false;
    }
  }

  void state_reply() {
    Reply r;
    r.type = spec::STATE;
    uint8_t p[12] = {last_seq, st, clamped, 0};
    for (int i = 0; i < SERVO_COUNT; i++) {
      uint16_t t = PROTOCOL_VERSION >= 2 ? applied[i] : out[i];
      p[4 + 2 * i] = (uint8_t)t;
      p[5 + 2 * i] = (uint8_t)(t >> 8);
    }
    r.payload.assign(p, p + 12);
    replies.push_back(r);
  }

  void handle(const spec::Frame &f, unsigned long now) {
    last_seq = f.seq;
    last_rx = now;
    const uint8_t *p = f.payload.data();
    switch (f.type) {
      case spec::HELLO: {
        set_role(spec::FOLLOWER_ROLE);  // "every HELLO puts it back in the follower role"
        uint8_t a[6] = {PROTOCOL_VERSION, FIRMWARE_MAJOR, FIRMWARE_MINOR, SERVO_COUNT,
                        (uint8_t)watchdog_ms, (uint8_t)(watchdog_ms >> 8)};
        Reply r;
        r.type = spec::HELLO_ACK;
        r.payload.assign(a, a + 6);
        replies.push_back(r);
        return;
      }
      case spec::SET_PULSES:
        // "ignores SET_PULSES until ESTOP(0)"; a leader ignores them
        if (st != spec::E_STOP && role == spec::FOLLOWER_ROLE) {
          clamped = 0;
          for (int i = 0; i < SERVO_COUNT; i++) {
            uint16_t t = (uint16_t)(p[2 * i] | (p[2 * i + 1] << 8));
            uint16_t c = t == 0 ? 0 : t < SERVO_MIN_TICKS[i] ? SERVO_MIN_TICKS[i] : t > SERVO_MAX_TICKS[i] ? SERVO_MAX_TICKS[i] : t;
            clamped |= c != t;
            applied[i] = out[i] = c;
          }
          output = true;
          st = spec::RUNNING;
        }
        break;
      case spec::HEARTBEAT:
        break;
      case spec::ESTOP:
        if (role == spec::LEADER_ROLE) break;  // "ESTOP changes nothing" for a leader
        if (p[0] == 1 || (PROTOCOL_VERSION >= 2 && p[0] == 2)) {
          st = spec::E_STOP;
          if (p[0] == 2) stop_pulses();
        } else if (p[0] == 0 && st == spec::E_STOP) {
          if (PROTOCOL_VERSION >= 2) {
            st = output ? spec::RUNNING : spec::IDLE;  // "held pulses go on, stopped ones stay off"
          } else {
            bool any = false;
            for (int i = 0; i < SERVO_COUNT; i++) any |= applied[i] != 0;
            st = any ? spec::RUNNING : spec::IDLE;
          }
        }
        break;
      case spec::CONFIG: {
        uint16_t ms = (uint16_t)(p[0] | (p[1] << 8));
        watchdog_ms = ms < WATCHDOG_MS_MIN ? WATCHDOG_MS_MIN : ms;
        detach = p[2] == 1;
        break;
      }
      case spec::ROLE:
        if (p[0] <= spec::LEADER_ROLE) set_role(p[0]);  // other bytes: no change, STATE
        break;
      default:  // HELLO_ACK, STATE, LEADER_STATE: device-to-host types, no answer
        return;
    }
    state_reply();
  }

  // what loop() does with the bytes that arrived since the last one, at `now`
  void loop(const uint8_t *bytes, size_t n, unsigned long now) {
    for (size_t i = 0; i < n; i++) {
      last_byte = now;
      std::vector<spec::Frame> frames;
      dec.feed(bytes[i], frames);
      for (const spec::Frame &f : frames) handle(f, now);
    }
    if (!dec.buf.empty() && now - last_byte > FRAME_GAP_MS) dec.clear();  // a partial frame only
    if (st == spec::RUNNING && now - last_rx > watchdog_ms) {
      if (detach) {
        st = spec::WATCHDOG_DETACHED;
        stop_pulses();
      } else {
        st = spec::WATCHDOG_HOLD;
      }
      state_reply();
    }
    if (role == spec::LEADER_ROLE && window_due) {  // "a LEADER_STATE every window"
      Reply r;
      r.type = spec::LEADER_STATE;
      r.payload.assign(window_payload, window_payload + 11);
      replies.push_back(r);
      window_due = false;
    }
  }
};

static Model model;
static spec::Decoder tx_decoder;
static size_t tx_seen;
static int last_tx_seq;
static size_t step;

static void print_replies(const char *what, const std::vector<Reply> &v, size_t from) {
  fprintf(stderr, "  %s:", what);
  for (size_t i = from; i < v.size(); i++) {
    fprintf(stderr, " [type %u:", v[i].type);
    for (uint8_t b : v[i].payload) fprintf(stderr, " %02X", b);
    fprintf(stderr, "]");
  }
  fprintf(stderr, "\n");
}

// Deliver `bytes`, run loop() once on the sketch and on the model, compare.
static void run_loop(const uint8_t *bytes, size_t n) {
  step++;
  rx.insert(rx.end(), bytes, bytes + n);
  size_t replies_before = model.replies.size();
  loop();
  SPEC_CHECK(rx_next == rx.size(), "loop() left %zu bytes unread", rx.size() - rx_next);
  model.loop(bytes, n, now_ms);
  SPEC_CHECK(decoder.n <= sizeof(decoder.buf), "decoder holds %u bytes", decoder.n);

  // what the sketch wrote, as frames
  std::vector<spec::Frame> sent;
  for (; tx_seen < tx.size(); tx_seen++) tx_decoder.feed(tx[tx_seen], sent);
  std::vector<Reply> got;
  for (const spec::Frame &f : sent) {
    SPEC_CHECK(f.seq == (uint8_t)(last_tx_seq + 1), "transmit sequence %u after %d", f.seq, last_tx_seq);
    last_tx_seq = f.seq;
    Reply r;
    r.type = f.type;
    r.payload = f.payload;
    if (r.type == spec::STATE) r.payload[3] = 0;  // rx_errors: counted, not modelled
    got.push_back(r);
  }
  bool same = got.size() == model.replies.size() - replies_before;
  for (size_t i = 0; same && i < got.size(); i++)
    same = got[i].type == model.replies[replies_before + i].type && got[i].payload == model.replies[replies_before + i].payload;
  if (!same) {
    fprintf(stderr, "step %zu at %lu ms, %zu bytes in:", step, now_ms, n);
    for (size_t i = 0; i < n; i++) fprintf(stderr, " %02X", bytes[i]);
    fprintf(stderr, "\n");
    print_replies("the sketch answered", got, 0);
    print_replies("PROTOCOL.md answers", model.replies, replies_before);
  }
  SPEC_CHECK(same, "the sketch's replies differ from PROTOCOL.md's");
  for (int i = 0; i < SERVO_COUNT; i++)
    SPEC_CHECK(width[i] == model.out[i], "step %zu at %lu ms: pin %d outputs %u ticks, PROTOCOL.md says %u",
               step, now_ms, 8 + i, width[i], model.out[i]);
  SPEC_CHECK(sampling == (model.role == spec::LEADER_ROLE), "step %zu: the sampler %s in the %s role", step,
             sampling ? "runs" : "stopped", model.role == spec::LEADER_ROLE ? "leader" : "follower");
  SPEC_CHECK(!window_ready, "step %zu: a sampling window was not taken", step);
}

// A sampling window ends with the sums, deadman bit and overruns in `b` (10 bytes).
static void window_ends(const uint8_t *b) {
  if (sampling) {
    for (int c = 0; c < LEADER_CHANNELS; c++) window_data.sum[c] = (uint16_t)(b[2 * c] | (b[2 * c + 1] << 8));
    window_data.deadman = b[8] & 1;
    window_data.window = windows++;
    window_data.overruns = b[9];
    window_ready = true;
    memcpy(model.window_payload, b, 8);
    model.window_payload[8] = window_data.deadman;
    model.window_payload[9] = window_data.window;
    model.window_payload[10] = window_data.overruns;
    model.window_due = true;
  }
  run_loop(NULL, 0);
}

static void advance(unsigned long ms) {
  now_ms += ms;
  run_loop(NULL, 0);
}

static void resync_check(uint8_t seq) {
  advance(FRAME_GAP_MS + 1);
  std::vector<uint8_t> hb = spec::encode(spec::HEARTBEAT, seq, NULL, 0);
  size_t before = model.replies.size();
  run_loop(hb.data(), hb.size());
  SPEC_CHECK(model.replies.size() > before && model.replies.back().type == spec::STATE &&
                 model.replies.back().payload[0] == seq,
             "a HEARTBEAT after a pause was not answered");
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  boot();
  model = Model();
  tx_decoder.clear();
  tx_seen = 0;
  last_tx_seq = 0;
  step = 0;
  size_t i = 0;
  auto next = [&](uint8_t dflt) -> uint8_t { return i < size ? data[i++] : dflt; };
  while (i < size) {
    uint8_t op = data[i++];
    switch (op >> 6) {
      case 0: {
        size_t k = (op & 0x3F) + 1;
        if (k > size - i) k = size - i;
        run_loop(data + i, k);
        i += k;
        break;
      }
      case 1: {
        if (op & 0x20) {
          uint8_t b[10];
          for (int j = 0; j < 10; j++) b[j] = next(0);
          window_ends(b);
          break;
        }
        uint8_t type = op & 0x0F;
        uint8_t seq = next(0);
        int len = spec::payload_len(type);
        if (len < 0) len = next(0) & 0x0F;
        uint8_t payload[15];
        for (int j = 0; j < len; j++) payload[j] = next(0);
        std::vector<uint8_t> f = spec::encode(type, seq, payload, (uint8_t)len);
        run_loop(f.data(), f.size());
        break;
      }
      case 2: {
        uint8_t d = op & 0x3F;
        advance(d < 32 ? d : (unsigned long)(d - 31) * 25);
        break;
      }
      default:
        resync_check(next(0x5A));
        break;
    }
  }
  resync_check(0x5A);
  return 0;
}
