//! The solids every scene is made of, and their ray intersections: boxes turned about the
//! vertical (walls, floors, furniture, doors), vertical cylinders (pillars, poles, round tops) and
//! capsules (people's limbs, foliage; a sphere is a capsule of zero length). [`Solid`] is any of
//! them, as the building's BVH holds them.

use nalgebra::Vector3;

pub type V3 = Vector3<f64>;

/// What a ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray.
    pub t: f64,
    /// Unit surface normal facing the ray.
    pub normal: V3,
    pub albedo: f32,
    /// 0 for the building, k for person k.
    pub label: u16,
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: V3,
    pub max: V3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: V3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY),
        max: V3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY),
    };

    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.inf(&o.min), max: self.max.sup(&o.max) }
    }

    pub fn centre(&self) -> V3 {
        (self.min + self.max) * 0.5
    }

    /// Entry distance of a ray (`inv_d` = 1/d per axis) if it meets the box before `t_max`.
    #[inline]
    pub fn enter(&self, o: &V3, inv_d: &V3, t_max: f64) -> Option<f64> {
        let mut t0 = 0.0f64;
        let mut t1 = t_max;
        for a in 0..3 {
            let ta = (self.min[a] - o[a]) * inv_d[a];
            let tb = (self.max[a] - o[a]) * inv_d[a];
            let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
            // NaN (0 * inf on a face) must not widen the interval: compare so NaN loses.
            if lo > t0 {
                t0 = lo;
            }
            if hi < t1 {
                t1 = hi;
            }
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }
}

/// A box turned by `yaw` about the vertical through its centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawBox {
    pub centre: V3,
    pub half: V3,
    cos: f64,
    sin: f64,
    pub albedo: f32,
    /// Turned by a multiple of 90 deg: tested in world axes (`world_half`), without a rotation.
    aligned: bool,
    world_half: V3,
}

impl YawBox {
    pub fn new(centre: V3, size: V3, yaw_rad: f64, albedo: f32) -> Self {
        let (sin, cos) = yaw_rad.sin_cos();
        let half = size * 0.5;
        let aligned = sin.abs() < 1e-12 || cos.abs() < 1e-12;
        let world_half = if cos.abs() < 1e-12 { V3::new(half.y, half.x, half.z) } else { half };
        Self { centre, half, cos, sin, albedo, aligned, world_half }
    }

    pub fn yaw_rad(&self) -> f64 {
        self.sin.atan2(self.cos)
    }

    pub fn aabb(&self) -> Aabb {
        let ex = (self.half.x * self.cos).abs() + (self.half.y * self.sin).abs();
        let ey = (self.half.x * self.sin).abs() + (self.half.y * self.cos).abs();
        let e = V3::new(ex, ey, self.half.z);
        Aabb { min: self.centre - e, max: self.centre + e }
    }

    fn local_of(&self, v: &V3) -> V3 {
        V3::new(self.cos * v.x + self.sin * v.y, -self.sin * v.x + self.cos * v.y, v.z)
    }

    fn world_of(&self, v: &V3) -> V3 {
        V3::new(self.cos * v.x - self.sin * v.y, self.sin * v.x + self.cos * v.y, v.z)
    }

    /// As [`YawBox::intersect`], with the ray's reciprocal direction at hand (`inv_d` = 1/d):
    /// boxes along the world axes need no rotation and no division.
    #[inline]
    pub fn intersect_inv(&self, o: &V3, d: &V3, inv_d: &V3, t_max: f64) -> Option<(f64, V3)> {
        if !self.aligned {
            return self.intersect(o, d, t_max);
        }
        let mut t0 = f64::NEG_INFINITY;
        let mut t1 = t_max;
        let mut axis = 0usize;
        for a in 0..3 {
            let lo = self.centre[a] - self.world_half[a] - o[a];
            let hi = self.centre[a] + self.world_half[a] - o[a];
            if d[a].abs() < 1e-15 {
                if lo > 0.0 || hi < 0.0 {
                    return None;
                }
                continue;
            }
            let (ta, tb) = (lo * inv_d[a], hi * inv_d[a]);
            let (near, far) = if ta < tb { (ta, tb) } else { (tb, ta) };
            if near > t0 {
                t0 = near;
                axis = a;
            }
            if far < t1 {
                t1 = far;
            }
            if t0 > t1 {
                return None;
            }
        }
        if t0 <= 1e-9 {
            return None;
        }
        let mut n = V3::zeros();
        n[axis] = -d[axis].signum();
        Some((t0, n))
    }

