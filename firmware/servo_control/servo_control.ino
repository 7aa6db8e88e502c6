// EezyBotArm Mk2 servo controller for an Arduino Uno.
//
// Speaks the framed binary protocol of PROTOCOL.md with serial_node over USB at
// 115200 baud and drives the servos on pins 8 (base), 9 (shoulder), 10 (elbow) and
// 11 (gripper) with its own Timer1 pulse driver (servo_pwm.cpp: the Servo library's
// pulses, 544-2400 us every 20 ms; a new command starts the next frame early, 14 ms or
// more after the last). Malformed frames are ignored and counted; every command is
// clamped to the limits in config.h; on silence longer than the watchdog timeout it
// holds (or stops) the pulses and says so; the e-stop holds (or stops) them and ignores
// commands until released. No pulses go out before the first command; until
// then it reports its hold pose (config.h), where the host's first command starts.
//
// The same sketch is a leader (PROTOCOL.md version 3: the host selects the role with
// ROLE, so the same image goes on both Unos of leader-follower teleoperation): no
// pulses; four potentiometers on A0..A3 and a deadman button on D2 sampled by Timer2
// (leader_adc.cpp: 16 samples a channel in 9.6 ms windows) and streamed as
// LEADER_STATE, one a window. A HELLO (a new session) makes it a follower again.
//
// Builds in the Arduino IDE (board: Arduino Uno) and with `make` (avr-gcc + Debian's
// arduino-core-avr).

#include <Arduino.h>
#include "config.h"
#include "protocol.h"
#include "servo_pwm.h"
#include "leader_adc.h"

static Decoder decoder;
static uint8_t state = STATE_IDLE;
static uint8_t role = ROLE_FOLLOWER;
// clamped command, ticks (0 = no pulses on that channel); the hold pose before the first
static uint16_t applied[SERVO_COUNT];
static bool output = false;  // pulses going out
static uint8_t clamped = 0;
static uint8_t last_seq = 0;
static uint8_t tx_seq = 0;
static uint16_t watchdog_ms = WATCHDOG_MS_DEFAULT;
static uint8_t watchdog_detach = WATCHDOG_DETACH_DEFAULT;
static unsigned long last_rx_ms = 0;
static unsigned long last_byte_ms = 0;

static void put_u16(uint8_t *p, uint16_t v) {
  p[0] = (uint8_t)(v & 0xFF);
  p[1] = (uint8_t)(v >> 8);
}

static uint16_t get_u16(const uint8_t *p) {
  return (uint16_t)p[0] | ((uint16_t)p[1] << 8);
}

static void send(uint8_t type, const uint8_t *payload, uint8_t len) {
  uint8_t out[PROTO_MAX_PAYLOAD + PROTO_OVERHEAD];
  tx_seq++;
  uint8_t n = proto_encode(type, tx_seq, payload, len, out);
  Serial.write(out, n);
}

static void send_state() {
  uint8_t p[12];
  p[0] = last_seq;
  p[1] = state;
  p[2] = clamped;
  p[3] = decoder.errors;
  // the commanded widths; without pulses, the pose the next command starts from
  for (uint8_t i = 0; i < SERVO_COUNT; i++) put_u16(p + 4 + 2 * i, applied[i]);
  send(MSG_STATE, p, sizeof(p));
}

// Output what `applied` says, or nothing when detached / idle.
static void output_pulses(bool on) {
  output = on;
  for (uint8_t i = 0; i < SERVO_COUNT; i++) servo_pwm_set(i, on ? applied[i] : 0);
  servo_pwm_sync();  // a new width starts the next frame early (servo_pwm.h)
}

static void send_leader_state(const LeaderWindow *w) {
  uint8_t p[11];
  for (uint8_t i = 0; i < LEADER_CHANNELS; i++) put_u16(p + 2 * i, w->sum[i]);
  p[8] = w->deadman;
  p[9] = w->window;
  p[10] = w->overruns;
  send(MSG_LEADER_STATE, p, sizeof(p));
}

// Leader: the pulses stop (whatever the state, the e-stop too: a leader has none),
// the sampling starts. Follower again: idle, the next command starts from `applied`.
// Taking the role the device has changes nothing.
static void set_role(uint8_t r) {
  if (r == role) return;
  role = r;
  if (r == ROLE_LEADER) {
    output_pulses(false);
    state = STATE_LEADER;
    leader_adc_begin();
  } else {
    leader_adc_end();
    state = STATE_IDLE;
  }
}

