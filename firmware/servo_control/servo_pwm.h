// Servo pulses on Timer1, as the Arduino Servo library makes them: one pulse after
// the other on pins 8, 9, 10, 11 (PB0..PB3), each servo refreshed every 20 ms,
// widths in 0.5 us ticks. Every edge falls on its scheduled timer tick (the interrupt
// comes 20 us early and waits for it), so widths do not vary with interrupt latency;
// channel 0's width is read 100 us before its pulse, the others' at the previous edge.
#pragma once
#include <stdint.h>

void servo_pwm_begin();
// Set the width of channel `i` in ticks; 0 stops its pulses.
void servo_pwm_set(uint8_t i, uint16_t ticks);
uint16_t servo_pwm_get(uint8_t i);
