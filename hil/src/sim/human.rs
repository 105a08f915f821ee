//! People: a skeleton of 14 joints in one of four poses, fleshed out with capsules, walking with
//! a swing of the legs and arms.
//!
//! Person frame: origin on the floor between the feet (the pelvis for someone lying), x the way
//! they face, z up. Joint heights are those of a 1.75 m adult, scaled by height; a build other
//! than 1 scales the widths (across the body, and every radius) but not the height.

use crate::sim::scenario::PoseKind;
use crate::sim::shapes::{Aabb, Capsule, Hit, V3};

const REFERENCE_HEIGHT_M: f64 = 1.75;
pub const CLOTHING_ALBEDO: f32 = 0.3;
pub const SKIN_ALBEDO: f32 = 0.45;

/// Joints of the skeleton.
#[derive(Clone, Copy, Debug)]
struct Skeleton {
    head: V3,
    neck: V3,
    pelvis: V3,
    shoulder: [V3; 2],
    elbow: [V3; 2],
    wrist: [V3; 2],
    hip: [V3; 2],
    knee: [V3; 2],
    ankle: [V3; 2],
}

fn v(x: f64, y: f64, z: f64) -> V3 {
    V3::new(x, y, z)
}

/// The skeleton of a pose; `swing` in [-1, 1] moves the legs and arms as in a stride.
fn skeleton(pose: PoseKind, swing: f64) -> Skeleton {
    match pose {
        PoseKind::Standing => {
            let leg = 0.45 * swing; // hip angle, rad
            let arm = -0.35 * swing;
            let hip = [v(0.0, 0.10, 0.92), v(0.0, -0.10, 0.92)];
            let thigh = 0.44;
            let shin = 0.42;
            let knee = |h: V3, a: f64| h + v(thigh * a.sin(), 0.0, -thigh * a.cos());
            let k = [knee(hip[0], leg), knee(hip[1], -leg)];
            let ankle = |k: V3, a: f64| k + v(shin * (a * 0.6).sin(), 0.0, -shin * (a * 0.6).cos());
            let shoulder = [v(0.0, 0.21, 1.43), v(0.0, -0.21, 1.43)];
            let elbow = |s: V3, a: f64| s + v(0.29 * a.sin(), 0.03_f64.copysign(s.y), -0.29 * a.cos());
            let e = [elbow(shoulder[0], arm), elbow(shoulder[1], -arm)];
            let wrist = |e: V3, a: f64| e + v(0.26 * (a + 0.2).sin(), 0.0, -0.26 * (a + 0.2).cos());
            Skeleton {
                head: v(0.0, 0.0, 1.63),
                neck: v(0.0, 0.0, 1.48),
                pelvis: v(0.0, 0.0, 0.95),
                shoulder,
                elbow: e,
                wrist: [wrist(e[0], arm), wrist(e[1], -arm)],
                hip,
                knee: k,
                ankle: [ankle(k[0], leg), ankle(k[1], -leg)],
            }
        }
        PoseKind::Sitting => Skeleton {
            head: v(-0.05, 0.0, 1.20),
            neck: v(-0.05, 0.0, 1.05),
            pelvis: v(-0.10, 0.0, 0.50),
            shoulder: [v(-0.05, 0.21, 1.00), v(-0.05, -0.21, 1.00)],
            elbow: [v(0.05, 0.25, 0.74), v(0.05, -0.25, 0.74)],
            wrist: [v(0.30, 0.20, 0.62), v(0.30, -0.20, 0.62)],
            hip: [v(-0.10, 0.10, 0.48), v(-0.10, -0.10, 0.48)],
            knee: [v(0.33, 0.11, 0.50), v(0.33, -0.11, 0.50)],
            ankle: [v(0.36, 0.11, 0.08), v(0.36, -0.11, 0.08)],
        },
        PoseKind::Crouching => Skeleton {
            head: v(0.15, 0.0, 0.98),
            neck: v(0.10, 0.0, 0.85),
            pelvis: v(-0.15, 0.0, 0.45),
            shoulder: [v(0.08, 0.21, 0.82), v(0.08, -0.21, 0.82)],
            elbow: [v(0.25, 0.26, 0.58), v(0.25, -0.26, 0.58)],
            wrist: [v(0.42, 0.20, 0.45), v(0.42, -0.20, 0.45)],
            hip: [v(-0.15, 0.11, 0.43), v(-0.15, -0.11, 0.43)],
            knee: [v(0.22, 0.16, 0.40), v(0.22, -0.16, 0.40)],
            ankle: [v(0.02, 0.13, 0.08), v(0.02, -0.13, 0.08)],
        },
        PoseKind::Lying => Skeleton {
            // On the back, head towards +x, body about 0.12 m off the floor at the pelvis.
            head: v(0.70, 0.0, 0.11),
            neck: v(0.55, 0.0, 0.12),
            pelvis: v(0.0, 0.0, 0.12),
            shoulder: [v(0.48, 0.21, 0.12), v(0.48, -0.21, 0.12)],
            elbow: [v(0.22, 0.30, 0.07), v(0.22, -0.30, 0.07)],
            wrist: [v(-0.02, 0.32, 0.06), v(-0.02, -0.32, 0.06)],
            hip: [v(-0.03, 0.10, 0.11), v(-0.03, -0.10, 0.11)],
            knee: [v(-0.47, 0.12, 0.12), v(-0.47, -0.12, 0.12)],
            ankle: [v(-0.89, 0.13, 0.08), v(-0.89, -0.13, 0.08)],
        },
    }
}

