//! The bridge's own `diagnostics` on its site's LAN (diagnostic_msgs/DiagnosticArray,
//! the contract's QoS: reliable, volatile, 10), once a second: one status
//! `eezybot_wan_bridge_SIDE: WAN link` whose level and message say whether the router is
//! connected, with the router's endpoint and, over TLS, its certificate's expiry in the
//! nodes' keys (`certificate_expires`, `certificate_days_left`; within 30 days a warning
//! naming the file: [`crate::expiry`]). The panel's health strip shows it beside the
//! nodes'. On the Pi the bridge's own route carries it to the PCs like serial_node's
//! (the plugin's readers ignore only their own participant's writers).
//!
//! A DDS participant of its own (Cyclone DDS through cyclors, as the plugin's), created
//! once the plugin's exists: the first participant of a domain fixes the domain's
//! configuration, which the plugin sets (CYCLONEDDS_URI) before it creates its own.

use std::ffi::CString;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use cyclors::*;

use crate::cdr::{now_nanos, Cdr};
use crate::expiry::{now_unix, CertificateExpiry};

/// diagnostic_msgs/DiagnosticStatus levels.
pub const OK: u8 = 0;
/// A warning (a certificate within 30 days of its end).
pub const WARN: u8 = 1;
/// An error (not connected to the router).
pub const ERROR: u8 = 2;

/// What the status says; `connected` is kept current by the bridge.
pub struct Health {
    /// `eezybot_wan_bridge_pc` or `_pi`.
    pub node: String,
    /// The nodes' namespace (`""` or `/arm2`).
    pub namespace: String,
    /// The router's endpoint.
    pub router: String,
    /// The certificate's end (TLS only).
    pub expiry: Option<CertificateExpiry>,
    /// Whether the router is connected now.
    pub connected: Arc<AtomicBool>,
}

/// One status: (level, name, message, hardware_id, values).
pub type Status = (u8, String, String, String, Vec<(String, String)>);

impl Health {
    /// The status now (`now`: Unix seconds).
    pub fn status(&self, now: i64) -> Status {
        let connected = self.connected.load(Ordering::Relaxed);
        let (mut level, mut message) = if connected {
            (OK, format!("connected to the router {}", self.router))
        } else {
            (
                ERROR,
                format!(
                    "not connected to the router {}: is it running and reachable, and were its certificate and ours made by the same CA (wan_certs.sh)?",
                    self.router
                ),
            )
        };
        let mut values = vec![
            ("router".to_string(), self.router.clone()),
            ("connected".to_string(), connected.to_string()),
        ];
        if let Some(e) = &self.expiry {
            values.push(("certificate".into(), e.path.display().to_string()));
            values.push(("certificate_expires".into(), e.date()));
            values.push(("certificate_days_left".into(), e.days_left(now).to_string()));
            if let Some(w) = e.warning(now) {
                level = level.max(WARN);
                message = format!("{message}; {w}");
            }
        }
        (
            level,
            format!("{}: WAN link", self.node),
            message,
            self.router.clone(),
            values,
        )
    }
}

/// diagnostic_msgs/DiagnosticArray stamped `unix_nanos`.
pub fn diagnostic_array(unix_nanos: i128, statuses: &[Status]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(unix_nanos, "");
    c.u32(statuses.len() as u32);
    for (level, name, message, hardware_id, values) in statuses {
        c.u8(*level)
            .string(name)
            .string(message)
            .string(hardware_id);
        c.u32(values.len() as u32);
        for (k, v) in values {
            c.string(k).string(v);
        }
    }
    c.into_bytes()
}

/// A DDS writer of raw CDR samples.
struct Writer(dds_entity_t);

impl Writer {
    /// Participant, topic and writer in `domain`; `None` with the reason logged.
    fn new(domain: u32, topic: &str, type_name: &str) -> Result<Writer, String> {
        let topic = CString::new(topic).map_err(|e| e.to_string())?;
        let type_name = CString::new(type_name).map_err(|e| e.to_string())?;
        // SAFETY: plain Cyclone DDS C calls with valid, NUL-terminated strings; the
        // topic functions copy their arguments; every entity is checked.
        unsafe {
            let dp = dds_create_participant(domain, std::ptr::null(), std::ptr::null());
            if dp < 0 {
                return Err(format!("DDS participant: {}", retcode(dp)));
            }
            let t = cdds_create_blob_topic(dp, topic.into_raw(), type_name.into_raw(), true);
            if t < 0 {
                dds_delete(dp);
                return Err(format!("DDS topic: {}", retcode(t)));
            }
            let qos = dds_create_qos();
            dds_qset_reliability(
                qos,
                dds_reliability_kind_DDS_RELIABILITY_RELIABLE,
                100_000_000,
            );
            dds_qset_durability(qos, dds_durability_kind_DDS_DURABILITY_VOLATILE);
            dds_qset_history(qos, dds_history_kind_DDS_HISTORY_KEEP_LAST, 10);
            let w = dds_create_writer(dp, t, qos, std::ptr::null());
            dds_delete_qos(qos);
            if w < 0 {
                dds_delete(dp);
                return Err(format!("DDS writer: {}", retcode(w)));
            }
            Ok(Writer(w))
        }
    }

