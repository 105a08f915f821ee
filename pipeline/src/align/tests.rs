#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use crate::voxel_hash::{voxel_downsample, voxel_downsample_every};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use std::path::PathBuf;

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/registration")
}

/// The real pair and its ground truth, or `None` (test skipped, said so) where shared/data is absent.
fn real_pair() -> Option<(Vec<Vec3>, Vec<Vec3>, Isometry3<f64>)> {
    let dir = data_dir();
    if !dir.join("source.ply").exists() {
        eprintln!("skipped: {} is absent", dir.display());
        return None;
    }
    let source = cloud_points(&crate::cloud::read(&dir.join("source.ply")).unwrap());
    let target = cloud_points(&crate::cloud::read(&dir.join("target.ply")).unwrap());
    let text = std::fs::read_to_string(dir.join("T_target_source.txt")).unwrap();
    let v: Vec<f64> = text.split_whitespace().map(|t| t.parse().unwrap()).collect();
    assert_eq!(v.len(), 16);
    let mut rows = [[0.0; 4]; 4];
    for (i, x) in v.iter().enumerate() {
        rows[i / 4][i % 4] = *x;
    }
    Some((source, target, pose_from_rows(&rows).unwrap()))
}

/// The yaw grid's seeds (the global stage adds its own).
fn grid_seeds(report: &AlignReport) -> usize {
    report.seeds.iter().filter(|s| s.origin == SeedOrigin::YawGrid).count()
}

fn assert_close(report: &AlignReport, truth: &Isometry3<f64>, what: &str) {
    let (t_m, r_deg) = pose_error(&report.pose, truth);
    eprintln!(
        "{what}: accepted {} after {} attempts, error {:.2} cm {:.3} deg, {:.0} ms",
        report.accepted,
        report.attempts.len(),
        t_m * 100.0,
        r_deg,
        report.total_ms
    );
    assert!(report.accepted, "{what}: rejected: {:?}", report.best().map(|a| &a.rejected_because));
    assert!(t_m < 0.05 && r_deg < 0.5, "{what}: error {t_m} m {r_deg} deg");
}

#[test]
fn real_pair_from_identity_and_perturbed_starts() {
    let Some((source, target, truth)) = real_pair() else { return };
    let aligner = Aligner::new(&target, AlignConfig::default()).unwrap();
    let report = aligner.align(&source, &Isometry3::identity());
    assert_close(&report, &truth, "identity");
    assert_eq!(report.attempts.len(), 1, "identity start: the best-ranked seed should pass");
    assert!(report.failure.is_none());
    assert_eq!(grid_seeds(&report), 12, "yaw seeds every 30 deg");
    let m = &report.attempts[0].metrics;
    assert!(m.degeneracy_index > 0.0 && m.degeneracy_index <= 1.0 / 3.0 + 1e-9);
    perturbed_starts(&aligner, &source, &truth, &[(30.0, 1.0, 0.0)]);
}

#[test]
fn real_pair_from_far_starts_with_reseeding() {
    let Some((source, target, truth)) = real_pair() else { return };
    let aligner = Aligner::new(&target, AlignConfig::default()).unwrap();
    perturbed_starts(&aligner, &source, &truth, &[(90.0, 0.0, 1.5), (180.0, 2.0, 0.0)]);
}

#[test]
fn a_source_capped_to_a_third_of_its_points_still_aligns() {
    let Some((source, target, truth)) = real_pair() else { return };
    let config = AlignConfig { source_max_points: source.len() / 3, ..AlignConfig::default() };
    let aligner = Aligner::new(&target, config).unwrap();
    let report = aligner.align(&source, &Isometry3::identity());
    assert_close(&report, &truth, "a third of the points");
    let all = Aligner::new(&target, AlignConfig::default()).unwrap().align(&source, &Isometry3::identity());
    assert!(report.source_points < all.source_points, "fewer points reach fewer voxels");
    assert!(
        report.source_points * 2 > all.source_points,
        "but most of them: {} of {}",
        report.source_points,
        all.source_points
    );
}