    /// Nearest entry of a ray from outside the box, before `t_max`.
    #[inline]
    pub fn intersect(&self, o: &V3, d: &V3, t_max: f64) -> Option<(f64, V3)> {
        let lo = self.local_of(&(o - self.centre));
        let ld = self.local_of(d);
        let mut t0 = f64::NEG_INFINITY;
        let mut t1 = t_max;
        let mut axis = 0usize;
        for a in 0..3 {
            if ld[a].abs() < 1e-15 {
                if lo[a].abs() > self.half[a] {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / ld[a];
            let ta = (-self.half[a] - lo[a]) * inv;
            let tb = (self.half[a] - lo[a]) * inv;
            let (near, far) = if ta < tb { (ta, tb) } else { (tb, ta) };
            if near > t0 {
                t0 = near;
                axis = a;
            }
            t1 = t1.min(far);
            if t0 > t1 {
                return None;
            }
        }
        // A ray starting inside (t0 <= 0) sees no surface of this box.
        if t0 <= 1e-9 {
            return None;
        }
        let mut n = V3::zeros();
        n[axis] = -ld[axis].signum();
        Some((t0, self.world_of(&n)))
    }
}

/// A capsule: all points within `radius` of the segment `a`-`b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    pub a: V3,
    pub b: V3,
    pub radius: f64,
    pub albedo: f32,
}

impl Capsule {
    pub fn aabb(&self) -> Aabb {
        let r = V3::repeat(self.radius);
        Aabb { min: self.a.inf(&self.b) - r, max: self.a.sup(&self.b) + r }
    }

    /// Nearest entry of a unit ray before `t_max`.
    #[inline]
    pub fn intersect(&self, o: &V3, d: &V3, t_max: f64) -> Option<(f64, V3)> {
        let ba = self.b - self.a;
        let oa = o - self.a;
        let baba = ba.dot(&ba);
        let bard = ba.dot(d);
        let baoa = ba.dot(&oa);
        let rdoa = d.dot(&oa);
        let oaoa = oa.dot(&oa);
        let r2 = self.radius * self.radius;
        let mut best: Option<f64> = None;
        if baba > 1e-18 {
            // The cylinder's side.
            let a = baba - bard * bard;
            let b = baba * rdoa - baoa * bard;
            let c = baba * oaoa - baoa * baoa - r2 * baba;
            let h = b * b - a * c;
            if a > 1e-18 && h >= 0.0 {
                let t = (-b - h.sqrt()) / a;
                let y = baoa + t * bard;
                if t > 1e-9 && y > 0.0 && y < baba {
                    best = Some(t);
                }
            }
        }
        if best.is_none() {
            // The end caps (spheres at a and b).
            for centre in [self.a, self.b] {
                let oc = o - centre;
                let b = oc.dot(d);
                let c = oc.dot(&oc) - r2;
                let h = b * b - c;
                if h >= 0.0 {
                    let t = -b - h.sqrt();
                    if t > 1e-9 && best.is_none_or(|bt| t < bt) {
                        best = Some(t);
                    }
                }
            }
        }
        let t = best.filter(|&t| t < t_max)?;
        let p = o + d * t;
        let s = if baba > 1e-18 { ((p - self.a).dot(&ba) / baba).clamp(0.0, 1.0) } else { 0.0 };
        let n = (p - (self.a + ba * s)).try_normalize(1e-12).unwrap_or(-d);
        Some((t, n))
    }
}

/// A vertical cylinder: all points within `radius_m` of the axis through (`x_m`, `y_m`), between
/// the heights `z0_m` and `z1_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cylinder {
    pub x_m: f64,
    pub y_m: f64,
    pub z0_m: f64,
    pub z1_m: f64,
    pub radius_m: f64,
    pub albedo: f32,
}

