//! KITTI velodyne `.bin` files: a bare array of points, each x, y, z, intensity as little-endian
//! f32. No header, so no start time, line, tag or firing time.

use super::{CloudPoint, PointCloud};
use crate::PipelineError;

/// Bytes of one point.
pub const POINT_SIZE: usize = 16;

/// Reads a KITTI `.bin` file from bytes; its length must be a multiple of 16.
pub fn read_bytes(bytes: &[u8]) -> Result<PointCloud, PipelineError> {
    let chunks = bytes.chunks_exact(POINT_SIZE);
    if !chunks.remainder().is_empty() {
        return Err(PipelineError::BadFile {
            format: "KITTI",
            reason: format!("{} bytes is not a whole number of 16-byte points", bytes.len()),
        });
    }
    let points = chunks
        .map(|c| {
            let mut v = [0f32; 4];
            for (dst, src) in v.iter_mut().zip(c.chunks_exact(4)) {
                *dst = f32::from_le_bytes([src[0], src[1], src[2], src[3]]);
            }
            CloudPoint { intensity: v[3], ..CloudPoint::xyz(v[0], v[1], v[2]) }
        })
        .collect();
    Ok(PointCloud { start: None, points })
}

/// Encodes x, y, z, intensity of every point.
pub fn encode(cloud: &PointCloud, out: &mut Vec<u8>) {
    out.reserve(cloud.points.len() * POINT_SIZE);
    for p in &cloud.points {
        for v in [p.x_m, p.y_m, p.z_m, p.intensity] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_bad_lengths() {
        let cloud = PointCloud::new(
            None,
            vec![
                CloudPoint { intensity: 0.25, ..CloudPoint::xyz(1.0, -2.0, 3.5) },
                CloudPoint::xyz(f32::MAX, 0.0, -0.0),
            ],
        );
        let mut bytes = Vec::new();
        encode(&cloud, &mut bytes);
        assert_eq!(bytes.len(), 32);
        assert_eq!(read_bytes(&bytes).unwrap(), cloud);
        assert!(read_bytes(&[]).unwrap().is_empty());
        assert!(matches!(read_bytes(&bytes[..31]), Err(PipelineError::BadFile { .. })));
    }
}