#[test]
fn nearest_matches_a_brute_force_search() {
    // A deterministic scatter over a few cells, queries inside and between them, on cell
    // boundaries and outside the cloud, with the search radius at and under the cell size.
    let mut next = crate::rng::uniform(12345u64);
    let points: Vec<Vec3> =
        (0..2000).map(|_| Vec3::new(next() * 3.0 - 1.5, next() * 3.0 - 1.5, next() * 1.0)).collect();
    let index = geometry::VoxelIndex::new(points.clone(), 0.5);
    let mut queries: Vec<Vec3> =
        (0..500).map(|_| Vec3::new(next() * 4.0 - 2.0, next() * 4.0 - 2.0, next() * 2.0 - 0.5)).collect();
    queries.extend([Vec3::new(0.5, 0.5, 0.5), Vec3::new(-0.5, 0.0, 1.0), Vec3::new(10.0, 0.0, 0.0)]);
    for max_m in [0.5, 0.2, 0.05] {
        for q in &queries {
            let brute = points
                .iter()
                .enumerate()
                .map(|(i, p)| (i, (p - q).norm_squared()))
                .filter(|&(_, d2)| d2 <= max_m * max_m)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let found = index.nearest(q, max_m);
            assert_eq!(found.map(|f| f.1), brute.map(|b| b.1), "query {q:?}, radius {max_m}");
        }
    }
}

#[test]
fn voxel_downsample_every_nth_point() {
    let points: Vec<Vec3> =
        (0..1000).map(|i| Vec3::new(f64::from(i % 10) * 0.01, f64::from(i / 10) * 0.01, 0.0)).collect();
    assert_eq!(voxel_downsample_every(&points, 0.5, 1), voxel_downsample(&points, 0.5));
    // 1 m x 0.1 m of points, 0.5 m voxels: both voxels from every 7th point, from the same centroids roughly.
    let every7 = voxel_downsample_every(&points, 0.5, 7);
    assert_eq!(every7.len(), 2);
    assert!(every7.iter().zip(voxel_downsample(&points, 0.5)).all(|(a, b)| (a - b).norm() < 0.02));
    assert_eq!(voxel_downsample_every(&points, 0.5, 0), voxel_downsample(&points, 0.5), "0 is every point");
}

/// Starts off the truth by a yaw about the true position (reseeding does the large ones) and a shift.
fn perturbed_starts(aligner: &Aligner, source: &[Vec3], truth: &Isometry3<f64>, starts: &[(f64, f64, f64)]) {
    for &(yaw_deg, dx_m, dy_m) in starts {
        let perturb = Isometry3::from_parts(
            Translation3::new(dx_m, dy_m, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, f64::to_radians(yaw_deg)),
        );
        let start = Isometry3::from_parts(truth.translation * perturb.translation, perturb.rotation * truth.rotation);
        let report = aligner.align(source, &start);
        assert_close(&report, truth, &format!("yaw {yaw_deg} deg, shift ({dx_m}, {dy_m}) m"));
    }
}

#[test]
fn synthetic_known_transform() {
    // Four walls, a floor, a ceiling and two boxes: constrained in all six directions.
    let mut target = Vec::new();
    let step = 0.1;
    for i in 0..=100 {
        for j in 0..=30 {
            let (a, b) = (-5.0 + f64::from(i) * step, f64::from(j) * step);
            target.push(Vec3::new(a, -4.0, b));
            target.push(Vec3::new(a, 4.0, b));
            target.push(Vec3::new(-5.0, a * 0.8, b));
            target.push(Vec3::new(5.0, a * 0.8, b));
        }
        for j in 0..=80 {
            let (a, b) = (-5.0 + f64::from(i) * step, -4.0 + f64::from(j) * step);
            target.push(Vec3::new(a, b, 0.0));
            target.push(Vec3::new(a, b, 3.0));
        }
    }
    for i in 0..=10 {
        for j in 0..=10 {
            let (a, b) = (f64::from(i) * step, f64::from(j) * step);
            target.push(Vec3::new(1.0 + a, 1.0 + b, 1.0));
            target.push(Vec3::new(1.0, 1.0 + a, b));
            target.push(Vec3::new(1.0 + a, 1.0, b));
            target.push(Vec3::new(-3.0 + a, -2.0, b * 1.5));
            target.push(Vec3::new(-3.0, -2.0 + a, b * 1.5));
        }
    }
    let truth =
        Isometry3::from_parts(Translation3::new(0.4, -0.3, 0.1), UnitQuaternion::from_euler_angles(0.02, -0.01, 0.2));
    let inv = truth.inverse();
    let source: Vec<Vec3> = target.iter().map(|p| (inv * Point3::from(*p)).coords).collect();
    // Every place the correlative stage finds is a seed, so that the ambiguity check has
    // contenders to refine (by default it keeps only places near the best's score).
    let config = AlignConfig { correlative_within_best: 1.0, ..AlignConfig::default() };
    let aligner = Aligner::new(&target, config).unwrap();
    let report = aligner.align(&source, &Isometry3::identity());
    assert_close(&report, &truth, "synthetic");
    let best = report.best().unwrap();
    assert!(best.metrics.rms_residual_m < 0.01);
    // The consistency check ran (six probes, all back at the result) and did not move it; the
    // ambiguity check refined other seeds and found none as good.
    assert_eq!((best.probes.len(), best.verify_hops), (6, 0));
    assert!(best.probes.iter().all(|p| p.moved_m < 0.02), "{:?}", best.probes);
    assert!(!best.alternatives.is_empty() && !best.ambiguous);
    // The information matrix is reported in the source frame: same eigenvalues, so its smallest
    // is the degeneracy index.
    let info = nalgebra::Matrix6::from_fn(|i, j| best.metrics.information[i][j]);
    let min = nalgebra::SymmetricEigen::new(info).eigenvalues.min();
    assert!((min - best.metrics.degeneracy_index).abs() < 1e-9, "{min} vs {}", best.metrics.degeneracy_index);
}

