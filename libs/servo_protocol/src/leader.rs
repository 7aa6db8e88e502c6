//! The leader role (protocol version 3): a second Uno with a leader arm (or three or four
//! potentiometers in a printed leader) reads A0–A3 and a deadman button on D2 and
//! streams them as [`Message::LeaderState`], one every sampling window
//! ([`crate::LEADER_PERIOD_US`], 9.6 ms: 104.2 Hz).
//!
//! [`LeaderState`] is that frame decoded for a host, with the conversions: a channel's
//! value is the sum of 16 10-bit samples, and [`LEADER_FULL_SCALE`] (16 × 1024) stands for
//! the ADC reference, AVcc, the same 5 V that feeds the potentiometers; so
//! [`LeaderState::fraction`] is where each wiper is between GND (0) and 5 V (1),
//! whatever the supply's exact voltage (the measurement is ratiometric).
//!
//! ```
//! use servo_protocol::leader::LeaderState;
//! use servo_protocol::{Frame, Message};
//! let f = Frame {
//!     seq: 7,
//!     msg: Message::LeaderState { adc: [0, 8192, 16368, 4096], deadman: true, window: 3, overruns: 0 },
//! };
//! let s = LeaderState::from_frame(&f).unwrap();
//! assert_eq!((s.seq, s.window, s.deadman), (7, 3, true));
//! assert_eq!(s.fraction(1), 0.5);
//! assert_eq!(s.millivolts(3, 5000.0), 1250.0);
//! ```

use crate::frame::{
    Frame, Message, LEADER_ADC_MAX, LEADER_CHANNELS, LEADER_FULL_SCALE, LEADER_OVERSAMPLING,
};

/// One LEADER_STATE, decoded: what a leader host acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LeaderState {
    /// A0–A3: each the sum of [`LEADER_OVERSAMPLING`] 10-bit samples over the window,
    /// 0 ..= [`LEADER_ADC_MAX`] ([`LEADER_FULL_SCALE`] = AVcc)
    pub adc: [u16; LEADER_CHANNELS],
    /// the deadman button was held at every sample of the window (a release, or a
    /// bounce, anywhere in it reads as released)
    pub deadman: bool,
    /// the window's number, wrapping (0: the first after the ROLE)
    pub window: u8,
    /// the device's count of late samples, wrapping (0 in normal operation)
    pub overruns: u8,
    /// the frame's sequence number (the device's transmit counter, shared with STATE)
    pub seq: u8,
}

impl LeaderState {
    /// The LEADER_STATE a frame carries; `None` for any other message.
    pub fn from_frame(frame: &Frame) -> Option<LeaderState> {
        match frame.msg {
            Message::LeaderState {
                adc,
                deadman,
                window,
                overruns,
            } => Some(LeaderState {
                adc,
                deadman,
                window,
                overruns,
                seq: frame.seq,
            }),
            _ => None,
        }
    }

    /// Channel `i`'s mean input as a fraction of AVcc, `adc / 16384`: 0 at GND,
    /// 1023/1024 at most (the ADC's top code). For a potentiometer between GND and 5 V,
    /// the wiper's position along the track.
    ///
    /// # Panics
    /// If `i` is not a channel (0..4).
    pub fn fraction(&self, i: usize) -> f64 {
        f64::from(self.adc[i]) / f64::from(LEADER_FULL_SCALE)
    }

    /// Every channel's [`LeaderState::fraction`].
    pub fn fractions(&self) -> [f64; LEADER_CHANNELS] {
        std::array::from_fn(|i| self.fraction(i))
    }

    /// Channel `i`'s mean input in millivolts, for an AVcc of `avcc_mv` (5000 on a Uno
    /// on USB; measure it for better).
    ///
    /// # Panics
    /// If `i` is not a channel (0..4).
    pub fn millivolts(&self, i: usize, avcc_mv: f64) -> f64 {
        self.fraction(i) * avcc_mv
    }

    /// Channel `i`'s mean 10-bit ADC code (0 ..= 1023, in sixteenths).
    ///
    /// # Panics
    /// If `i` is not a channel (0..4).
    pub fn mean_code(&self, i: usize) -> f64 {
        f64::from(self.adc[i]) / f64::from(LEADER_OVERSAMPLING)
    }

    /// Whether every channel is within what the ADC can report (a frame from a device
    /// that follows the protocol always is).
    pub fn in_range(&self) -> bool {
        self.adc.iter().all(|v| *v <= LEADER_ADC_MAX)
    }

