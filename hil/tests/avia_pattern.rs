//! The simulated Avia's scan pattern against a real Avia frame (shared/data/livox/avia_frame.pcd:
//! 24,000 firings of 0.1 s in firing order, x y z intensity tag line; zeros where nothing
//! returned). Point i fired at i x 4167 ns, so each real return gives the true beam direction at
//! a known time, and the model must point the same way.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_hil::sim::pattern::AviaPattern;
use std::path::PathBuf;

fn real_frame() -> Option<Vec<(usize, u8, [f64; 3])>> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/livox/avia_frame.pcd");
    let bytes = std::fs::read(&path).ok()?;
    let marker = b"DATA binary\n";
    let start = bytes.windows(marker.len()).position(|w| w == marker)? + marker.len();
    let records = bytes.get(start..)?.chunks_exact(18);
    Some(
        records
            .enumerate()
            .filter_map(|(i, r)| {
                let f = |k: usize| f64::from(f32::from_le_bytes([r[k], r[k + 1], r[k + 2], r[k + 3]]));
                let p = [f(0), f(4), f(8)];
                (p != [0.0; 3]).then_some((i, r[17], p))
            })
            .collect(),
    )
}

fn angles_deg(p: [f64; 3]) -> (f64, f64) {
    (p[1].atan2(p[0]).to_degrees(), p[2].atan2(p[0].hypot(p[1])).to_degrees())
}

#[test]
fn model_points_where_the_real_avia_pointed() {
    let Some(frame) = real_frame() else {
        panic!("../shared/data/livox/avia_frame.pcd is missing: the pattern cannot be checked");
    };
    assert_eq!(frame.len(), 2813, "returns in the real frame");
    let mut errors: Vec<f64> = Vec::new();
    let mut line_agrees = 0usize;
    for &(i, line, p) in &frame {
        let t_ns = i as u64 * 4167;
        let model_line = i % 6;
        line_agrees += usize::from(usize::from(line) == model_line);
        let (az, el) = angles_deg(p);
        let (maz, mel) = AviaPattern::angles_deg(t_ns, model_line);
        errors.push((az - maz).hypot(el - mel));
    }
    errors.sort_by(f64::total_cmp);
    let pct = |q: f64| errors[((errors.len() - 1) as f64 * q) as usize];
    eprintln!(
        "angular error over {} real returns: median {:.2} deg, p90 {:.2} deg, p99 {:.2} deg",
        errors.len(),
        pct(0.5),
        pct(0.9),
        pct(0.99)
    );
    assert_eq!(line_agrees, frame.len(), "line = firing index mod 6");
    assert!(pct(0.5) < 0.8 && pct(0.9) < 1.5, "median {} p90 {}", pct(0.5), pct(0.9));
    // A pattern with the wrong prism rates fails the same check: the test can tell.
    let mut wrong: Vec<f64> = frame
        .iter()
        .map(|&(i, _, p)| {
            let (az, el) = angles_deg(p);
            let (maz, mel) = AviaPattern::angles_deg(i as u64 * 4167 * 11 / 10, i % 6);
            (az - maz).hypot(el - mel)
        })
        .collect();
    wrong.sort_by(f64::total_cmp);
    assert!(wrong[wrong.len() / 2] > 5.0, "a 10 % slower clock still matched: {}", wrong[wrong.len() / 2]);
}

/// The distribution of off-axis angles: the real returns against the model's beams at the same
/// firing times, and the model's whole frame (the real frame has no returns from the sky).
#[test]
fn off_axis_distribution_matches_where_the_real_frame_saw_something() {
    let Some(frame) = real_frame() else { panic!("avia_frame.pcd is missing") };
    let off_axis = |az: f64, el: f64| {
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        let _ = (sa, se);
        (ce * ca).clamp(-1.0, 1.0).acos().to_degrees()
    };
    let mut real = [0usize; 8];
    let mut model = [0usize; 8];
    for &(i, _, p) in &frame {
        let (az, el) = angles_deg(p);
        real[((off_axis(az, el) / 5.0) as usize).min(7)] += 1;
        let (maz, mel) = AviaPattern::angles_deg(i as u64 * 4167, i % 6);
        model[((off_axis(maz, mel) / 5.0) as usize).min(7)] += 1;
    }
    eprintln!("off-axis histogram (5 deg bins) real {real:?} model {model:?}");
    for k in 0..8 {
        let (r, m) = (real[k] as f64, model[k] as f64);
        assert!((r - m).abs() <= 0.15 * r.max(m) + 20.0, "bin {k}: real {r} model {m}");
    }
}
