#include "servo_pwm.h"
#include "config.h"
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

// Gap scheduled for a channel without pulses, so the sequence keeps moving.
#define IDLE_SLOT_TICKS 200
// The compare match comes this early (20 us); the ISR reads the width of the pulse the
// edge begins, then waits for the edge's tick itself. Another interrupt running when the
// match is due (the UART's, ~5-10 us) delays the ISR's entry, and so the read, but not
// the edge.
#define EDGE_LEAD_TICKS 40
// A frame started early by servo_pwm_sync() begins this long after the call (40 us): the
// compare match, EDGE_LEAD_TICKS before it, is still ahead when it is armed.
#define SYNC_LEAD_TICKS 80
// The shortest gap between the last pulse of a frame and the next frame.
#define MIN_GAP_TICKS 200

static const uint8_t MASK[SERVO_COUNT] = {_BV(0), _BV(1), _BV(2), _BV(3)};
static volatile uint16_t width[SERVO_COUNT];
// The width of each channel's last pulse (0: none, or none since its pulses stopped).
static volatile uint16_t shown[SERVO_COUNT];
// Channels whose width changed since their pulse of the current frame read it: they
// have something new to show.
static volatile uint8_t fresh;
// Slots: 0..3 a channel's pulse, SERVO_COUNT the rest of the frame. `slot` is the one
// the next edge begins. Its width is read when the ISR for that edge is entered
// (EDGE_LEAD_TICKS before the edge, or later if another interrupt delays the entry), and
// everything that depends on it is worked out before the ISR waits for the edge's tick:
// the fall of one pulse and the rise of the next happen in the same write, on the tick,
// and only the scheduling of the following edge comes after it.
static volatile uint8_t slot;
static volatile uint16_t frame_start;  // the tick the current (or last) frame began
static volatile uint16_t edge;  // the tick of the next edge; the compare match is EDGE_LEAD_TICKS earlier
// The next frame / the current one was started early for a new width: the frame after
// it may wait SYNC_MAX_TICKS for the next one.
static volatile uint8_t next_synced, synced;

void servo_pwm_begin() {
  DDRB |= 0x0F;     // PB0..PB3 = pins 8..11 as outputs
  PORTB &= ~0x0F;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1A = 0;             // normal mode: TCNT1 runs 0..65535 freely
    TCCR1B = _BV(CS11);     // prescaler 8: 0.5 us a tick
    slot = 0;               // the first edge begins a frame (without pulses yet)
    edge = TCNT1 + 200;
    frame_start = edge - REFRESH_TICKS;  // as if a frame had begun a period before
    OCR1A = edge - EDGE_LEAD_TICKS;
    TIFR1 = _BV(OCF1A);
    TIMSK1 |= _BV(OCIE1A);
  }
}

void servo_pwm_set(uint8_t i, uint16_t ticks) {
  if (i >= SERVO_COUNT) return;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    if (width[i] != ticks) {
      width[i] = ticks;
      fresh |= MASK[i];
    }
  }
}

void servo_pwm_sync() {
#if FRAME_SYNC
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    // During the pulses the end of the last one schedules the next frame (the ISR);
    // in the gap after them, start it now, or once the frame is SYNC_MIN_TICKS old.
    if (slot != 0 || !fresh) return;
    const uint16_t start = frame_start;
    const uint16_t now = TCNT1;
    uint16_t at = start + SYNC_MIN_TICKS;
    if ((uint16_t)(now - start) > SYNC_MIN_TICKS - SYNC_LEAD_TICKS) at = now + SYNC_LEAD_TICKS;
    // only ever earlier: once the compare match for the frame's start has come
    // (EDGE_LEAD_TICKS before it), `at` is later than `edge` and nothing changes
    if ((uint16_t)(at - start) < (uint16_t)(edge - start)) {
      edge = at;
      OCR1A = at - EDGE_LEAD_TICKS;
      next_synced = 1;
    }
  }
#endif
}

void servo_pwm_hold() {
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    for (uint8_t i = 0; i < SERVO_COUNT; i++) {
      if (shown[i] == 0) continue;
      width[i] = shown[i];
      fresh &= ~MASK[i];
    }
  }
}

uint16_t servo_pwm_get(uint8_t i) {
  uint16_t w;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { w = width[i]; }
  return w;
}

ISR(TIMER1_COMPA_vect) {
  const uint16_t due = edge;
  const uint8_t s = slot;
  // What this edge begins, read now: a width set until this moment is in this pulse.
  uint16_t w = 0;
  uint8_t out = 0;
  if (s < SERVO_COUNT) {
    w = width[s];
    fresh &= ~MASK[s];
    if (w) out = MASK[s];
  }
  // `out` in a register before the wait: the compiler may not sink its computation past
  // the loop, where the time from the tick to the write would depend on the width
  asm volatile("" : "+r"(out));
  while ((int16_t)(TCNT1 - due) < 0) {
  }
  PORTB = (PORTB & 0xF0) | out;  // end the previous pulse, start this slot's
  if (s < SERVO_COUNT) {
    shown[s] = w;
    if (s == 0) {
      frame_start = due;
      synced = next_synced;
      next_synced = 0;
    }
    edge = due + (w ? w : IDLE_SLOT_TICKS);
    slot = s + 1;
  } else {
    // The pulses are over. A channel with a width it has not shown yet (set while the
    // frame's pulses went out) pulls the next frame in; one started so waits longer for
    // the next command; otherwise the Servo library's 20 ms.
    uint16_t period = REFRESH_TICKS;
#if FRAME_SYNC
    if (fresh) {
      period = SYNC_MIN_TICKS;
      next_synced = 1;
    } else if (synced) {
      period = SYNC_MAX_TICKS;
    }
#endif
    edge = frame_start + period;
    if ((uint16_t)(edge - frame_start) < (uint16_t)(due - frame_start) + MIN_GAP_TICKS) edge = due + MIN_GAP_TICKS;
    slot = 0;
  }
  OCR1A = edge - EDGE_LEAD_TICKS;
}
