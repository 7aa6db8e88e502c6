// The leader role's inputs (PROTOCOL.md, version 3): the wipers of four potentiometers on
// A0..A3 (10 kOhm, between 5 V and GND) and a deadman button on D2 (to GND; the pin's
// pull-up holds it high, so pressed = LOW).
//
// Timer2 interrupts every 150 us (CTC, 2 us ticks). Each interrupt reads the conversion
// the interrupt before started, reads D2, then starts the next conversion on the next
// channel (A0 A1 A2 A3 A0 ...): 64 samples, 16 a channel, make a window of
// LEADER_PERIOD_US = 9.6 ms (104.2 windows a second). A channel's value is the sum of its
// 16 samples (0..16368; 16384 stands for the reference, AVcc); the deadman bit is set
// when D2 was low at all 64 samples, so a release or a bounce anywhere in the window
// reads as released.
//
// A conversion takes 13 ADC clocks of 8 us (16 MHz / 128), 104 us (108 us at most from
// the start request), within the 150 us before the next interrupt reads it; one whose
// interrupt came early enough to find it unfinished (the conversion was started late by
// a long interrupt before it) is waited for and counted in `overruns`. The sampling runs
// only in the leader role: a follower's Timer2 and ADC stay as the Arduino core leaves
// them, and nothing of it runs near the servo pulses.
#pragma once
#include <stdint.h>
#include "protocol.h"

struct LeaderWindow {
  uint16_t sum[LEADER_CHANNELS];  // LEADER_OVERSAMPLING 10-bit samples each
  uint8_t deadman;                // 1: D2 low at every sample of the window
  uint8_t window;                 // the window's number since leader_adc_begin(), wrapping
  uint8_t overruns;               // samples that waited for their conversion, wrapping
};

// Start sampling (D2 gets its pull-up); the first window ends LEADER_PERIOD_US later.
void leader_adc_begin();
// Stop sampling; Timer2 back as it was. A window not taken is dropped.
void leader_adc_end();
// 1: `out` holds the window finished since the last call (if two finished, the newer:
// the gap in `window` says so); 0: none.
uint8_t leader_adc_take(LeaderWindow *out);