/// A person at one instant: capsules in the world frame, ready for ray casting.
#[derive(Clone, Debug)]
pub struct Body {
    pub label: u16,
    pub capsules: Vec<Capsule>,
    pub bounds: Aabb,
    /// The oriented box around the body: centre, size (length along the heading, width,
    /// height) and heading.
    pub box_centre: V3,
    pub box_size: V3,
    pub yaw_rad: f64,
}

impl Body {
    /// Poses a person of average build: `at` the frame origin on the floor, `yaw_rad` the heading.
    pub fn new(label: u16, pose: PoseKind, height_m: f64, at: V3, yaw_rad: f64, swing: f64) -> Self {
        Self::with_build(label, pose, height_m, 1.0, at, yaw_rad, swing)
    }

    /// As [`Body::new`], `build` times as wide (0.7 slight .. 1.4 heavy). A build of exactly 1
    /// multiplies by one, so it poses the same body, to the bit, as [`Body::new`] always did.
    pub fn with_build(label: u16, pose: PoseKind, height_m: f64, build: f64, at: V3, yaw_rad: f64, swing: f64) -> Self {
        let s = skeleton(pose, swing.clamp(-1.0, 1.0));
        let k = height_m / REFERENCE_HEIGHT_M;
        let (sin, cos) = yaw_rad.sin_cos();
        // y runs across the body in every pose (lying too: on the back, head along x).
        let place = |p: V3| {
            let y = p.y * build;
            at + V3::new(k * (cos * p.x - sin * y), k * (sin * p.x + cos * y), k * p.z)
        };
        let limb =
            |a: V3, b: V3, r: f64, albedo: f32| Capsule { a: place(a), b: place(b), radius: r * k * build, albedo };
        let torso_side = |y: f64| {
            let o = v(0.0, y, 0.0);
            limb(s.pelvis + o, s.neck + o - (s.neck - s.pelvis) * 0.08, 0.12, CLOTHING_ALBEDO)
        };
        let mut capsules = vec![
            limb(s.head, s.head, 0.105, SKIN_ALBEDO),
            limb(s.neck, s.head, 0.055, SKIN_ALBEDO),
            torso_side(0.08),
            torso_side(-0.08),
        ];
        for i in 0..2 {
            capsules.push(limb(s.shoulder[i], s.elbow[i], 0.05, CLOTHING_ALBEDO));
            capsules.push(limb(s.elbow[i], s.wrist[i], 0.04, SKIN_ALBEDO));
            capsules.push(limb(s.hip[i], s.knee[i], 0.075, CLOTHING_ALBEDO));
            capsules.push(limb(s.knee[i], s.ankle[i], 0.055, CLOTHING_ALBEDO));
        }
        let bounds = capsules.iter().fold(Aabb::EMPTY, |acc, c| acc.union(&c.aabb()));
        // The tight box in the person's own frame.
        let to_local = |p: V3| {
            let q = p - at;
            V3::new(cos * q.x + sin * q.y, -sin * q.x + cos * q.y, q.z)
        };
        let local = capsules.iter().fold(Aabb::EMPTY, |acc, c| {
            let r = V3::repeat(c.radius);
            let (a, b) = (to_local(c.a), to_local(c.b));
            acc.union(&Aabb { min: a.inf(&b) - r, max: a.sup(&b) + r })
        });
        let lc = local.centre();
        let box_centre = at + V3::new(cos * lc.x - sin * lc.y, sin * lc.x + cos * lc.y, lc.z);
        Self { label, capsules, bounds, box_centre, box_size: local.max - local.min, yaw_rad }
    }

