//! The servo pins as a servo sees them: pulse widths from pin edges, for the twin driven
//! by the firmware in simavr (`servo_sim`'s event file: every edge on pins 8–11 with its
//! simulated cycle), in lock-step with the board's clock.
//!
//! A servo steers to the width of the last pulse it got. An analog servo such as the
//! MG995 stops driving its motor when the pulses stop; so does the twin's after
//! [`PULSE_TIMEOUT_S`] without one.

/// The AVR's clock (Hz): an Uno's 16 MHz.
pub const CPU_HZ: f64 = 16_000_000.0;

/// A servo that got no pulse for this long goes limp (three of the firmware's 20 ms
/// frames: an analog servo's one-shot lasts about one frame, so this is generous).
pub const PULSE_TIMEOUT_S: f64 = 0.06;

/// A high level longer than this is not a servo pulse (a pin held high), and is ignored.
pub const MAX_PULSE_US: f64 = 3000.0;

/// One line of `servo_sim`'s event file that the twin uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoardEvent {
    /// `e CYCLE PIN LEVEL`: a servo pin (0–3: pins 8–11) changed level.
    Edge {
        /// Simulated cycle.
        cycle: u64,
        /// 0–3.
        pin: usize,
        /// The new level.
        high: bool,
    },
    /// `c CYCLE`: the board has run up to here (every simulated millisecond).
    Clock {
        /// Simulated cycle.
        cycle: u64,
    },
    /// `w CYCLE NS`: the harness read host bytes at this wall time (CLOCK_REALTIME ns):
    /// ties the simulated clock to the wall's.
    Wall {
        /// Simulated cycle.
        cycle: u64,
        /// Nanoseconds since the Unix epoch.
        ns: i64,
    },
}

impl BoardEvent {
    /// The event of a line, or `None` for the lines the twin does not use (UART bytes,
    /// ADC conversions, cable events) and for a line it cannot read (a partial last line
    /// is the caller's to complete first).
    pub fn parse(line: &str) -> Option<BoardEvent> {
        let mut f = line.split_ascii_whitespace();
        let kind = f.next()?;
        let cycle = f.next()?.parse().ok()?;
        match kind {
            "e" => {
                let pin: usize = f.next()?.parse().ok()?;
                let level: u8 = f.next()?.parse().ok()?;
                (pin < 4 && level <= 1).then_some(BoardEvent::Edge {
                    cycle,
                    pin,
                    high: level == 1,
                })
            }
            "c" => Some(BoardEvent::Clock { cycle }),
            "w" => Some(BoardEvent::Wall {
                cycle,
                ns: f.next()?.parse().ok()?,
            }),
            _ => None,
        }
    }

    /// Its simulated time (s since power-up).
    pub fn time_s(&self) -> f64 {
        let cycle = match self {
            BoardEvent::Edge { cycle, .. }
            | BoardEvent::Clock { cycle }
            | BoardEvent::Wall { cycle, .. } => *cycle,
        };
        cycle as f64 / CPU_HZ
    }
}

/// The four servo pins' pulses.
#[derive(Clone, Debug, Default)]
pub struct PulseDecoder {
    /// per pin: when it went high (s), if it is high
    rise: [Option<f64>; 4],
    /// per pin: the last complete pulse (width µs, its end s)
    last: [Option<(f64, f64)>; 4],
}

impl PulseDecoder {
    /// Takes a pin edge at `t` s.
    pub fn edge(&mut self, pin: usize, high: bool, t: f64) {
        if pin >= 4 {
            return;
        }
        if high {
            self.rise[pin] = Some(t);
        } else if let Some(r) = self.rise[pin].take() {
            let width_us = (t - r) * 1e6;
            if width_us > 0.0 && width_us <= MAX_PULSE_US {
                self.last[pin] = Some((width_us, t));
            }
        }
    }

    /// The width (µs) each servo steers to at `t` s: its last pulse's, or 0 (no pulse:
    /// limp) when it got none within [`PULSE_TIMEOUT_S`].
    pub fn widths_us(&self, t: f64) -> [f64; 4] {
        self.last.map(|p| match p {
            Some((w, end)) if t - end <= PULSE_TIMEOUT_S => w,
            _ => 0.0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_parse_and_others_are_skipped() {
        assert_eq!(
            BoardEvent::parse("e 16000 2 1"),
            Some(BoardEvent::Edge {
                cycle: 16000,
                pin: 2,
                high: true
            })
        );
        assert_eq!(
            BoardEvent::parse("c 32000"),
            Some(BoardEvent::Clock { cycle: 32000 })
        );
        assert_eq!(
            BoardEvent::parse("w 48000 1700000000000000000"),
            Some(BoardEvent::Wall {
                cycle: 48000,
                ns: 1_700_000_000_000_000_000
            })
        );
        assert_eq!(BoardEvent::parse("r 100 255"), None);
        assert_eq!(BoardEvent::parse("e 16000 7 1"), None);
        assert_eq!(BoardEvent::parse("e 160"), None);
        assert_eq!(BoardEvent::parse(""), None);
        assert_eq!(
            BoardEvent::parse("c 16000").map(|e| e.time_s()),
            Some(0.001)
        );
    }

    #[test]
    fn a_pulse_is_its_high_time_and_lasts_until_the_timeout() {
        let mut d = PulseDecoder::default();
        assert_eq!(d.widths_us(0.0), [0.0; 4]);
        d.edge(1, true, 0.010);
        d.edge(1, false, 0.010 + 1472e-6);
        let w = d.widths_us(0.02);
        assert!((w[1] - 1472.0).abs() < 1e-6 && w[0] == 0.0, "{w:?}");
        // held while pulses come, gone after the timeout
        let end = 0.010 + 1472e-6;
        assert!(d.widths_us(end + PULSE_TIMEOUT_S - 1e-6)[1] > 0.0);
        assert_eq!(d.widths_us(end + PULSE_TIMEOUT_S + 1e-6)[1], 0.0);
    }

    #[test]
    fn a_fall_without_a_rise_and_a_pin_held_high_are_not_pulses() {
        let mut d = PulseDecoder::default();
        d.edge(0, false, 0.001);
        d.edge(2, true, 0.0);
        d.edge(2, false, 0.5);
        d.edge(9, true, 0.0);
        assert_eq!(d.widths_us(0.5), [0.0; 4]);
    }
}