    /// Write one serialized sample (with its encapsulation header).
    fn write(&self, data: &[u8]) -> Result<(), String> {
        // SAFETY: as the plugin's dds_write: the serdata copies the bytes from the iovec,
        // which outlives the call.
        unsafe {
            let mut sertype: *const ddsi_sertype = std::ptr::null();
            let ret = dds_get_entity_sertype(self.0, &mut sertype);
            if ret < 0 {
                return Err(format!("sertype: {}", retcode(ret)));
            }
            // ddsrt_iov_len_t is usize here, not on every platform Cyclone builds for
            #[allow(clippy::useless_conversion)]
            let iov = ddsrt_iovec_t {
                iov_base: data.as_ptr() as *mut std::ffi::c_void,
                iov_len: data.len().try_into().map_err(|_| "sample too large")?,
            };
            let serdata =
                ddsi_serdata_from_ser_iov(sertype, ddsi_serdata_kind_SDK_DATA, 1, &iov, data.len());
            let ret = dds_writecdr(self.0, serdata);
            if ret < 0 {
                return Err(format!("write: {}", retcode(ret)));
            }
        }
        Ok(())
    }
}

fn retcode(r: i32) -> String {
    // SAFETY: dds_strretcode returns a static string.
    unsafe { std::ffi::CStr::from_ptr(dds_strretcode(-r)) }
        .to_string_lossy()
        .into_owned()
}

/// Whether this process has a participant in `domain` (the plugin's).
fn plugin_participant_exists(domain: u32) -> bool {
    let mut found: [dds_entity_t; 1] = [0];
    // SAFETY: writes at most 1 entity into `found`.
    unsafe { dds_lookup_participant(domain, found.as_mut_ptr(), 1) > 0 }
}

/// Publish `health` every second from a thread of its own, once the plugin's DDS
/// participant exists; `program` prefixes the one line said if DDS refuses.
pub fn spawn(program: &'static str, domain: u32, health: Health) {
    std::thread::Builder::new()
        .name("diagnostics".into())
        .spawn(move || {
            while !plugin_participant_exists(domain) {
                std::thread::sleep(Duration::from_millis(100));
            }
            let topic = format!("rt{}/diagnostics", health.namespace);
            let writer = match Writer::new(
                domain,
                &topic,
                "diagnostic_msgs::msg::dds_::DiagnosticArray_",
            ) {
                Ok(w) => w,
                Err(e) => {
                    eprintln!("{program}: no diagnostics on {topic}: {e}");
                    return;
                }
            };
            let mut said = false;
            loop {
                let sample = diagnostic_array(now_nanos(), &[health.status(now_unix())]);
                if let Err(e) = writer.write(&sample) {
                    if !said {
                        eprintln!("{program}: diagnostics not written: {e}");
                        said = true;
                    }
                }
                std::thread::sleep(Duration::from_secs(1));
            }
        })
        .map(|_| ())
        .unwrap_or_else(|e| eprintln!("{program}: no diagnostics thread: {e}"));
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn health(connected: bool, days: Option<i64>) -> Health {
        Health {
            node: "eezybot_wan_bridge_pi".into(),
            namespace: String::new(),
            router: "tls/10.77.0.1:7447".into(),
            expiry: days.map(|d| CertificateExpiry {
                path: PathBuf::from("/c/pi.pem"),
                not_after: 1_800_000_000 + d * 86_400,
            }),
            connected: Arc::new(AtomicBool::new(connected)),
        }
    }

    #[test]
    fn the_status_says_the_link_and_the_certificates_end() {
        let (level, name, message, _, values) = health(true, Some(400)).status(1_800_000_000);
        assert_eq!(
            (level, name.as_str()),
            (OK, "eezybot_wan_bridge_pi: WAN link")
        );
        assert!(message.starts_with("connected"), "{message}");
        let v: std::collections::HashMap<_, _> = values.into_iter().collect();
        assert_eq!(v["certificate_days_left"], "400");
        assert_eq!(v["certificate_expires"], "2028-02-19");
        let (level, _, message, _, _) = health(true, Some(10)).status(1_800_000_000);
        assert_eq!(level, WARN);
        assert!(message.contains("/c/pi.pem expires on"), "{message}");
        let (level, _, message, _, values) = health(false, None).status(1_800_000_000);
        assert_eq!(level, ERROR);
        assert!(message.starts_with("not connected"), "{message}");
        assert_eq!(values.len(), 2);
    }

    #[test]
    fn a_diagnostic_array_as_ros_writes_it() {
        let b = diagnostic_array(
            0,
            &[(
                1,
                "n".into(),
                "".into(),
                "h".into(),
                vec![("k".into(), "v".into())],
            )],
        );
        let want: Vec<u8> = [
            &[0, 1, 0, 0][..],
            &[0; 8],             // stamp
            &1u32.to_le_bytes(), // frame_id
            &[0, 0, 0, 0],       // its NUL, padding
            &1u32.to_le_bytes(), // one status
            &[1, 0, 0, 0],       // level, padding
            &2u32.to_le_bytes(),
            b"n\0",
            &[0, 0],
            &1u32.to_le_bytes(),
            &[0, 0, 0, 0],
            &2u32.to_le_bytes(),
            b"h\0",
            &[0, 0],
            &1u32.to_le_bytes(), // one value
            &2u32.to_le_bytes(),
            b"k\0",
            &[0, 0],
            &2u32.to_le_bytes(),
            b"v\0",
        ]
        .concat();
        assert_eq!(b, want);
    }
}
