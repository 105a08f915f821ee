//! A seeded uniform generator (no dependency for it): tests that scatter points, and the
//! alignment's global stage, whose samples must repeat for a rerun to be byte-identical.

/// Uniform numbers in [0, 1) from `seed` (a 64-bit LCG, top 53 bits): the same for a seed.
pub fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}
