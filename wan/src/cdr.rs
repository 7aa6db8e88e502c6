//! A little CDR (XCDR1, little-endian, as ROS 2's DDS layers write it) for the few
//! messages the WAN binaries write themselves: the bridge's `diagnostics`
//! (diagnostic_msgs/DiagnosticArray) and the check client's `servo_angles`
//! (sensor_msgs/JointState, examples/acl_probe.rs). The payload begins with the 4-byte
//! encapsulation header; alignment is relative to the end of it.

/// A serialized sample being written.
pub struct Cdr(Vec<u8>);

impl Default for Cdr {
    fn default() -> Self {
        Self::new()
    }
}

impl Cdr {
    /// The encapsulation header CDR_LE, nothing else yet.
    pub fn new() -> Self {
        Cdr(vec![0x00, 0x01, 0x00, 0x00])
    }

    fn align(&mut self, n: usize) {
        while !(self.0.len() - 4).is_multiple_of(n) {
            self.0.push(0);
        }
    }

    /// An octet (uint8, byte).
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }

    /// An int32.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A uint32 (also a sequence's length).
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A float64.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A string: length with its NUL, the bytes, the NUL.
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(u32::try_from(s.len() + 1).unwrap_or(u32::MAX));
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
        self
    }

    /// A std_msgs/Header: stamp (sec, nanosec) and frame_id.
    pub fn header(&mut self, unix_nanos: i128, frame_id: &str) -> &mut Self {
        let sec = i32::try_from(unix_nanos.div_euclid(1_000_000_000)).unwrap_or(i32::MAX);
        let nanosec = unix_nanos.rem_euclid(1_000_000_000) as u32;
        self.i32(sec).u32(nanosec).string(frame_id)
    }

    /// The bytes.
    pub fn into_bytes(self) -> Vec<u8> {
        self.0
    }
}

/// Nanoseconds since the Unix epoch now.
pub fn now_nanos() -> i128 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i128)
}

/// sensor_msgs/JointState with names and positions only (no velocity or effort).
pub fn joint_state(unix_nanos: i128, names: &[&str], positions: &[f64]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(unix_nanos, "");
    c.u32(names.len() as u32);
    for n in names {
        c.string(n);
    }
    c.u32(positions.len() as u32);
    for p in positions {
        c.f64(*p);
    }
    c.u32(0).u32(0);
    c.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_joint_state_as_ros_writes_it() {
        let b = joint_state(1_000_000_002, &["a"], &[1.5]);
        let want: Vec<u8> = [
            &[0, 1, 0, 0][..],
            &1i32.to_le_bytes(),
            &2u32.to_le_bytes(),
            &1u32.to_le_bytes(), // frame_id "" (its NUL)
            &[0, 0, 0, 0],       // NUL + padding to 4
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"a\0",
            &[0, 0],
            &1u32.to_le_bytes(), // at 28: the f64 at 32 is aligned
            &1.5f64.to_le_bytes(),
            &0u32.to_le_bytes(),
            &0u32.to_le_bytes(),
        ]
        .concat();
        assert_eq!(b, want);
    }
}
