// Servo pulses on Timer1, as the Arduino Servo library makes them: one pulse after
// the other on pins 8, 9, 10, 11 (PB0..PB3), each servo refreshed every 20 ms,
// widths in 0.5 us ticks. Every edge falls on its scheduled timer tick (the interrupt
// comes 20 us early and waits for it), so widths do not vary with interrupt latency.
// Each channel's width is read when the interrupt for the edge that starts its pulse
// comes in, 20 us before the edge or a little later (if another interrupt delays it).
#pragma once
#include <stdint.h>

void servo_pwm_begin();
// Set the width of channel `i` in ticks; 0 stops its pulses. It is in the channel's
// next pulse that starts 20 us or more after the call, in this frame if that is still to come.
void servo_pwm_set(uint8_t i, uint16_t ticks);
uint16_t servo_pwm_get(uint8_t i);
