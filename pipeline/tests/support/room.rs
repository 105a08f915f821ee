//! A synthetic room for the learned detector's tests and bench.

/// A room seen from its middle: floor, two walls, a table top, a standing and a lying person,
/// and scattered clutter, in the model frame (deterministic).
pub fn room() -> Vec<[f32; 3]> {
    let mut uniform = starc_pipeline::rng::uniform(7);
    let mut next = move || uniform() as f32;
    let mut pts = Vec::new();
    for _ in 0..20_000 {
        pts.push([next() * 9.0, next() * 10.0 - 5.0, 0.01 * (next() - 0.5)]);
    }
    for _ in 0..8_000 {
        pts.push([9.0 + 0.02 * next(), next() * 10.0 - 5.0, next() * 2.6]);
        pts.push([next() * 9.0, 5.0 + 0.02 * next(), next() * 2.6]);
    }
    for _ in 0..2_000 {
        pts.push([3.0 + next() * 1.6, -2.0 + next() * 0.8, 0.75 + 0.01 * next()]);
    }
    for _ in 0..1_500 {
        let a = next() * std::f32::consts::TAU;
        pts.push([5.0 + 0.2 * a.cos(), 1.0 + 0.15 * a.sin(), next() * 1.75]);
        pts.push([2.0 + next() * 1.7, 3.0 + 0.2 * a.sin(), 0.12 + 0.1 * a.cos()]);
    }
    for _ in 0..1_000 {
        pts.push([next() * 20.0, next() * 20.0 - 10.0, next() * 3.0 - 0.3]);
    }
    pts
}
