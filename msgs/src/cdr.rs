//! Encode and decode messages exactly as a ROS 2 DataWriter/DataReader does.
//!
//! A serialized ROS 2 message is a 4-byte encapsulation header (representation
//! identifier and options) followed by CDR data. ros2-client writes
//! little-endian CDR (`00 01 00 00`); readers accept either byte order.

use rustdds::no_key::SerializerAdapter;
use rustdds::serialization::{deserialize_from_cdr_with_rep_id, CDRSerializerAdapter};
use rustdds::RepresentationIdentifier;
use serde::{de::DeserializeOwned, Serialize};

/// Why bytes could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CdrError {
    /// Fewer than the 4 bytes of the encapsulation header.
    #[error("serialized message is {len} bytes, shorter than the 4-byte encapsulation header")]
    TooShort {
        /// How many bytes there were.
        len: usize,
    },
    /// A representation other than plain CDR (big or little endian).
    #[error("unsupported representation identifier {0:02x?}")]
    UnsupportedRepresentation([u8; 2]),
    /// The CDR layer refused the data.
    #[error("CDR: {0}")]
    Cdr(String),
}

/// Serialize `msg` with its encapsulation header, as ros2-client puts it on the wire.
pub fn encode<M: Serialize>(msg: &M) -> Result<Vec<u8>, CdrError> {
    let body =
        CDRSerializerAdapter::<M>::to_bytes(msg).map_err(|e| CdrError::Cdr(e.to_string()))?;
    let rep = CDRSerializerAdapter::<M>::output_encoding().to_bytes();
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&[rep[0], rep[1], 0, 0]);
    out.extend_from_slice(&body);
    Ok(out)
}

/// Deserialize a message with its encapsulation header (as `rclpy.serialization.serialize_message` produces).
pub fn decode<M: DeserializeOwned>(bytes: &[u8]) -> Result<M, CdrError> {
    if bytes.len() < 4 {
        return Err(CdrError::TooShort { len: bytes.len() });
    }
    let rep = [bytes[0], bytes[1]];
    let rep_id =
        RepresentationIdentifier::from_bytes(&rep).map_err(|e| CdrError::Cdr(e.to_string()))?;
    if rep_id != RepresentationIdentifier::CDR_LE && rep_id != RepresentationIdentifier::CDR_BE {
        return Err(CdrError::UnsupportedRepresentation(rep));
    }
    let (msg, _consumed) = deserialize_from_cdr_with_rep_id::<M>(&bytes[4..], rep_id)
        .map_err(|e| CdrError::Cdr(e.to_string()))?;
    Ok(msg)
}

/// Serialized bytes as lowercase hex, the line format of the interop tools
/// (`recv TOPIC HEX`).
/// ```
/// assert_eq!(eezybot_msgs::cdr::hex(&[0, 1, 0xab]), "0001ab");
/// ```
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The bytes of a hex string; `None` if it has an odd length or a non-hex digit.
/// ```
/// use eezybot_msgs::cdr::unhex;
/// assert_eq!(unhex("0001ab"), Some(vec![0, 1, 0xab]));
/// assert_eq!(unhex("0g"), None);
/// assert_eq!(unhex("abc"), None);
/// ```
pub fn unhex(s: &str) -> Option<Vec<u8>> {
    (0..s.len())
        .step_by(2)
        .map(|i| s.get(i..i + 2).and_then(|h| u8::from_str_radix(h, 16).ok()))
        .collect()
}