impl Cylinder {
    pub fn aabb(&self) -> Aabb {
        let r = self.radius_m;
        Aabb {
            min: V3::new(self.x_m - r, self.y_m - r, self.z0_m),
            max: V3::new(self.x_m + r, self.y_m + r, self.z1_m),
        }
    }

    /// The ray's parameter interval inside the infinite vertical cylinder, or none.
    fn side_interval(&self, o: &V3, d: &V3) -> Option<(f64, f64)> {
        let (px, py) = (o.x - self.x_m, o.y - self.y_m);
        let a = d.x * d.x + d.y * d.y;
        let b = px * d.x + py * d.y;
        let c = px * px + py * py - self.radius_m * self.radius_m;
        if a < 1e-18 {
            // Parallel to the axis: inside for all t, or never.
            return (c <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY));
        }
        let h = b * b - a * c;
        if h < 0.0 {
            return None;
        }
        let s = h.sqrt();
        Some(((-b - s) / a, (-b + s) / a))
    }

    /// The ray's parameter interval between the two cap planes, or none.
    fn slab_interval(&self, o: &V3, d: &V3) -> Option<(f64, f64)> {
        if d.z.abs() < 1e-15 {
            let inside = o.z >= self.z0_m && o.z <= self.z1_m;
            return inside.then_some((f64::NEG_INFINITY, f64::INFINITY));
        }
        let (ta, tb) = ((self.z0_m - o.z) / d.z, (self.z1_m - o.z) / d.z);
        Some(if ta < tb { (ta, tb) } else { (tb, ta) })
    }

    /// Nearest entry of a unit ray from outside the cylinder, before `t_max` (the conventions of
    /// [`YawBox::intersect`]: a ray starting inside sees nothing, the normal faces the ray).
    #[inline]
    pub fn intersect(&self, o: &V3, d: &V3, t_max: f64) -> Option<(f64, V3)> {
        let (s0, s1) = self.side_interval(o, d)?;
        let (z0, z1) = self.slab_interval(o, d)?;
        let t0 = s0.max(z0);
        let t1 = s1.min(z1).min(t_max);
        if t0 > t1 || t0 <= 1e-9 {
            return None;
        }
        if s0 >= z0 {
            let p = o + d * t0;
            let n = V3::new(p.x - self.x_m, p.y - self.y_m, 0.0);
            return Some((t0, n.try_normalize(1e-12).unwrap_or(-d)));
        }
        Some((t0, V3::new(0.0, 0.0, -d.z.signum())))
    }
}

/// Any solid of the building, as its BVH holds them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solid {
    Box(YawBox),
    Cylinder(Cylinder),
    /// A capsule, or a sphere when its ends coincide.
    Capsule(Capsule),
}

impl From<YawBox> for Solid {
    fn from(b: YawBox) -> Self {
        Solid::Box(b)
    }
}

impl From<Cylinder> for Solid {
    fn from(c: Cylinder) -> Self {
        Solid::Cylinder(c)
    }
}

impl From<Capsule> for Solid {
    fn from(c: Capsule) -> Self {
        Solid::Capsule(c)
    }
}

impl Solid {
    pub fn aabb(&self) -> Aabb {
        match self {
            Solid::Box(b) => b.aabb(),
            Solid::Cylinder(c) => c.aabb(),
            Solid::Capsule(c) => c.aabb(),
        }
    }