#[test]
fn symmetric_room_is_ambiguous_not_accepted() {
    // A bare box room: turned by 180 deg it fits exactly as well, so no answer can be trusted.
    let mut target = Vec::new();
    for i in 0..=100 {
        for j in 0..=30 {
            let (a, b) = (-5.0 + f64::from(i) * 0.1, f64::from(j) * 0.1);
            target.push(Vec3::new(a, -3.0, b));
            target.push(Vec3::new(a, 3.0, b));
            target.push(Vec3::new(-5.0, a * 0.6, b));
            target.push(Vec3::new(5.0, a * 0.6, b));
        }
        for j in 0..=60 {
            let (a, b) = (-5.0 + f64::from(i) * 0.1, -3.0 + f64::from(j) * 0.1);
            target.push(Vec3::new(a, b, 0.0));
            target.push(Vec3::new(a, b, 3.0));
        }
    }
    let truth =
        Isometry3::from_parts(Translation3::new(0.3, -0.2, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3));
    let inv = truth.inverse();
    let source: Vec<Vec3> = target.iter().map(|p| (inv * Point3::from(*p)).coords).collect();
    let aligner = Aligner::new(&target, AlignConfig::default()).unwrap();
    let report = aligner.align(&source, &Isometry3::identity());
    assert!(!report.accepted, "accepted {:?}", report.best().map(|a| &a.metrics));
    assert!(report.attempts.iter().any(|a| a.ambiguous), "{:?}", report.failure);
    let because = report.failure.as_ref().map_or(&[][..], |f| f.because());
    assert!(because.iter().any(|r| matches!(r, Rejection::Ambiguous { .. })), "{:?}", report.failure);
    // The correlative stage's test alone refuses it too: the turned place scores the same.
    let correlative = Aligner::new(&target, AlignConfig { ambiguity_seeds: 0, ..AlignConfig::default() }).unwrap();
    let report = correlative.align(&source, &Isometry3::identity());
    assert!(!report.accepted);
    let because = report.failure.as_ref().map_or(&[][..], |f| f.because());
    assert!(because.iter().any(|r| matches!(r, Rejection::ElsewhereAsGood { .. })), "{:?}", report.failure);
    // With both off the same search accepts one of the two: a coin toss.
    let off = AlignConfig { ambiguity_seeds: 0, correlative_seeds: 0, ..AlignConfig::default() };
    assert!(Aligner::new(&target, off).unwrap().align(&source, &Isometry3::identity()).accepted);
}

#[test]
fn nonsense_pair_is_rejected() {
    let Some((_, target, _)) = real_pair() else { return };
    // A scattered cloud (deterministic pseudo-random) around the scan: nothing in it matches.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let source: Vec<Vec3> =
        (0..20_000).map(|_| Vec3::new(next() * 40.0 - 20.0, next() * 40.0 - 20.0, next() * 6.0 - 2.0)).collect();
    // With escalation, nothing at the guess's position sends the search to four more positions:
    // still rejected, in at most twice the attempts.
    let escalated = AlignConfig { reseed_yaw_step_deg: 120.0, ..AlignConfig::default() };
    let report = Aligner::new(&target, escalated).unwrap().align(&source, &Isometry3::identity());
    assert!(!report.accepted);
    assert_eq!(grid_seeds(&report), 3 * 5, "seeds at the guess and at four positions around it");
    assert!(report.attempts.len() <= 6, "{} full attempts", report.attempts.len());
    let config = AlignConfig { reseed_yaw_step_deg: 120.0, escalate_shift_m: 0.0, ..AlignConfig::default() };
    let aligner = Aligner::new(&target, config).unwrap();
    let report = aligner.align(&source, &Isometry3::identity());
    let best = report.best().unwrap();
    eprintln!("nonsense: {:?}", best.rejected_because);
    assert!(!report.accepted);
    assert_eq!(grid_seeds(&report), 3, "every yaw seed scored");
    assert!(!report.attempts.is_empty() && report.attempts.len() <= 3, "{} full attempts", report.attempts.len());
    assert!(report.attempts.iter().all(|a| !a.accepted && !a.rejected_because.is_empty()));
    let failure = report.failure.as_ref().unwrap();
    assert!(matches!(failure, AlignFailure::NoneAccepted { because, .. } if !because.is_empty()), "{failure}");
}

