//! A bounding-volume hierarchy over the building's solids: the ray caster's index.

use crate::sim::shapes::{Aabb, Hit, Solid, YawBox, V3};

const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first item and count; inner: left child index (right is `first + 1`... see build).
    first: u32,
    count: u32,
    right: u32,
}

/// A static BVH of solids (median split on the widest axis of the centroids).
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    solids: Vec<Solid>,
}

impl Bvh {
    /// Builds over boxes, cylinders, capsules or [`Solid`]s alike. The tree depends only on the
    /// solids' bounds and order, so a list of boxes gives the tree (and the hits) it always did.
    pub fn build<S: Into<Solid>>(solids: impl IntoIterator<Item = S>) -> Self {
        let mut solids: Vec<Solid> = solids.into_iter().map(Into::into).collect();
        let mut nodes = Vec::with_capacity(2 * solids.len() / LEAF_SIZE + 1);
        if !solids.is_empty() {
            let n = solids.len();
            build_node(&mut solids, 0, n, &mut nodes);
        }
        Self { nodes, solids }
    }

    pub fn len(&self) -> usize {
        self.solids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.solids.is_empty()
    }

    /// Every solid, in the tree's order.
    pub fn solids(&self) -> &[Solid] {
        &self.solids
    }

    /// The boxes among the solids, in the tree's order.
    pub fn boxes(&self) -> impl Iterator<Item = &YawBox> + '_ {
        self.solids.iter().filter_map(|s| match s {
            Solid::Box(b) => Some(b),
            _ => None,
        })
    }

    /// The nearest solid hit by the unit ray before `t_max`.
    pub fn cast(&self, o: &V3, d: &V3, t_max: f64) -> Option<Hit> {
        self.cast_inv(o, d, &d.map(|v| 1.0 / v), t_max)
    }

    /// As [`Bvh::cast`], with the ray's reciprocal direction (`inv` = 1/d) already at hand.
    pub fn cast_inv(&self, o: &V3, d: &V3, inv: &V3, t_max: f64) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: Option<Hit> = None;
        let mut limit = t_max;
        // (node, its entry distance): a node is skipped when a nearer hit was found meanwhile.
        let mut stack = [(0u32, 0.0f64); 64];
        let mut top = 0usize;
        if let Some(root) = self.nodes.first() {
            if let Some(t) = root.bounds.enter(o, inv, limit) {
                stack[0] = (0, t);
                top = 1;
            }
        }
        while top > 0 {
            top -= 1;
            let (index, t_enter) = stack[top];
            if t_enter > limit {
                continue;
            }
            let Some(node) = self.nodes.get(index as usize) else { continue };
            if node.count > 0 {
                let (a, b) = (node.first as usize, (node.first + node.count) as usize);
                for solid in self.solids.get(a..b).unwrap_or(&[]) {
                    if let Some((t, normal)) = solid.intersect_inv(o, d, inv, limit) {
                        limit = t;
                        best = Some(Hit { t, normal, albedo: solid.albedo(), label: 0 });
                    }
                }
            } else if top + 2 <= stack.len() {
                let enter = |i: u32| self.nodes.get(i as usize).and_then(|n| n.bounds.enter(o, inv, limit));
                let (l, r) = (node.first, node.right);
                match (enter(l), enter(r)) {
                    (Some(tl), Some(tr)) => {
                        // The nearer child on top, so the far one is usually culled.
                        let (near, far) = if tl <= tr { ((l, tl), (r, tr)) } else { ((r, tr), (l, tl)) };
                        stack[top] = far;
                        stack[top + 1] = near;
                        top += 2;
                    }
                    (Some(t), None) => {
                        stack[top] = (l, t);
                        top += 1;
                    }
                    (None, Some(t)) => {
                        stack[top] = (r, t);
                        top += 1;
                    }
                    (None, None) => {}
                }
            }
        }
        best
    }
}