    /// Windows lost between `previous` (the last one received) and this one: the gap in
    /// the window counter (0 when this is the next one). A gap of 256 or more windows
    /// (2.5 s) cannot be told from a shorter one.
    pub fn windows_lost_since(&self, previous: &LeaderState) -> u8 {
        self.window.wrapping_sub(previous.window).wrapping_sub(1)
    }
}

/// What a simulated leader's inputs are ([`crate::device::Device::set_leader_input`],
/// [`crate::device::VirtualArduino::set_leader_input`]): the wipers' voltages and the
/// deadman button.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LeaderInput {
    /// A0–A3, millivolts (0 ..= the ADC reference, 5000)
    pub millivolts: [f64; LEADER_CHANNELS],
    /// the deadman button held (D2 pulled to GND)
    pub deadman: bool,
}

impl LeaderInput {
    /// The ADC reference of a Uno on USB (AVcc), millivolts.
    pub const AVCC_MV: f64 = 5000.0;

    /// Inputs at these fractions of AVcc (each clamped into 0..=1).
    pub fn from_fractions(fractions: [f64; LEADER_CHANNELS], deadman: bool) -> LeaderInput {
        LeaderInput {
            millivolts: fractions.map(|f| f.clamp(0.0, 1.0) * Self::AVCC_MV),
            deadman,
        }
    }

    /// The 10-bit code the ADC gives for channel `i` (datasheet: `Vin × 1024 / Vref`,
    /// truncated, at most 1023).
    ///
    /// # Panics
    /// If `i` is not a channel (0..4).
    pub fn code(&self, i: usize) -> u16 {
        let v = self.millivolts[i].max(0.0) * 1024.0 / Self::AVCC_MV;
        (v.floor() as u16).min(1023)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{decode, encode};

    fn frame(adc: [u16; 4], deadman: bool, window: u8) -> Frame {
        Frame {
            seq: 42,
            msg: Message::LeaderState {
                adc,
                deadman,
                window,
                overruns: 0,
            },
        }
    }

    #[test]
    fn a_leader_state_decodes_from_the_wire_into_the_struct() {
        let bytes = encode(&frame([1, 2, 3, 16368], false, 255));
        let f = decode(&mut bytes.clone()).unwrap().unwrap();
        let s = LeaderState::from_frame(&f).unwrap();
        assert_eq!(
            s,
            LeaderState {
                adc: [1, 2, 3, 16368],
                deadman: false,
                window: 255,
                overruns: 0,
                seq: 42
            }
        );
        assert!(s.in_range());
        assert!(LeaderState::from_frame(&Frame {
            seq: 1,
            msg: Message::Heartbeat
        })
        .is_none());
    }

    #[test]
    fn conversions_are_exact() {
        let s = LeaderState::from_frame(&frame([0, 16384 / 4, 16368, 8200], true, 0)).unwrap();
        assert_eq!(s.fraction(0), 0.0);
        assert_eq!(s.fraction(1), 0.25);
        assert_eq!(s.fraction(2), 1023.0 / 1024.0);
        assert_eq!(s.millivolts(1, 5000.0), 1250.0);
        assert_eq!(s.mean_code(3), 512.5);
        assert_eq!(s.fractions()[1], 0.25);
        let bad = LeaderState {
            adc: [16369, 0, 0, 0],
            ..s
        };
        assert!(!bad.in_range());
    }

    #[test]
    fn lost_windows_are_counted_across_the_wrap() {
        let at = |w| LeaderState::from_frame(&frame([0; 4], true, w)).unwrap();
        assert_eq!(at(6).windows_lost_since(&at(5)), 0);
        assert_eq!(at(8).windows_lost_since(&at(5)), 2);
        assert_eq!(at(0).windows_lost_since(&at(255)), 0);
        assert_eq!(at(2).windows_lost_since(&at(254)), 3);
    }

    #[test]
    fn simulated_inputs_give_the_datasheet_codes() {
        let i = LeaderInput::from_fractions([0.0, 0.5, 1.0, 2.0], true);
        assert_eq!(i.millivolts, [0.0, 2500.0, 5000.0, 5000.0]);
        assert_eq!(
            (i.code(0), i.code(1), i.code(2), i.code(3)),
            (0, 512, 1023, 1023)
        );
        let mv = LeaderInput {
            millivolts: [1000.0, 4.8, 4.9, -3.0],
            deadman: false,
        };
        // 1000 mV × 1024 / 5000 = 204.8; one code is 4.88 mV
        assert_eq!(
            (mv.code(0), mv.code(1), mv.code(2), mv.code(3)),
            (204, 0, 1, 0)
        );
    }
}
