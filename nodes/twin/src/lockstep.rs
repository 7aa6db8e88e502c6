//! The twin driven by the firmware in simavr, by its pin pulses, in lock-step with the
//! board's simulated clock: the highest-fidelity chain (serial_node → the real firmware's
//! UART → its PWM edges → the servos' physics).
//!
//! `servo_sim` writes every edge of pins 8–11 with its simulated cycle to its event file,
//! and a clock line every simulated millisecond ([`BoardEvent`]). The twin reads the file
//! in order and advances its physics to each event's time before it takes it, so the
//! twin's time is the board's: a loaded host slows both alike, and a recorded file
//! replays as fast as the physics runs, with the same result.

use twin_model::pulses::{BoardEvent, PulseDecoder};

use crate::sim::{Sim, SimError};

/// The twin's side of the lock-step: the pins' pulses and the tie to the wall clock.
#[derive(Debug, Default)]
pub struct Lockstep {
    pulses: PulseDecoder,
    /// the wall clock (ns since the epoch) at the board's power-up, once a `w` line said
    epoch_ns: Option<i64>,
}

impl Lockstep {
    /// Starts at the board's power-up: the twin's simulated time 0.
    pub fn new() -> Lockstep {
        Lockstep::default()
    }

    /// Advances `sim` to `event`'s time, a step at a time with the pulses as they are,
    /// then takes the event.
    pub fn apply(&mut self, sim: &mut Sim, event: BoardEvent) -> Result<(), SimError> {
        let t = event.time_s();
        let dt = sim.timestep();
        while sim.time() + dt / 2.0 <= t {
            sim.set_pulses_us(self.pulses.widths_us(sim.time()));
            sim.step()?;
        }
        match event {
            BoardEvent::Edge { pin, high, .. } => self.pulses.edge(pin, high, t),
            BoardEvent::Wall { ns, .. } => {
                self.epoch_ns.get_or_insert(ns - (t * 1e9) as i64);
            }
            BoardEvent::Clock { .. } => {}
        }
        Ok(())
    }

    /// The wall clock (ns since the epoch) at the board's power-up, once known.
    pub fn epoch_ns(&self) -> Option<i64> {
        self.epoch_ns
    }

    /// The widths (µs) the servos steer to at `t`.
    pub fn widths_us(&self, t: f64) -> [f64; 4] {
        self.pulses.widths_us(t)
    }
}
