//! When the TLS files of `launch_scripts/wan_certs.sh` run out: the earlier `notAfter`
//! of a party's certificate and of the CA's (either one expired and the other end
//! refuses the handshake). The same convention as the secured nodes'
//! (`ros_plumbing::security::CertificateExpiry`, `diagnostics::annotate_certificate`):
//! `certificate_expires` (UTC date) and `certificate_days_left`, a warning within
//! [`WARNING_DAYS`] of the end naming the file to renew.

use std::path::{Path, PathBuf};

use x509_parser::prelude::{FromDer, X509Certificate};

/// A certificate this close to its end is warned about (as the nodes do).
pub const WARNING_DAYS: i64 = 30;

/// The file whose certificate runs out first, and when.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CertificateExpiry {
    /// The PEM file.
    pub path: PathBuf,
    /// Its `notAfter`, seconds since the Unix epoch.
    pub not_after: i64,
}

/// The `notAfter` of the first certificate in the PEM file `path`.
pub fn not_after(path: &Path) -> Result<i64, String> {
    let pem = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let der = rustls_pemfile::certs(&mut pem.as_slice())
        .next()
        .and_then(Result::ok)
        .ok_or_else(|| format!("{} holds no PEM certificate", path.display()))?;
    let (_, cert) = X509Certificate::from_der(der.as_ref())
        .map_err(|e| format!("{}: not a certificate ({e})", path.display()))?;
    Ok(cert.validity().not_after.timestamp())
}

impl CertificateExpiry {
    /// The earliest end among these PEM files (a party's certificate and its CA's).
    pub fn earliest(paths: &[&Path]) -> Result<CertificateExpiry, String> {
        let mut earliest: Option<CertificateExpiry> = None;
        for path in paths {
            let not_after = not_after(path)?;
            if earliest.as_ref().is_none_or(|e| not_after < e.not_after) {
                earliest = Some(CertificateExpiry {
                    path: path.to_path_buf(),
                    not_after,
                });
            }
        }
        earliest.ok_or_else(|| "no certificate".to_string())
    }

    /// Whole days from `now` (Unix seconds) to the end, rounded down (negative past it).
    pub fn days_left(&self, now: i64) -> i64 {
        (self.not_after - now).div_euclid(86_400)
    }

    /// `YYYY-MM-DD` (UTC) of the end.
    pub fn date(&self) -> String {
        utc_date(self.not_after)
    }

    /// Within [`WARNING_DAYS`] of the end (or past it): what to say, naming the file.
    pub fn warning(&self, now: i64) -> Option<String> {
        let days = self.days_left(now);
        (days < WARNING_DAYS).then(|| {
            format!(
                "{} expires on {} ({days} days): renew it (docs/security.md: Certificates that expire)",
                self.path.display(),
                self.date()
            )
        })
    }

    /// One line for a log at start: the end, and the warning if any.
    pub fn summary(&self, now: i64) -> String {
        match self.warning(now) {
            Some(w) => format!("WARNING: {w}"),
            None => format!(
                "certificate valid until {} ({} days; {} runs out first)",
                self.date(),
                self.days_left(now),
                self.path.display()
            ),
        }
    }
}

/// Seconds since the Unix epoch now (0 if the clock is before it).
pub fn now_unix() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX))
}

/// `YYYY-MM-DD` of a Unix time (UTC).
pub fn utc_date(unix: i64) -> String {
    let (y, m, d) = civil_from_days(unix.div_euclid(86_400));
    format!("{y:04}-{m:02}-{d:02}")
}

/// Year, month, day of a day count since 1970-01-01 (Howard Hinnant's algorithm, as
/// ros_plumbing::sros2::civil_from_days).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expiry(days: i64) -> CertificateExpiry {
        CertificateExpiry {
            path: PathBuf::from("/certs/pi.pem"),
            not_after: 1_800_000_000 + days * 86_400,
        }
    }

    #[test]
    fn dates_are_utc_calendar_dates() {
        assert_eq!(utc_date(0), "1970-01-01");
        assert_eq!(utc_date(951_782_400), "2000-02-29");
        assert_eq!(utc_date(1_796_000_000), "2026-11-30");
        assert_eq!(utc_date(-86_400), "1969-12-31");
    }

    #[test]
    fn within_30_days_it_is_a_warning_that_names_the_file() {
        let now = 1_800_000_000;
        assert_eq!(expiry(30).warning(now), None);
        assert_eq!(expiry(30).days_left(now), 30);
        let w = expiry(29).warning(now).unwrap();
        assert!(
            w.starts_with("/certs/pi.pem expires on 2027-02-13 (29 days): renew it"),
            "{w}"
        );
        assert!(expiry(-2).warning(now).unwrap().contains("(-2 days)"));
        assert!(expiry(400)
            .summary(now)
            .starts_with("certificate valid until"));
        assert!(expiry(3).summary(now).starts_with("WARNING: /certs/pi.pem"));
    }
}
