#include "servo_pwm.h"
#include "config.h"
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

// Gap scheduled for a channel without pulses, so the sequence keeps moving.
#define IDLE_SLOT_TICKS 200
// The compare match comes this early (20 us); the ISR then waits for the edge's tick
// itself. Another interrupt running when the match is due (the UART's, ~5-10 us) delays
// the ISR's entry, but not the edge.
#define EDGE_LEAD_TICKS 40
// Channel 0's width is read this long (100 us) before its pulse begins, so a command
// that arrives in the rest of the 20 ms frame still makes it into the next one.
#define LATCH_LEAD_TICKS 200

static const uint8_t MASK[SERVO_COUNT] = {_BV(0), _BV(1), _BV(2), _BV(3)};
static volatile uint16_t width[SERVO_COUNT];
// Slots: 0..3 a channel's pulse, SERVO_COUNT the rest of the 20 ms frame, SERVO_COUNT + 1
// the last 100 us before the next frame (channel 0's width is read at its start).
// `slot` is the one the next edge begins; what to drive on PB0..PB3 then, and for how
// long, are latched one slot ahead, so the ISR has nothing to compute between waiting
// for the edge and writing the pins: the fall of one pulse and the rise of the next
// happen in the same write, on the edge's timer tick.
static uint8_t slot;
static uint8_t next_out;
static uint16_t next_width;
static uint16_t frame_start;
static uint16_t edge;  // the tick of the next edge; the compare match is EDGE_LEAD_TICKS earlier

void servo_pwm_begin() {
  DDRB |= 0x0F;     // PB0..PB3 = pins 8..11 as outputs
  PORTB &= ~0x0F;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1A = 0;             // normal mode: TCNT1 runs 0..65535 freely
    TCCR1B = _BV(CS11);     // prescaler 8: 0.5 us a tick
    slot = 0;               // the first edge begins a frame (without pulses yet)
    next_out = 0;
    next_width = 0;
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
  while ((int16_t)(TCNT1 - due) < 0) {
  }
  PORTB = (PORTB & 0xF0) | next_out;  // end the previous pulse, start this slot's
  uint8_t s;
  if (slot < SERVO_COUNT) {
    edge = due + (next_width ? next_width : IDLE_SLOT_TICKS);
    s = slot + 1;
  } else if (slot == SERVO_COUNT) {
    frame_start += REFRESH_TICKS;     // each frame starts 20 ms after the previous one
    edge = frame_start - LATCH_LEAD_TICKS;
    s = SERVO_COUNT + 1;
  } else {
    edge = frame_start;
    s = 0;
  }
  OCR1A = edge - EDGE_LEAD_TICKS;
  // latch what the next edge begins
  if (s < SERVO_COUNT) {
    next_width = width[s];
    next_out = next_width ? MASK[s] : 0;
  } else {
    next_width = 0;
    next_out = 0;
  }
  slot = s;
}
