// Device configuration of the servo_control firmware. Edit for your build of the arm.
#pragma once
#include <stdint.h>

#define FIRMWARE_MAJOR 1
#define FIRMWARE_MINOR 1  // 1.1: the leader role (protocol version 3)
// PROTOCOL_VERSION and the frame constants: protocol.h (written from libs/servo_protocol)

#define SERVO_COUNT 4
#define SERIAL_BAUD 115200UL

// Pulse widths in Timer1 ticks of 0.5 us (16 MHz / 8). Every command is clamped into
// these, whatever the host sends: 544..2400 us is the Servo library's full range.
static const uint16_t SERVO_MIN_TICKS[SERVO_COUNT] = {1088, 1088, 1088, 1088};
static const uint16_t SERVO_MAX_TICKS[SERVO_COUNT] = {4800, 4800, 4800, 4800};

// The pose the arm is assumed to be in at power-up (no pulses go out until the first
// command), reported to the host so that its first command ramps from here: docs/robot.md's
// home pose (base 0 deg, main arm vertical, forearm horizontal: arm servos at 90 deg,
// 1472 us) with the claw closed (60 deg, 1163 us). Must lie within the limits above.
static const uint16_t HOLD_TICKS[SERVO_COUNT] = {2944, 2944, 2944, 2325};

// Refresh period of every servo while no command brings a new width, as the Servo
// library: 20 ms.
#define REFRESH_TICKS 40000U
// Frame sync (servo_pwm.h): a new width starts the next frame as soon as the frame
// before is SYNC_MIN_TICKS old (14 ms), and a frame started so waits up to
// SYNC_MAX_TICKS (22.5 ms) for the next new width: a 50 Hz command stream starts the
// frames itself. 14-22.5 ms are the frame periods RC receivers give analog servos
// (Futaba's 14 ms, the classic 22.5 ms PPM frame). 0: every frame 20 ms after the last.
#define FRAME_SYNC 1
#define SYNC_MIN_TICKS 28000U
#define SYNC_MAX_TICKS 45000U

// Silence after which the watchdog acts, and what it does (host can change both).
#define WATCHDOG_MS_DEFAULT 500
#define WATCHDOG_DETACH_DEFAULT 0   // 0: hold the last pulses, 1: stop the pulses
#define WATCHDOG_MS_MIN 20

// A partial frame older than this is dropped (a 12-byte frame takes ~1 ms at 115200),
// so bytes lost mid-frame never hold up the next frame.
#define FRAME_GAP_MS 5

// The leader role (PROTOCOL.md version 3; wiring in docs/protocol.md): potentiometer
// wipers on A0..A3, deadman button from D2 to GND. Its sampling (LEADER_PERIOD_US,
// LEADER_OVERSAMPLING) is a protocol constant, in protocol.h; leader_adc.cpp does it.
