//! A first-order motor: the speed approaches its steady state with time constant `tau_s`.

/// First-order lag.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstOrder {
    pub value: f64,
    pub tau_s: f64,
}

impl FirstOrder {
    pub fn new(tau_s: f64) -> Self {
        Self { value: 0.0, tau_s: tau_s.max(1e-4) }
    }

    /// Moves toward `target` for `dt_s` seconds (exact for a constant target).
    pub fn step(&mut self, target: f64, dt_s: f64) -> f64 {
        let k = 1.0 - (-dt_s.max(0.0) / self.tau_s).exp();
        self.value += (target - self.value) * k;
        self.value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reaches_63_percent_in_one_tau() {
        let mut m = FirstOrder::new(0.05);
        for _ in 0..50 {
            m.step(10.0, 0.001);
        }
        assert!((m.value - 10.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-9, "{}", m.value);
    }
}