    /// The nearest capsule hit before `t_max`.
    #[inline]
    pub fn cast(&self, o: &V3, d: &V3, inv_d: &V3, t_max: f64) -> Option<Hit> {
        self.bounds.enter(o, inv_d, t_max)?;
        let mut best: Option<Hit> = None;
        let mut limit = t_max;
        for c in &self.capsules {
            if let Some((t, normal)) = c.intersect(o, d, limit) {
                limit = t;
                best = Some(Hit { t, normal, albedo: c.albedo, label: self.label });
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_have_human_extents() {
        let at = V3::new(2.0, 3.0, 0.0);
        let standing = Body::new(1, PoseKind::Standing, 1.75, at, 0.3, 0.0);
        assert!((standing.bounds.max.z - 1.735).abs() < 0.02, "{:?}", standing.bounds);
        assert!(standing.bounds.min.z.abs() < 0.05);
        let tall = Body::new(1, PoseKind::Standing, 1.90, at, 0.0, 0.0);
        assert!((tall.bounds.max.z - 1.90 * 1.735 / 1.75).abs() < 0.02);
        let sitting = Body::new(1, PoseKind::Sitting, 1.75, at, 0.0, 0.0);
        assert!(sitting.box_size.z > 1.2 && sitting.box_size.z < 1.4, "{:?}", sitting.box_size);
        let crouching = Body::new(1, PoseKind::Crouching, 1.75, at, 0.0, 0.0);
        assert!(crouching.box_size.z > 0.95 && crouching.box_size.z < 1.15, "{:?}", crouching.box_size);
        let lying = Body::new(1, PoseKind::Lying, 1.75, at, 0.0, 0.0);
        assert!(lying.box_size.z < 0.35 && lying.box_size.x > 1.6, "{:?}", lying.box_size);
        // A stride moves the feet apart along the heading.
        let stride = Body::new(1, PoseKind::Standing, 1.75, V3::zeros(), 0.0, 1.0);
        assert!(stride.box_size.x > standing.box_size.x + 0.2);
    }

    #[test]
    fn build_scales_widths_not_height() {
        let at = V3::new(2.0, 3.0, 0.0);
        for pose in [PoseKind::Standing, PoseKind::Sitting, PoseKind::Crouching, PoseKind::Lying] {
            let base = Body::new(1, pose, 1.75, at, 0.4, 0.3);
            let same = Body::with_build(1, pose, 1.75, 1.0, at, 0.4, 0.3);
            assert_eq!(
                (&base.capsules, base.box_size, base.box_centre),
                (&same.capsules, same.box_size, same.box_centre)
            );
            let heavy = Body::with_build(1, pose, 1.75, 1.3, at, 0.4, 0.3);
            let slight = Body::with_build(1, pose, 1.75, 0.75, at, 0.4, 0.3);
            // Across the body (y): wider and narrower.
            assert!(heavy.box_size.y > base.box_size.y * 1.2 && slight.box_size.y < base.box_size.y * 0.8, "{pose:?}");
            for (b, r) in [(&heavy, 1.3), (&slight, 0.75)] {
                let radii = b.capsules.iter().zip(&base.capsules).all(|(c, d)| (c.radius - d.radius * r).abs() < 1e-12);
                assert!(radii, "{pose:?}");
            }
        }
        // Height: the head's top stays within its grown radius of where it was.
        let base = Body::new(1, PoseKind::Standing, 1.75, at, 0.0, 0.0);
        let heavy = Body::with_build(1, PoseKind::Standing, 1.75, 1.4, at, 0.0, 0.0);
        let head = |b: &Body| b.capsules[0].a.z;
        assert_eq!(head(&base), head(&heavy));
        assert!(heavy.bounds.max.z - base.bounds.max.z < 0.4 * 0.105 + 1e-9);
    }

    #[test]
    fn a_ray_at_the_chest_hits_the_person() {
        let body = Body::new(7, PoseKind::Standing, 1.75, V3::new(5.0, 0.0, 0.0), std::f64::consts::PI, 0.0);
        let d = V3::x();
        let hit = body.cast(&V3::new(0.0, 0.0, 1.2), &d, &d.map(|x| 1.0 / x), 100.0);
        let hit = hit.map(|h| (h.label, h.t));
        assert!(matches!(hit, Some((7, t)) if (t - 4.91).abs() < 0.01), "{hit:?}");
    }
}