static void handle(const Frame *f) {
  last_seq = f->seq;
  last_rx_ms = millis();
  switch (f->type) {
    case MSG_HELLO: {
      set_role(ROLE_FOLLOWER);  // a new session starts as a follower
      uint8_t p[6] = {PROTOCOL_VERSION, FIRMWARE_MAJOR, FIRMWARE_MINOR, SERVO_COUNT, 0, 0};
      put_u16(p + 4, watchdog_ms);
      send(MSG_HELLO_ACK, p, sizeof(p));
      return;
    }
    case MSG_SET_PULSES:
      if (state != STATE_ESTOP && role == ROLE_FOLLOWER) {  // a leader drives nothing
        clamped = 0;
        for (uint8_t i = 0; i < SERVO_COUNT; i++) {
          uint16_t t = get_u16(f->payload + 2 * i);
          if (t != 0) {
            if (t < SERVO_MIN_TICKS[i]) { t = SERVO_MIN_TICKS[i]; clamped = 1; }
            if (t > SERVO_MAX_TICKS[i]) { t = SERVO_MAX_TICKS[i]; clamped = 1; }
          }
          applied[i] = t;
        }
        state = STATE_RUNNING;
        output_pulses(true);
      }
      break;
    case MSG_HEARTBEAT:
      break;
    case MSG_ESTOP:
      if (role == ROLE_LEADER) break;  // no pulses to hold or stop
      if (f->payload[0] == 1 || f->payload[0] == 2) {
        state = STATE_ESTOP;  // ignore commands; 1: hold the pulses, 2: stop them
        if (f->payload[0] == 2) {
          output_pulses(false);
        } else if (output) {
          // hold what the pins show: a command not on them yet is dropped, so the servos
          // get no new position from here on (not the next frame's)
          servo_pwm_hold();
          for (uint8_t i = 0; i < SERVO_COUNT; i++) {
            if (servo_pwm_get(i)) applied[i] = servo_pwm_get(i);
          }
        }
      } else if (f->payload[0] == 0 && state == STATE_ESTOP) {
        // held pulses go on; stopped ones wait for a new command
        state = output ? STATE_RUNNING : STATE_IDLE;
      }
      break;
    case MSG_CONFIG: {
      uint16_t ms = get_u16(f->payload);
      watchdog_ms = ms < WATCHDOG_MS_MIN ? WATCHDOG_MS_MIN : ms;
      watchdog_detach = f->payload[2] == 1;
      break;
    }
    case MSG_ROLE:
      if (f->payload[0] <= ROLE_LEADER) set_role(f->payload[0]);
      break;
    default:  // device-to-host types sent to the device
      decoder.errors++;
      return;
  }
  send_state();
}

void setup() {
  Serial.begin(SERIAL_BAUD);
  proto_decoder_init(&decoder);
  for (uint8_t i = 0; i < SERVO_COUNT; i++) applied[i] = HOLD_TICKS[i];
  servo_pwm_begin();  // no pulses until the first command
  last_rx_ms = millis();
}

void loop() {
  while (Serial.available() > 0) {
    Frame f;
    last_byte_ms = millis();
    proto_decoder_push(&decoder, (uint8_t)Serial.read());
    // every frame this byte completes: after a false start byte there can be several
    while (proto_decoder_pop(&decoder, &f)) handle(&f);
  }
  if (decoder.n > 0 && (unsigned long)(millis() - last_byte_ms) > FRAME_GAP_MS) {
    decoder.n = 0;  // a partial frame only (the rest of it is not coming)
    decoder.errors++;
  }
  if (state == STATE_RUNNING && (unsigned long)(millis() - last_rx_ms) > watchdog_ms) {
    if (watchdog_detach) {
      state = STATE_WATCHDOG_DETACHED;
      output_pulses(false);
    } else {
      state = STATE_WATCHDOG_HOLD;
    }
    send_state();
  }
  if (role == ROLE_LEADER) {
    LeaderWindow w;
    if (leader_adc_take(&w)) send_leader_state(&w);
  }
}