#[test]
fn config_defaults_and_example_load() {
    let empty = AlignConfig::from_toml("").unwrap();
    assert_eq!(empty, AlignConfig::default());
    let example =
        std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/align.toml")).unwrap();
    assert_eq!(AlignConfig::from_toml(&example).unwrap(), AlignConfig::default());
    assert!(AlignConfig::from_toml("max_rms_m = 0.1\nbogus = 1\n").is_err());
    assert!(AlignConfig::from_toml("icp_trim_ratio = 1.5\n").is_err());
    assert!(AlignConfig::from_toml("ndt_resolutions_m = []\n").is_err());
    assert!(AlignConfig::from_toml("verify_margin = 1.0\n").is_err());
    assert!(AlignConfig::from_toml("ambiguity_margin = -0.1\n").is_err());
    assert!(AlignConfig::from_toml("verify_max_points = 0\n").is_err());
    assert!(AlignConfig::from_toml("free_space_max_blocked = 1.5\n").is_err());
    assert!(AlignConfig::from_toml("free_space_step_m = 0\n").is_err());
    assert!(AlignConfig::from_toml("pinned_slides_m = [0.5, -1.0]\n").is_err());
    assert!(AlignConfig::from_toml("pinned_min_inlier_ratio = 1.5\n").is_err());
    assert!(AlignConfig::from_toml("pinned_min_lost = -0.1\n").is_err());
    assert_eq!(AlignConfig::from_toml("pinned_slides_m = []\n").unwrap().pinned_slides_m, Vec::<f64>::new());
    assert!(AlignConfig::from_toml("free_space_end_margin_m = -0.1\n").is_err());
}

#[test]
fn reseed_offsets_cover_the_circle() {
    assert_eq!(yaw_offsets_deg(90.0), vec![90.0, -90.0, 180.0]);
    assert_eq!(yaw_offsets_deg(60.0).len(), 5);
    assert_eq!(yaw_offsets_deg(360.0), Vec::<f64>::new());
}

#[test]
fn bad_input_does_not_panic() {
    let target = vec![Vec3::new(f64::NAN, 0.0, 0.0), Vec3::new(1e300, -1e300, 0.0)];
    assert!(Aligner::new(&target, AlignConfig::default()).is_err());
    assert!(Aligner::new(&[], AlignConfig::default()).is_err());
}

/// A 10 x 8 x 3 m room with a box in one corner, sampled every 10 cm.
fn room() -> Vec<Vec3> {
    let mut points = Vec::new();
    let grid = |n: i32| (0..=n).map(|k| f64::from(k) * 0.1);
    for a in grid(100) {
        for z in grid(30) {
            points.push(Vec3::new(a, 0.0, z));
            points.push(Vec3::new(a, 8.0, z));
        }
    }
    for b in grid(80) {
        for z in grid(30) {
            points.push(Vec3::new(0.0, b, z));
            points.push(Vec3::new(10.0, b, z));
        }
        for a in grid(100) {
            points.push(Vec3::new(a, b, 0.0));
        }
    }
    for a in grid(10) {
        for z in grid(10) {
            points.push(Vec3::new(8.0 + a, 6.0, z));
            points.push(Vec3::new(8.0, 6.0 + a, z));
        }
    }
    points
}

