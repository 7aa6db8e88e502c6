// Servo pulses on Timer1, as the Arduino Servo library makes them: one pulse after
// the other on pins 8, 9, 10, 11 (PB0..PB3), widths in 0.5 us ticks. Every edge falls
// on its scheduled timer tick (the interrupt comes 20 us early and waits for it), so
// widths do not vary with interrupt latency. Each channel's width is read when the
// interrupt for the edge that starts its pulse comes in, 20 us before the edge or a
// little later (if another interrupt delays it).
//
// Frames (config.h): with nothing new to show, a frame starts REFRESH_TICKS (20 ms)
// after the previous one, as the Servo library's. A new width starts the next frame
// early, as soon as the previous frame's pulses are over and it began SYNC_MIN_TICKS
// (14 ms) or more before; a frame started so waits up to SYNC_MAX_TICKS (22.5 ms) for
// the next new width. So a stream of commands at 45-70 Hz starts each frame itself,
// 20 us after it is stored, instead of waiting up to a whole frame; the period stays
// within 14-22.5 ms, the frame periods of RC receivers for analog servos. FRAME_SYNC 0
// in config.h keeps the fixed 20 ms frame.
#pragma once
#include <stdint.h>

void servo_pwm_begin();
// Set the width of channel `i` in ticks; 0 stops its pulses. It is in the channel's
// next pulse that starts 20 us or more after the call, in this frame if that is still
// to come. Call servo_pwm_sync() after setting a command's widths.
void servo_pwm_set(uint8_t i, uint16_t ticks);
// Widths set since the current frame began start the next frame as early as the frame
// timing allows (see above); nothing changes if none did.
void servo_pwm_sync();
uint16_t servo_pwm_get(uint8_t i);
// Each channel keeps the width its pulses show now: a width set since the channel's last
// pulse began, and not in it, is dropped, so no pulse after the call shows a width the
// servo was not already being shown (the e-stop's hold). A channel without pulses yet
// keeps what was set.
void servo_pwm_hold();
