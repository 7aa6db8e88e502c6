#include "leader_adc.h"
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#define SAMPLES_PER_WINDOW (LEADER_CHANNELS * LEADER_OVERSAMPLING)
#define SAMPLE_US (LEADER_PERIOD_US / SAMPLES_PER_WINDOW)
// Timer2 at 16 MHz / 32: 2 us a tick; compare match A every SAMPLE_US in CTC mode
#define T2_TICK_US 2
#define T2_TOP (SAMPLE_US / T2_TICK_US - 1)
// ADC clock 16 MHz / 128 = 125 kHz (the datasheet's 50-200 kHz for 10 bits): 104 us a
// conversion, 108 us at most from the start request to the result
#define ADC_PRESCALER (_BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0))
#define CONVERSION_MAX_US 108

static_assert(F_CPU == 16000000L, "Timer2's and the ADC's dividers assume 16 MHz");
static_assert((LEADER_CHANNELS & (LEADER_CHANNELS - 1)) == 0, "channels: a power of two");
static_assert(SAMPLES_PER_WINDOW <= 255, "the sample counter is a byte");
static_assert(SAMPLE_US * SAMPLES_PER_WINDOW == LEADER_PERIOD_US, "a window is whole samples");
static_assert(SAMPLE_US % T2_TICK_US == 0 && T2_TOP <= 255, "a sample is whole Timer2 ticks");
static_assert(SAMPLE_US > CONVERSION_MAX_US, "a conversion is done by the next sample");
static_assert(LEADER_OVERSAMPLING * 1023UL <= 0xFFFF, "a channel's sum fits 16 bits");

static volatile uint16_t acc[LEADER_CHANNELS];
static volatile uint8_t taken;  // samples taken in this window
static volatile uint8_t held;   // of them, with D2 low
static volatile uint8_t overruns;
static volatile uint8_t window;
static volatile uint16_t ready_sum[LEADER_CHANNELS];
static volatile uint8_t ready_deadman, ready_window, ready_overruns, ready;
// Timer2 as the Arduino core set it up (analogWrite on pins 3 and 11), restored by _end()
static uint8_t saved_tccr2a, saved_tccr2b, saved_ocr2a, saved_timsk2;
static uint8_t running;

static inline uint8_t admux(uint8_t channel) {
  return _BV(REFS0) | channel;  // reference AVcc, the potentiometers' own 5 V
}

ISR(TIMER2_COMPA_vect) {
  if (ADCSRA & _BV(ADSC)) {
    // started late (a long interrupt delayed the one before): wait for it, count it
    overruns++;
    while (ADCSRA & _BV(ADSC)) {
    }
  }
  const uint16_t v = ADC;  // read before ADMUX changes: the conversion's own channel
  uint8_t n = taken;
  const uint8_t channel = n & (LEADER_CHANNELS - 1);
  ADMUX = admux((n + 1) & (LEADER_CHANNELS - 1));
  ADCSRA |= _BV(ADSC);  // the next sample's conversion
  acc[channel] += v;
  if (!(PIND & _BV(PIND2))) held++;
  if (++n == SAMPLES_PER_WINDOW) {
    for (uint8_t c = 0; c < LEADER_CHANNELS; c++) {
      ready_sum[c] = acc[c];
      acc[c] = 0;
    }
    ready_deadman = held == SAMPLES_PER_WINDOW;
    ready_window = window++;
    ready_overruns = overruns;
    ready = 1;
    held = 0;
    n = 0;
  }
  taken = n;
}

void leader_adc_begin() {
  if (running) return;
  running = 1;
  DDRD &= ~_BV(DDD2);  // D2: input with its pull-up
  PORTD |= _BV(PORTD2);
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    saved_tccr2a = TCCR2A;
    saved_tccr2b = TCCR2B;
    saved_ocr2a = OCR2A;
    saved_timsk2 = TIMSK2;
    TIMSK2 = 0;
    TCCR2B = 0;
    for (uint8_t c = 0; c < LEADER_CHANNELS; c++) acc[c] = 0;
    taken = held = overruns = window = ready = 0;
  }
  // The ADC's first conversion after it is enabled takes 25 clocks (200 us): one
  // thrown away here (in the loop, once, at the ROLE), then conversion 0 (A0) for the
  // first interrupt to read.
  ADMUX = admux(0);
  ADCSRA = _BV(ADEN) | ADC_PRESCALER | _BV(ADSC);
  while (ADCSRA & _BV(ADSC)) {
  }
  ADCSRA |= _BV(ADSC);
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR2A = _BV(WGM21);  // CTC: TCNT2 0..OCR2A
    TCNT2 = 0;
    OCR2A = T2_TOP;
    TIFR2 = _BV(OCF2A) | _BV(OCF2B) | _BV(TOV2);
    TIMSK2 = _BV(OCIE2A);
    TCCR2B = _BV(CS21) | _BV(CS20);  // clk/32
  }
}

void leader_adc_end() {
  if (!running) return;
  running = 0;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TIMSK2 = 0;
    TCCR2B = 0;
    TCCR2A = saved_tccr2a;
    OCR2A = saved_ocr2a;
    TCNT2 = 0;
    TIFR2 = _BV(OCF2A) | _BV(OCF2B) | _BV(TOV2);
    TCCR2B = saved_tccr2b;
    TIMSK2 = saved_timsk2;
    ready = 0;
  }
}

uint8_t leader_adc_take(LeaderWindow *out) {
  uint8_t got = 0;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    if (ready) {
      for (uint8_t c = 0; c < LEADER_CHANNELS; c++) out->sum[c] = ready_sum[c];
      out->deadman = ready_deadman;
      out->window = ready_window;
      out->overruns = ready_overruns;
      ready = 0;
      got = 1;
    }
  }
  return got;
}