#[test]
fn the_free_space_check_rejects_rays_that_pass_through_the_map() {
    let target = room();
    let config = AlignConfig { reseed_yaw_step_deg: 0.0, verify_shift_m: 0.0, ..AlignConfig::default() };
    let aligner = Aligner::new(&target, config).unwrap();
    let source = target.clone();
    // Seen from inside the room: every ray ends on the surface it meets first, but for the few
    // to the corner behind the box (the made-up source holds them; a real scan would not).
    let inside = Vec3::new(4.0, 3.0, 1.5);
    let rays: Vec<Ray> = source.iter().step_by(7).map(|p| Ray { origin: inside, end: *p }).collect();
    let report = aligner.align_with_rays(&source, &rays, &Isometry3::identity());
    let a = report.best().unwrap();
    let f = a.free_space.as_ref().expect("the check ran");
    assert!(report.accepted, "{:?}", a.rejected_because);
    assert!(f.rays > 300 && f.blocked_ratio < 0.05, "{f:?}");
    // The same points claimed seen from outside the room, beyond its x = 0 wall: the rays to
    // the far walls pass through that wall. The surfaces fit as well; the rays give it away.
    let outside = Vec3::new(-3.0, 4.0, 1.5);
    let rays: Vec<Ray> = source.iter().step_by(7).map(|p| Ray { origin: outside, end: *p }).collect();
    let report = aligner.align_with_rays(&source, &rays, &Isometry3::identity());
    let a = report.best().unwrap();
    assert!(!report.accepted);
    assert!(
        a.rejected_because.iter().any(|r| matches!(r, Rejection::SeesThroughMap { .. })),
        "{:?}",
        a.rejected_because
    );
    assert!(a.free_space.as_ref().unwrap().blocked_ratio > 0.5);
    // No rays: no check, as `align` does.
    assert!(aligner.align(&source, &Isometry3::identity()).best().unwrap().free_space.is_none());
}

/// A 60 m corridor along x, 2.4 m wide and 2.7 m high, sampled every 10 cm; with its far end
/// wall (x = 60) when `far_end`.
fn corridor(far_end: bool) -> Vec<Vec3> {
    let grid = |n: i32| (0..=n).map(|k| f64::from(k) * 0.1);
    let mut points = Vec::new();
    for x in grid(600) {
        for z in grid(27) {
            points.push(Vec3::new(x, 0.0, z));
            points.push(Vec3::new(x, 2.4, z));
        }
        for y in grid(24) {
            points.push(Vec3::new(x, y, 0.0));
            points.push(Vec3::new(x, y, 2.7));
        }
    }
    if far_end {
        for y in grid(24) {
            for z in grid(27) {
                points.push(Vec3::new(60.0, y, z));
            }
        }
    }
    points
}

#[test]
fn a_corridor_is_pinned_by_its_far_end_and_not_without_it() {
    // The rig stands 10 m into the corridor looking down it: it sees the walls ahead of it and,
    // with it, the far end wall; the guess is 0.3 m off along the corridor, where trimmed ICP
    // alone leaves it (the end wall's pairs are the ones it trims).
    let truth =
        Isometry3::from_parts(Translation3::new(10.0, 1.2, 1.5), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.01));
    let guess = Isometry3::from_parts(Translation3::new(0.3, 0.0, 0.0), UnitQuaternion::identity()) * truth;
    let config = AlignConfig { reseed_yaw_step_deg: 0.0, ..AlignConfig::default() };
    let seen = |far_end: bool| -> Vec<Vec3> {
        let inv = truth.inverse();
        corridor(far_end).into_iter().filter(|p| p.x > 10.5).map(|p| (inv * Point3::from(p)).coords).collect()
    };
    for far_end in [true, false] {
        let target = corridor(far_end);
        let source = seen(far_end);
        let report = Aligner::new(&target, config.clone()).unwrap().align(&source, &guess);
        let best = report.best().unwrap();
        // Either way the index calls the corridor degenerate: the check decides.
        assert!(best.metrics.degeneracy_index < config.min_degeneracy_index, "{}", best.metrics.degeneracy_index);
        let check = best.pinned.as_ref().expect("the check ran");
        assert!(!check.directions.is_empty());
        if far_end {
            assert_close(&report, &truth, "corridor with its far end");
            assert!(check.pinned, "{check:?}");
        } else {
            assert!(!report.accepted && !check.pinned, "{check:?}");
            let because = report.failure.as_ref().map_or(&[][..], |f| f.because());
            assert!(because.iter().any(|r| matches!(r, Rejection::NotPinnedSlides { .. })), "{because:?}");
        }
    }
    // With the check off the index alone refuses even the corridor with its end.
    let off = AlignConfig { pinned_slides_m: Vec::new(), ..config };
    let report = Aligner::new(&corridor(true), off).unwrap().align(&seen(true), &guess);
    assert!(!report.accepted && report.best().unwrap().pinned.is_none());
}
