//! A bounding-volume hierarchy over the building's boxes: the ray caster's index.

use crate::sim::shapes::{Aabb, Hit, YawBox, V3};

const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first item and count; inner: left child index (right is `first + 1`... see build).
    first: u32,
    count: u32,
    right: u32,
}

/// A static BVH of boxes (median split on the widest axis of the centroids).
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    boxes: Vec<YawBox>,
}

impl Bvh {
    pub fn build(mut boxes: Vec<YawBox>) -> Self {
        let mut nodes = Vec::with_capacity(2 * boxes.len() / LEAF_SIZE + 1);
        if !boxes.is_empty() {
            let n = boxes.len();
            build_node(&mut boxes, 0, n, &mut nodes);
        }
        Self { nodes, boxes }
    }

    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    pub fn boxes(&self) -> &[YawBox] {
        &self.boxes
    }

    /// The nearest box hit by the unit ray before `t_max`.
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
                for bx in self.boxes.get(a..b).unwrap_or(&[]) {
                    if let Some((t, normal)) = bx.intersect_inv(o, d, inv, limit) {
                        limit = t;
                        best = Some(Hit { t, normal, albedo: bx.albedo, label: 0 });
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

fn build_node(boxes: &mut [YawBox], start: usize, end: usize, nodes: &mut Vec<Node>) -> u32 {
    let index = nodes.len() as u32;
    let bounds = boxes[start..end].iter().fold(Aabb::EMPTY, |acc, b| acc.union(&b.aabb()));
    nodes.push(Node { bounds, first: start as u32, count: (end - start) as u32, right: 0 });
    if end - start <= LEAF_SIZE {
        return index;
    }
    let centres = boxes[start..end].iter().fold(Aabb::EMPTY, |acc, b| {
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
    boxes[start..end]
        .select_nth_unstable_by(mid - start, |a, b| a.aabb().centre()[axis].total_cmp(&b.aabb().centre()[axis]));
    let left = build_node(boxes, start, mid, nodes);
    let right = build_node(boxes, mid, end, nodes);
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
}
