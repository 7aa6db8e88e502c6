// Servo pulses on Timer1, as the Arduino Servo library makes them: one pulse after
// the other on pins 8, 9, 10, 11 (PB0..PB3), each servo refreshed every 20 ms,
// widths in 0.5 us ticks. Edges are scheduled from the compare times, not from
// when the interrupt ran, so widths do not drift with interrupt latency.
#pragma once
#include <stdint.h>

void servo_pwm_begin();
// Set the width of channel `i` in ticks; 0 stops its pulses.
void servo_pwm_set(uint8_t i, uint16_t ticks);
uint16_t servo_pwm_get(uint8_t i);
