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

static const uint8_t MASK[SERVO_COUNT] = {_BV(0), _BV(1), _BV(2), _BV(3)};
static volatile uint16_t width[SERVO_COUNT];
// Slots: 0..3 a channel's pulse, SERVO_COUNT the rest of the 20 ms frame. `slot` is the
// one the next edge begins. Its width is read when the ISR for that edge is entered
// (EDGE_LEAD_TICKS before the edge, or later if another interrupt delays the entry), and
// everything that depends on it is worked out before the ISR waits for the edge's tick:
// the fall of one pulse and the rise of the next happen in the same write, on the tick,
// and only the scheduling of the following edge comes after it.
static uint8_t slot;
static uint16_t frame_start;
static uint16_t edge;  // the tick of the next edge; the compare match is EDGE_LEAD_TICKS earlier

void servo_pwm_begin() {
  DDRB |= 0x0F;     // PB0..PB3 = pins 8..11 as outputs
  PORTB &= ~0x0F;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1A = 0;             // normal mode: TCNT1 runs 0..65535 freely
    TCCR1B = _BV(CS11);     // prescaler 8: 0.5 us a tick
    slot = 0;               // the first edge begins a frame (without pulses yet)
    frame_start = TCNT1 + 200;
    edge = frame_start;
    OCR1A = edge - EDGE_LEAD_TICKS;
    TIFR1 = _BV(OCF1A);
    TIMSK1 |= _BV(OCIE1A);
  }
}

void servo_pwm_set(uint8_t i, uint16_t ticks) {
  if (i >= SERVO_COUNT) return;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { width[i] = ticks; }
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
    if (w) out = MASK[s];
  }
  // `out` in a register before the wait: the compiler may not sink its computation past
  // the loop, where the time from the tick to the write would depend on the width
  asm volatile("" : "+r"(out));
  while ((int16_t)(TCNT1 - due) < 0) {
  }
  PORTB = (PORTB & 0xF0) | out;  // end the previous pulse, start this slot's
  if (s < SERVO_COUNT) {
    edge = due + (w ? w : IDLE_SLOT_TICKS);
    slot = s + 1;
  } else {
    frame_start += REFRESH_TICKS;  // each frame starts 20 ms after the previous one
    edge = frame_start;
    slot = 0;
  }
  OCR1A = edge - EDGE_LEAD_TICKS;
}
