//! The test source's clock: frames on a fixed grid of 1/fps from a start time, frame `k`
//! at `start + floor(k * 10⁹ / fps)` ns. A frame is made when its slot comes; one that is
//! late takes the newest slot due, and the slots passed over are counted as dropped.
//!
//! # Examples
//! ```
//! use camera_node::grid::FrameGrid;
//! let mut g = FrameGrid::new(1_000_000_000, 30);
//! let s = g.next(1_000_000_000);
//! assert_eq!((s.index, s.at_ns, s.skipped), (0, 1_000_000_000, 0));
//! let s = g.next(1_000_000_001); // early for frame 1: wait until its slot
//! assert_eq!((s.index, s.at_ns), (1, 1_033_333_333));
//! let s = g.next(1_140_000_000); // late: frames 2 and 3 are passed over
//! assert_eq!((s.index, s.at_ns, s.skipped), (4, 1_133_333_333, 2));
//! ```

/// Frame slots on a grid of 1/fps.
#[derive(Clone, Debug)]
pub struct FrameGrid {
    start_ns: i64,
    fps: u32,
    next_index: u64,
}

/// A frame's slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slot {
    /// Frame number from the grid's start.
    pub index: u64,
    /// When the frame is due (its stamp), ns on the grid's clock.
    pub at_ns: i64,
    /// Slots passed over since the previous one (frames dropped).
    pub skipped: u64,
}

impl FrameGrid {
    /// A grid starting at `start_ns` with `fps` frames a second (at least 1).
    pub fn new(start_ns: i64, fps: u32) -> Self {
        FrameGrid {
            start_ns,
            fps: fps.max(1),
            next_index: 0,
        }
    }

    /// When slot `index` is due, ns.
    pub fn slot_ns(&self, index: u64) -> i64 {
        self.start_ns + (i128::from(index) * 1_000_000_000 / i128::from(self.fps)) as i64
    }

    /// The slot of the next frame at time `now_ns`: the next slot not taken yet, or if
    /// later slots are already due, the newest of them (the others skipped). Its time may
    /// be in the future: the caller waits until then.
    pub fn next(&mut self, now_ns: i64) -> Slot {
        let elapsed = i128::from(now_ns - self.start_ns).max(0);
        let due = (elapsed * i128::from(self.fps) / 1_000_000_000) as u64;
        let index = due.max(self.next_index);
        let skipped = index - self.next_index;
        self.next_index = index + 1;
        Slot {
            index,
            at_ns: self.slot_ns(index),
            skipped,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_time_frames_follow_the_grid_with_nothing_skipped() {
        let mut g = FrameGrid::new(0, 30);
        let mut now = 0;
        for k in 0..100u64 {
            let s = g.next(now);
            assert_eq!((s.index, s.skipped), (k, 0));
            let exact = k as f64 * 1e9 / 30.0;
            assert!((s.at_ns as f64 - exact).abs() < 1.0, "{k}: {}", s.at_ns);
            now = s.at_ns + 2_000_000; // made 2 ms after its slot
        }
    }

    #[test]
    fn a_late_frame_takes_the_newest_due_slot_and_counts_the_skipped() {
        let mut g = FrameGrid::new(500, 10);
        assert_eq!(g.next(500).index, 0);
        let s = g.next(500 + 350_000_000);
        assert_eq!(
            s,
            Slot {
                index: 3,
                at_ns: 300_000_500,
                skipped: 2
            }
        );
        // a clock before the start waits for slot 4
        let s = g.next(0);
        assert_eq!((s.index, s.skipped), (4, 0));
    }

    #[test]
    fn stamps_increase_and_differ_by_whole_periods_within_a_nanosecond() {
        let mut g = FrameGrid::new(1_764_446_400_123_456_789, 7);
        let stamps: Vec<i64> = (0..50).map(|i| g.next(i).at_ns).collect();
        for w in stamps.windows(2) {
            let d = w[1] - w[0];
            assert!((d - 142_857_142).abs() <= 1, "{d}");
        }
    }
}
