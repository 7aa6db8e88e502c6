//! The camera's link policy, a pure machine on a given clock: open the device, stream
//! until a read fails, then close it and try again after [`RETRY`]; a failing camera is
//! never fatal. [`crate::source::capture`] drives it and does the I/O.
//!
//! # Examples
//! ```
//! use camera_node::retry::{Link, RETRY};
//! use std::time::{Duration, Instant};
//! let t0 = Instant::now();
//! let mut link = Link::new(t0);
//! assert!(link.open_due(t0));
//! link.failed("no such device".into(), t0);
//! assert!(!link.open_due(t0 + Duration::from_millis(999)));
//! assert!(link.open_due(t0 + RETRY));
//! ```

use std::time::{Duration, Instant};

/// How long after a failure the device is opened again.
pub const RETRY: Duration = Duration::from_secs(1);

/// Where the camera is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LinkState {
    /// Not open; an attempt to open it is due at `retry_at`. `error` is why the last
    /// attempt or stream ended (none before the first attempt).
    Closed {
        /// when to open it again
        retry_at: Instant,
        /// the last failure, if any
        error: Option<String>,
    },
    /// Open and streaming.
    Streaming,
}

/// The link's state and its counts.
#[derive(Clone, Debug)]
pub struct Link {
    state: LinkState,
    retry: Duration,
    failures: u64,
    opens: u64,
}

impl Link {
    /// Closed, its first attempt due at `now`; retries after [`RETRY`].
    pub fn new(now: Instant) -> Self {
        Link::with_retry(now, RETRY)
    }

    /// Closed, its first attempt due at `now`; retries after `retry`.
    pub fn with_retry(now: Instant, retry: Duration) -> Self {
        Link {
            state: LinkState::Closed {
                retry_at: now,
                error: None,
            },
            retry,
            failures: 0,
            opens: 0,
        }
    }

    /// The state.
    pub fn state(&self) -> &LinkState {
        &self.state
    }

    /// Failures so far (opens and reads).
    pub fn failures(&self) -> u64 {
        self.failures
    }

    /// Successful opens so far.
    pub fn opens(&self) -> u64 {
        self.opens
    }

    /// Whether the device is to be opened now.
    pub fn open_due(&self, now: Instant) -> bool {
        matches!(self.state, LinkState::Closed { retry_at, .. } if now >= retry_at)
    }

    /// When to open it next (`None` while streaming).
    pub fn retry_at(&self) -> Option<Instant> {
        match self.state {
            LinkState::Closed { retry_at, .. } => Some(retry_at),
            LinkState::Streaming => None,
        }
    }

    /// The device opened.
    pub fn opened(&mut self) {
        self.opens += 1;
        self.state = LinkState::Streaming;
    }

    /// Opening or reading failed at `now` for `reason`: closed, the next attempt after
    /// the retry interval.
    pub fn failed(&mut self, reason: String, now: Instant) {
        self.failures += 1;
        self.state = LinkState::Closed {
            retry_at: now + self.retry,
            error: Some(reason),
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_that_fails_is_retried_every_second_and_streams_when_it_opens() {
        let t0 = Instant::now();
        let s = |ms| t0 + Duration::from_millis(ms);
        let mut link = Link::new(t0);
        assert!(link.open_due(t0));
        link.failed("open /dev/video0: No such file or directory".into(), t0);
        assert_eq!(link.retry_at(), Some(s(1000)));
        assert!(!link.open_due(s(999)));
        assert!(link.open_due(s(1000)));
        link.failed(
            "open /dev/video0: No such file or directory".into(),
            s(1003),
        );
        assert!(!link.open_due(s(2002)));
        assert!(link.open_due(s(2003)));
        link.opened();
        assert_eq!(link.state(), &LinkState::Streaming);
        assert!(!link.open_due(s(10_000)));
        assert_eq!(link.retry_at(), None);
        // unplugged while streaming
        link.failed("read: No such device".into(), s(5000));
        assert_eq!(
            link.state(),
            &LinkState::Closed {
                retry_at: s(6000),
                error: Some("read: No such device".into())
            }
        );
        assert_eq!((link.failures(), link.opens()), (3, 1));
    }
}
