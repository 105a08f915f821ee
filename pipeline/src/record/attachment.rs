//! The attachment rmw_zenoh puts on every sample (the ROS 2 bridge's, starc-link's `ros2`) (`AttachmentData` in rmw_zenoh_cpp): the
//! publisher's sequence number, the source time and the publisher's GID, in zenoh-ext's
//! serialization: two little-endian i64, then the GID as a sequence of 16 bytes (its length as
//! one LEB128 byte, 16). 33 bytes.

/// Bytes in a GID (`RMW_GID_STORAGE_SIZE`).
pub const GID_BYTES: usize = 16;
/// Bytes of an encoded attachment.
pub const ATTACHMENT_BYTES: usize = 8 + 8 + 1 + GID_BYTES;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    /// Nanoseconds since the Unix epoch, on the publisher's host clock.
    pub source_timestamp_ns: i64,
    pub gid: [u8; GID_BYTES],
}

impl Attachment {
    pub fn encode(&self) -> [u8; ATTACHMENT_BYTES] {
        let mut out = [0u8; ATTACHMENT_BYTES];
        out[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        out[8..16].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        out[16] = GID_BYTES as u8;
        out[17..].copy_from_slice(&self.gid);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<Self, crate::PipelineError> {
        let bytes: &[u8; ATTACHMENT_BYTES] = bytes.try_into().map_err(|_| bad("not 33 bytes"))?;
        if usize::from(bytes[16]) != GID_BYTES {
            return Err(bad("the GID is not 16 bytes"));
        }
        let i64_at = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&bytes[i..i + 8]);
            i64::from_le_bytes(b)
        };
        let mut gid = [0u8; GID_BYTES];
        gid.copy_from_slice(&bytes[17..]);
        Ok(Self { sequence_number: i64_at(0), source_timestamp_ns: i64_at(8), gid })
    }
}

fn bad(reason: &str) -> crate::PipelineError {
    crate::PipelineError::BadFile { format: "rmw_zenoh attachment", reason: reason.into() }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_refuses_other_layouts() {
        let a = Attachment { sequence_number: 7, source_timestamp_ns: -3, gid: [9; 16] };
        let bytes = a.encode();
        assert_eq!(bytes[..8], [7, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(bytes[16], 16);
        assert_eq!(Attachment::decode(&bytes).unwrap(), a);
        assert!(Attachment::decode(&bytes[..32]).is_err());
        let mut wrong = bytes;
        wrong[16] = 15;
        assert!(Attachment::decode(&wrong).is_err());
    }
}
