#include "servo_pwm.h"
#include "config.h"
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

// Gap scheduled for a channel without pulses, so the sequence keeps moving.
#define IDLE_SLOT_TICKS 200

static const uint8_t MASK[SERVO_COUNT] = {_BV(0), _BV(1), _BV(2), _BV(3)};
static volatile uint16_t width[SERVO_COUNT];
// The slot the next compare match begins: 0..3 a channel's pulse, SERVO_COUNT the rest of
// the 20 ms frame. What to drive on PB0..PB3 then, and for how long, are latched one slot
// ahead so that the ISR's first instruction sets the pins: the fall of one pulse and the
// rise of the next happen in the same write, a fixed number of cycles after the match,
// and every width is exact whatever the interrupt latency.
static uint8_t slot;
static uint8_t next_out;
static uint16_t next_width;
static uint16_t frame_start;

void servo_pwm_begin() {
  DDRB |= 0x0F;     // PB0..PB3 = pins 8..11 as outputs
  PORTB &= ~0x0F;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1A = 0;             // normal mode: TCNT1 runs 0..65535 freely
    TCCR1B = _BV(CS11);     // prescaler 8: 0.5 us a tick
    slot = 0;               // the first match begins a frame (without pulses yet)
    next_out = 0;
    next_width = 0;
    frame_start = TCNT1 + 100;
    OCR1A = frame_start;
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
  PORTB = (PORTB & 0xF0) | next_out;  // end the previous pulse, start this slot's
  uint16_t fired = OCR1A;             // when this match was due
  uint8_t s;
  if (slot < SERVO_COUNT) {
    OCR1A = fired + (next_width ? next_width : IDLE_SLOT_TICKS);
    s = slot + 1;
  } else {
    frame_start += REFRESH_TICKS;     // each frame starts 20 ms after the previous one
    OCR1A = frame_start;
    s = 0;
  }
  // latch what the next match begins
  if (s < SERVO_COUNT) {
    next_width = width[s];
    next_out = next_width ? MASK[s] : 0;
  } else {
    next_width = 0;
    next_out = 0;
  }
  slot = s;
}
