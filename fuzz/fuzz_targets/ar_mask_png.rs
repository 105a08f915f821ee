#![no_main]
//! Person-mask PNG reader: never panics on any bytes; what it accepts holds exactly one byte
//! per pixel, and the inlier count over it stays within the points given.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::ar::{mask_inlier_ratio, read_mask_png, ProjectedPoint};

fuzz_target!(|data: &[u8]| {
    if let Ok((width, height, pixels)) = read_mask_png(data) {
        assert_eq!(pixels.len() as u64, u64::from(width) * u64::from(height));
        // Points from the input's first bytes, some outside the image.
        let points: Vec<ProjectedPoint> = data
            .chunks_exact(2)
            .take(64)
            .map(|c| ProjectedPoint {
                u: f64::from(c[0]) * f64::from(width) / 200.0 - 1.0,
                v: f64::from(c[1]) * f64::from(height) / 200.0 - 1.0,
                depth_m: 1.0,
                person: 0,
            })
            .collect();
        let (inside, in_image) = mask_inlier_ratio(&points, &pixels, width, height);
        assert!(inside <= in_image && in_image <= points.len());
    }
});