    pub fn albedo(&self) -> f32 {
        match self {
            Solid::Box(b) => b.albedo,
            Solid::Cylinder(c) => c.albedo,
            Solid::Capsule(c) => c.albedo,
        }
    }

    /// Nearest entry of a unit ray before `t_max` (`inv_d` = 1/d, used by boxes along the axes).
    #[inline]
    pub fn intersect_inv(&self, o: &V3, d: &V3, inv_d: &V3, t_max: f64) -> Option<(f64, V3)> {
        match self {
            Solid::Box(b) => b.intersect_inv(o, d, inv_d, t_max),
            Solid::Cylinder(c) => c.intersect(o, d, t_max),
            Solid::Capsule(c) => c.intersect(o, d, t_max),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_hits_from_every_side_and_turned() {
        let b = YawBox::new(V3::new(5.0, 0.0, 1.0), V3::new(2.0, 1.0, 2.0), 0.0, 0.5);
        let (t, n) = b.intersect(&V3::new(0.0, 0.0, 1.0), &V3::x(), 100.0).unwrap_or_default();
        assert!((t - 4.0).abs() < 1e-9 && (n - V3::new(-1.0, 0.0, 0.0)).norm() < 1e-9);
        assert!(b.intersect(&V3::new(0.0, 0.0, 1.0), &V3::x(), 3.9).is_none());
        assert!(b.intersect(&V3::new(0.0, 2.0, 1.0), &V3::x(), 100.0).is_none());
        // Turned 90 deg: 1 m long along y now, 2 m wide along x... the near face is at x = 4.5.
        let b = YawBox::new(V3::new(5.0, 0.0, 1.0), V3::new(2.0, 1.0, 2.0), std::f64::consts::FRAC_PI_2, 0.5);
        let (t, _) = b.intersect(&V3::new(0.0, 0.0, 1.0), &V3::x(), 100.0).unwrap_or_default();
        assert!((t - 4.5).abs() < 1e-9, "{t}");
        let bb = b.aabb();
        assert!((bb.min.x - 4.5).abs() < 1e-9 && (bb.max.y - 1.0).abs() < 1e-9);
        // From inside: no hit.
        assert!(b.intersect(&V3::new(5.0, 0.0, 1.0), &V3::x(), 100.0).is_none());
    }

    #[test]
    fn the_aligned_path_agrees_with_the_general_one() {
        let mut rng = crate::rng::SplitMix64::new(4);
        for yaw in [0.0, std::f64::consts::FRAC_PI_2, std::f64::consts::PI, -std::f64::consts::FRAC_PI_2] {
            let b = YawBox::new(V3::new(3.0, 1.0, 1.0), V3::new(2.0, 0.5, 1.5), yaw, 0.5);
            for _ in 0..2000 {
                let o = V3::new(rng.next_f64() * 2.0 - 1.0, rng.next_f64() * 2.0 - 1.0, rng.next_f64() * 2.0);
                let d = V3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
                let inv = d.map(|v| 1.0 / v);
                let (a, g) = (b.intersect_inv(&o, &d, &inv, 50.0), b.intersect(&o, &d, 50.0));
                match (a, g) {
                    (Some((ta, na)), Some((tg, ng))) => assert!((ta - tg).abs() < 1e-9 && (na - ng).norm() < 1e-9),
                    (None, None) => {}
                    other => panic!("{other:?}"),
                }
            }
        }
    }

    #[test]
    fn capsule_side_and_caps() {
        let c = Capsule { a: V3::new(3.0, 0.0, 0.0), b: V3::new(3.0, 0.0, 2.0), radius: 0.5, albedo: 0.3 };
        let (t, n) = c.intersect(&V3::new(0.0, 0.0, 1.0), &V3::x(), 100.0).unwrap_or_default();
        assert!((t - 2.5).abs() < 1e-9 && (n + V3::x()).norm() < 1e-9);
        let (t, n) = c.intersect(&V3::new(3.0, 0.0, 5.0), &-V3::z(), 100.0).unwrap_or_default();
        assert!((t - 2.5).abs() < 1e-9 && (n - V3::z()).norm() < 1e-9);
        assert!(c.intersect(&V3::new(0.0, 0.6, 1.0), &V3::x(), 100.0).is_none());
        let sphere = Capsule { a: V3::new(2.0, 0.0, 0.0), b: V3::new(2.0, 0.0, 0.0), radius: 1.0, albedo: 0.3 };
        let (t, _) = sphere.intersect(&V3::zeros(), &V3::x(), 100.0).unwrap_or_default();
        assert!((t - 1.0).abs() < 1e-9);
    }

    #[test]
    fn aabb_entry() {
        let b = Aabb { min: V3::new(1.0, -1.0, -1.0), max: V3::new(2.0, 1.0, 1.0) };
        let d = V3::x();
        let inv = d.map(|v| 1.0 / v);
        assert_eq!(b.enter(&V3::zeros(), &inv, 10.0), Some(1.0));
        assert_eq!(b.enter(&V3::zeros(), &inv, 0.5), None);
        assert_eq!(b.enter(&V3::new(0.0, 2.0, 0.0), &inv, 10.0), None);
    }
    fn pillar() -> Cylinder {
        Cylinder { x_m: 4.0, y_m: 1.0, z0_m: 0.5, z1_m: 2.5, radius_m: 0.5, albedo: 0.35 }
    }

    #[test]
    fn cylinder_side_and_caps() {
        let c = pillar();
        let (t, n) = c.intersect(&V3::new(0.0, 1.0, 1.0), &V3::x(), 100.0).unwrap_or_default();
        assert!((t - 3.5).abs() < 1e-12 && (n + V3::x()).norm() < 1e-12, "{t} {n:?}");
        assert!(c.intersect(&V3::new(0.0, 1.0, 1.0), &V3::x(), 3.4).is_none());
        // Off the axis by 0.3 m: the chord starts sqrt(0.25 - 0.09) = 0.4 m before the axis.
        let (t, n) = c.intersect(&V3::new(0.0, 1.3, 1.0), &V3::x(), 100.0).unwrap_or_default();
        assert!((t - 3.6).abs() < 1e-12 && (n - V3::new(-0.8, 0.6, 0.0)).norm() < 1e-12, "{t} {n:?}");
        assert!(c.intersect(&V3::new(0.0, 1.51, 1.0), &V3::x(), 100.0).is_none());
        // Down onto the top cap, up onto the bottom one, and past both ends.
        let (t, n) = c.intersect(&V3::new(4.2, 1.0, 5.0), &-V3::z(), 100.0).unwrap_or_default();
        assert!((t - 2.5).abs() < 1e-12 && (n - V3::z()).norm() < 1e-12, "{t} {n:?}");
        let (t, n) = c.intersect(&V3::new(4.2, 1.0, 0.0), &V3::z(), 100.0).unwrap_or_default();
        assert!((t - 0.5).abs() < 1e-12 && (n + V3::z()).norm() < 1e-12, "{t} {n:?}");
        assert!(c.intersect(&V3::new(0.0, 1.0, 2.6), &V3::x(), 100.0).is_none());
        assert!(c.intersect(&V3::new(0.0, 1.0, 0.4), &V3::x(), 100.0).is_none());
        // Slanting down: it crosses the side's surface above the top, so it enters through the cap.
        let d = V3::new(1.0, 0.0, -1.0).normalize();
        let (t, n) = c.intersect(&V3::new(2.0, 1.0, 4.5), &d, 100.0).unwrap_or_default();
        assert!((t - 2.0 * 2f64.sqrt()).abs() < 1e-12 && (n - V3::z()).norm() < 1e-12, "{t} {n:?}");
        let bb = c.aabb();
        assert!(bb.min == V3::new(3.5, 0.5, 0.5) && bb.max == V3::new(4.5, 1.5, 2.5));
    }

    #[test]
    fn cylinder_is_not_seen_from_inside() {
        let c = pillar();
        for d in [V3::x(), -V3::x(), V3::z(), -V3::z(), V3::new(1.0, 1.0, 1.0).normalize()] {
            assert!(c.intersect(&V3::new(4.1, 1.1, 1.5), &d, 100.0).is_none(), "{d:?}");
        }
    }

    fn inside_cylinder(c: &Cylinder, p: &V3) -> bool {
        (p.x - c.x_m).hypot(p.y - c.y_m) <= c.radius_m && p.z >= c.z0_m && p.z <= c.z1_m
    }

    /// Agrees with marching along the ray: the first sample inside is just past the analytic
    /// entry, the hit lies on the surface, and a ray with no analytic hit has no sample inside.
    #[test]
    fn cylinder_agrees_with_sampling() {
        let c = pillar();
        let mut rng = crate::rng::SplitMix64::new(11);
        let step = 1e-3;
        let mut hits = 0;
        for _ in 0..400 {
            let o = V3::new(rng.next_f64() * 8.0, rng.next_f64() * 4.0 - 1.0, rng.next_f64() * 3.0);
            let d = (V3::new(4.0, 1.0, 1.5) + V3::new(rng.normal(), rng.normal(), rng.normal()) * 0.6 - o)
                .try_normalize(1e-9)
                .unwrap_or(V3::x());
            let first = (1..8000).map(|i| f64::from(i) * step).find(|&t| inside_cylinder(&c, &(o + d * t)));
            match (c.intersect(&o, &d, 8.0), first) {
                (Some((t, n)), Some(ts)) => {
                    hits += 1;
                    assert!(t <= ts + 1e-12 && ts - t <= step + 1e-12, "{t} {ts}");
                    let p = o + d * t;
                    let radial = (p.x - c.x_m).hypot(p.y - c.y_m);
                    let on_side = (radial - c.radius_m).abs() < 1e-9;
                    let on_cap = (p.z - c.z0_m).abs() < 1e-9 || (p.z - c.z1_m).abs() < 1e-9;
                    assert!((on_side || on_cap) && n.dot(&d) < 0.0, "{p:?} {n:?}");
                }
                // A grazing chord may be thinner than a step.
                (Some((t, _)), None) => assert!(!inside_cylinder(&c, &(o + d * (t + 2.0 * step)))),
                (None, Some(ts)) if inside_cylinder(&c, &o) => assert!(ts <= step * 1.5),
                (None, Some(ts)) => panic!("sampled inside at {ts} but no hit: {o:?} {d:?}"),
                (None, None) => {}
            }
        }
        assert!(hits > 100, "{hits}");
    }

    #[test]
    fn solids_dispatch() {
        let d = V3::x();
        let inv = d.map(|v| 1.0 / v);
        let o = V3::new(0.0, 1.0, 1.0);
        let b = YawBox::new(V3::new(4.0, 1.0, 1.0), V3::new(1.0, 1.0, 1.0), 0.0, 0.7);
        let cap = Capsule { a: V3::new(4.0, 1.0, 1.0), b: V3::new(4.0, 1.0, 1.0), radius: 0.25, albedo: 0.2 };
        let solids = [Solid::from(b), Solid::from(pillar()), Solid::from(cap)];
        let ts: Vec<f64> = solids.iter().filter_map(|s| s.intersect_inv(&o, &d, &inv, 100.0)).map(|h| h.0).collect();
        assert_eq!(ts.len(), 3);
        assert!((ts[0] - 3.5).abs() < 1e-12 && (ts[1] - 3.5).abs() < 1e-12 && (ts[2] - 3.75).abs() < 1e-12);
        assert_eq!(solids.map(|s| s.albedo()), [0.7, 0.35, 0.2]);
        assert_eq!(solids[0].aabb(), b.aabb());
    }
}