fn build_node(solids: &mut [Solid], start: usize, end: usize, nodes: &mut Vec<Node>) -> u32 {
    let index = nodes.len() as u32;
    let bounds = solids[start..end].iter().fold(Aabb::EMPTY, |acc, b| acc.union(&b.aabb()));
    nodes.push(Node { bounds, first: start as u32, count: (end - start) as u32, right: 0 });
    if end - start <= LEAF_SIZE {
        return index;
    }
    let centres = solids[start..end].iter().fold(Aabb::EMPTY, |acc, b| {
        let c = b.aabb().centre();
        acc.union(&Aabb { min: c, max: c })
    });
    let extent = centres.max - centres.min;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = (start + end) / 2;
    solids[start..end]
        .select_nth_unstable_by(mid - start, |a, b| a.aabb().centre()[axis].total_cmp(&b.aabb().centre()[axis]));
    let left = build_node(solids, start, mid, nodes);
    let right = build_node(solids, mid, end, nodes);
    if let Some(n) = nodes.get_mut(index as usize) {
        n.count = 0;
        n.first = left;
        n.right = right;
    }
    index
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::sim::shapes::{Capsule, Cylinder};

    /// The BVH finds exactly what testing every box finds.
    #[test]
    fn same_as_brute_force() {
        let mut rng = SplitMix64::new(7);
        let mut boxes = Vec::new();
        for _ in 0..300 {
            let c = V3::new(rng.next_f64() * 40.0 - 20.0, rng.next_f64() * 40.0 - 20.0, rng.next_f64() * 3.0);
            let s = V3::new(0.1 + rng.next_f64() * 2.0, 0.1 + rng.next_f64() * 2.0, 0.1 + rng.next_f64() * 2.0);
            boxes.push(YawBox::new(c, s, rng.next_f64() * std::f64::consts::TAU, 0.5));
        }
        let bvh = Bvh::build(boxes.clone());
        for _ in 0..5000 {
            let o = V3::new(rng.next_f64() * 10.0 - 5.0, rng.next_f64() * 10.0 - 5.0, 1.0);
            let d = V3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
            let brute =
                boxes.iter().filter_map(|b| b.intersect(&o, &d, 100.0)).map(|(t, _)| t).fold(f64::INFINITY, f64::min);
            let fast = bvh.cast(&o, &d, 100.0).map_or(f64::INFINITY, |h| h.t);
            assert!((brute - fast).abs() < 1e-9 || (brute.is_infinite() && fast.is_infinite()), "{brute} {fast}");
        }
    }
    /// Mixed solids: the BVH finds the same nearest hit (distance and normal) as testing each.
    #[test]
    fn mixed_solids_same_as_brute_force() {
        let mut rng = SplitMix64::new(9);
        let mut solids: Vec<Solid> = Vec::new();
        for i in 0..400 {
            let c = V3::new(rng.next_f64() * 40.0 - 20.0, rng.next_f64() * 40.0 - 20.0, rng.next_f64() * 3.0);
            let mut len = || 0.05 + rng.next_f64() * 1.5;
            let (a, b, h) = (len(), len(), len());
            solids.push(match i % 4 {
                0 => YawBox::new(c, V3::new(a, b, h), rng.next_f64() * std::f64::consts::TAU, 0.5).into(),
                1 => Cylinder { x_m: c.x, y_m: c.y, z0_m: c.z, z1_m: c.z + h, radius_m: a / 2.0, albedo: 0.4 }.into(),
                2 => Capsule { a: c, b: c + V3::new(b, -a, h) * 0.5, radius: a / 3.0, albedo: 0.3 }.into(),
                _ => Capsule { a: c, b: c, radius: a / 2.0, albedo: 0.2 }.into(),
            });
        }
        let bvh = Bvh::build(solids.clone());
        assert_eq!(bvh.len(), 400);
        assert_eq!(bvh.boxes().count(), 100);
        for _ in 0..5000 {
            let o = V3::new(rng.next_f64() * 10.0 - 5.0, rng.next_f64() * 10.0 - 5.0, 1.0);
            let d = V3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
            let inv = d.map(|v| 1.0 / v);
            let brute = solids
                .iter()
                .filter_map(|s| s.intersect_inv(&o, &d, &inv, 100.0).map(|(t, n)| (t, n, s.albedo())))
                .min_by(|p, q| p.0.total_cmp(&q.0));
            let fast = bvh.cast(&o, &d, 100.0);
            match (brute, fast) {
                (Some((t, n, albedo)), Some(h)) => {
                    assert!((t - h.t).abs() < 1e-9 && (n - h.normal).norm() < 1e-6, "{t} {h:?}");
                    assert!(albedo == h.albedo || (t - h.t).abs() < 1e-12);
                }
                (None, None) => {}
                other => panic!("{other:?}"),
            }
        }
    }
    /// The tree over boxes must stay the one built when the BVH held bare `YawBox`es: the
    /// standard library's selection picks its partition scheme by the element's size, so a
    /// `Solid` as large as a `YawBox` sorts boxes exactly as before (the enum's tag lives in a
    /// spare bit pattern of the box's `bool`).
    #[test]
    fn a_solid_is_the_size_of_a_box() {
        assert_eq!(std::mem::size_of::<Solid>(), std::mem::size_of::<YawBox>());
    }
}
