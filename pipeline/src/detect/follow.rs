//! The people the detector follows between windows: its full confirmations of the last
//! 2 x `follow_s`, chained into one track per person.
//!
//! A track is judged by where its newest confirmation puts the person now, moved on at the
//! track's own velocity: a cluster near where someone was confirmed a second ago, but far from
//! where they were confirmed since, is not them (a walker leaves behind the furniture they
//! passed), and a person sitting still is not followed to a table edge a metre away.

use nalgebra::Vector2;

/// One person's confirmations, chained newest to oldest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Track {
    /// Where and when (window stamp) they were last confirmed.
    pub at: Vector2<f64>,
    pub t_ns: u64,
    /// That newest confirmation's index in the slice the track was chained from.
    pub newest: usize,
    /// The oldest confirmation chained so far (where the next older one must lie near).
    tail: Vector2<f64>,
    tail_ns: u64,
    pub confirmations: usize,
}

/// Chains `confirmed` (position, stamp) into tracks: a confirmation belongs to the track whose
/// oldest confirmation so far lies within `radius_m` plus a walk at `walk_mps` over the time
/// between them (the nearest such track), else it starts one.
pub fn tracks(confirmed: &[(Vector2<f64>, u64)], radius_m: f64, walk_mps: f64) -> Vec<Track> {
    let mut newest_first: Vec<(usize, &(Vector2<f64>, u64))> = confirmed.iter().enumerate().collect();
    newest_first.sort_by_key(|(_, c)| std::cmp::Reverse(c.1));
    let mut out: Vec<Track> = Vec::new();
    for &(index, &(at, t_ns)) in &newest_first {
        let reach = |tr: &Track| radius_m + walk_mps * tr.tail_ns.saturating_sub(t_ns) as f64 * 1e-9;
        let nearest = out
            .iter_mut()
            .map(|tr| ((tr.tail - at).norm(), reach(tr), tr))
            .filter(|(d, reach, _)| d <= reach)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        match nearest {
            Some((_, _, tr)) => {
                tr.tail = at;
                tr.tail_ns = t_ns;
                tr.confirmations += 1;
            }
            None => out.push(Track { at, t_ns, newest: index, tail: at, tail_ns: t_ns, confirmations: 1 }),
        }
    }
    out
}

/// A track's velocity is measured over at least this long (shorter, it is taken as still).
const MIN_SPAN_NS: u64 = 300_000_000;

impl Track {
    /// Floor velocity from the oldest to the newest confirmation, m/s.
    pub fn velocity_mps(&self) -> Vector2<f64> {
        let span_ns = self.t_ns.saturating_sub(self.tail_ns);
        if span_ns < MIN_SPAN_NS {
            return Vector2::zeros();
        }
        (self.at - self.tail) / (span_ns as f64 * 1e-9)
    }

    /// Whether a cluster at `xy` in a window stamped `now_ns` may be this person: within
    /// `radius_m` of where their velocity has carried them since their last confirmation.
    pub fn reaches(&self, xy: Vector2<f64>, now_ns: u64, radius_m: f64) -> bool {
        (self.now_at(now_ns) - xy).norm() <= radius_m
    }

    /// Where the track's velocity has carried the person by `now_ns` since their last
    /// confirmation.
    pub fn now_at(&self, now_ns: u64) -> Vector2<f64> {
        let age_s = now_ns.saturating_sub(self.t_ns) as f64 * 1e-9;
        self.at + self.velocity_mps() * age_s
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_walker_and_a_sitter_are_two_tracks() {
        let mut confirmed = Vec::new();
        for k in 0..10u64 {
            // Walking along x at 0.8 m/s, confirmed every 0.1 s; sitting still 3 m away.
            confirmed.push((Vector2::new(0.08 * k as f64, 0.0), k * 100 * MS));
            confirmed.push((Vector2::new(0.0, 3.0), k * 100 * MS));
        }
        let t = tracks(&confirmed, 0.4, 1.5);
        assert_eq!(t.len(), 2, "{t:?}");
        let walker = t.iter().find(|tr| tr.at.y == 0.0).unwrap();
        assert_eq!(walker.confirmations, 10);
        assert!((walker.at.x - 0.72).abs() < 1e-9 && walker.t_ns == 900 * MS);
        assert!((walker.velocity_mps() - Vector2::new(0.8, 0.0)).norm() < 1e-9);
        // Followed where they are now, not where they were a second ago; 0.5 s on, 0.4 m ahead.
        assert!(walker.reaches(Vector2::new(0.8, 0.0), 1000 * MS, 0.4));
        assert!(!walker.reaches(Vector2::new(0.0, 0.0), 1000 * MS, 0.4));
        assert!(walker.reaches(Vector2::new(1.12, 0.0), 1400 * MS, 0.4));
        // The sitter is followed where they sit, not to a table edge 0.6 m away half a second on.
        let sitter = t.iter().find(|tr| tr.at.y == 3.0).unwrap();
        assert_eq!(sitter.velocity_mps(), Vector2::zeros());
        assert!(sitter.reaches(Vector2::new(0.1, 2.8), 1400 * MS, 0.4));
        assert!(!sitter.reaches(Vector2::new(0.6, 3.0), 1400 * MS, 0.4));
    }

    #[test]
    fn no_confirmations_no_tracks() {
        assert!(tracks(&[], 0.4, 1.5).is_empty());
    }
}
