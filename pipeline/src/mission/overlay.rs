//! What the rig draws: the people of the robot's recent detections, each at its latest
//! sighting, held for a while after the robot last saw them, with their age. A person is drawn
//! once confirmed: seen in two detection windows within `CONFIRM_NS` of each other (a single
//! window's false positive, held for a second, would otherwise stand on screen where no one is).
//! A person seen walking loses their points sooner: once they may have walked `MAX_DRIFT_M` from
//! where they were last seen, their points no longer show where they are, and only their box
//! (with its label, dimming with age like anyone's) stays for the hold: a walker the robot
//! lost sight of for a moment does not vanish from the responder's screen.

use super::person_motion::{self, WALKING_MPS};
use crate::ar::{ArPerson, OrientedBox};
use nalgebra::Vector3;
use std::collections::VecDeque;

/// A later sighting this close (m, in the floor plane) to an earlier one is the same person.
const SAME_PERSON_M: f64 = 0.7;
/// Two sightings of one person at most this far apart confirm them.
const CONFIRM_NS: u64 = 500_000_000;
/// A walker is drawn at their last sighting while their speed times its age is at most this
/// (a tenth of a body's width: the share of the drawn points that miss them grows with it, to
/// half at 0.25 m, measured in the lab).
const MAX_DRIFT_M: f64 = 0.1;
/// Walkers are upright (this tall) and faster than [`WALKING_MPS`]; a lying person's centre,
/// seen sliding out of the view, moves too, but they do not walk away from their points.
const WALKER_MIN_HEIGHT_M: f64 = 1.0;
/// Speeds are measured over at least this long (a centre jitters by centimetres per window).
const MIN_SPEED_BASELINE_NS: u64 = 200_000_000;

struct Shown {
    stamp_ns: u64,
    people: Vec<ArPerson>,
}

pub struct Overlay {
    hold_ns: u64,
    shown: VecDeque<Shown>,
}

impl Overlay {
    /// People stay on screen `hold_ns` after the detection that last showed them.
    pub fn new(hold_ns: u64) -> Self {
        Self { hold_ns, shown: VecDeque::new() }
    }

    /// A detection stamped `stamp_ns` (on the clock `at` is asked on).
    pub fn push(&mut self, stamp_ns: u64, people: Vec<ArPerson>) {
        // Arrivals may be out of order over the link: keep them sorted by stamp.
        let at = self.shown.iter().rposition(|s| s.stamp_ns <= stamp_ns).map_or(0, |i| i + 1);
        self.shown.insert(at, Shown { stamp_ns, people });
        // Kept past the hold for as long as they confirm or time the held ones.
        let keep_ns = self.hold_ns.saturating_add(CONFIRM_NS);
        while self.shown.front().is_some_and(|s| s.stamp_ns.saturating_add(keep_ns) < stamp_ns) {
            self.shown.pop_front();
        }
    }

    /// Newest detection stamp held.
    pub fn newest_ns(&self) -> Option<u64> {
        self.shown.back().map(|s| s.stamp_ns)
    }

    /// Everyone seen in the `hold_ns` up to `t_ns`, each at their latest sighting, aged; people
    /// seen walking with their points only while they cannot have walked `MAX_DRIFT_M` since,
    /// their box alone after that.
    pub fn at(&self, t_ns: u64) -> Vec<ArPerson> {
        let mut out: Vec<ArPerson> = Vec::new();
        for s in self.shown.iter().rev().filter(|s| s.stamp_ns <= t_ns && s.stamp_ns + self.hold_ns >= t_ns) {
            for p in &s.people {
                let Some(b) = p.bbox else { continue };
                // Someone already drawn at a later sighting: the newest one nearby, or theirs
                // followed window by window (a walker is by then further away than one person's
                // sightings are apart, and would be drawn twice).
                let shown_near =
                    |c: &Vector3<f64>| out.iter().filter_map(|q| q.bbox).any(|q| same_person(&q.centre_m, c));
                let seen = shown_near(&b.centre_m) || shown_near(&self.latest_sighting(s.stamp_ns, &b.centre_m, t_ns));
                // Confirmed by an earlier sighting in the `CONFIRM_NS` before this one.
                if seen || self.earlier_sighting(s.stamp_ns, 1, &b.centre_m).is_none() {
                    continue;
                }
                let age_ns = t_ns - s.stamp_ns;
                let speed = self.speed_mps(s.stamp_ns, &b.centre_m);
                let walking = b.size_m.z >= WALKER_MIN_HEIGHT_M && speed >= WALKING_MPS;
                let drifted = walking && speed * age_ns as f64 * 1e-9 > MAX_DRIFT_M;
                let points_world = if drifted { Vec::new() } else { p.points_world.clone() };
                out.push(ArPerson { points_world, bbox: p.bbox, age_ns, pose: p.pose });
            }
        }
        out
    }

    /// The boxes of the people [`Overlay::at`] would draw at `t_ns`.
    pub fn boxes_at(&self, t_ns: u64) -> Vec<OrientedBox> {
        self.at(t_ns).into_iter().filter_map(|p| p.bbox).collect()
    }

    /// The earliest sighting near `centre` in the `CONFIRM_NS` before `stamp_ns` and at least
    /// `min_gap_ns` before it: its stamp and centre.
    fn earlier_sighting(&self, stamp_ns: u64, min_gap_ns: u64, centre: &Vector3<f64>) -> Option<(u64, Vector3<f64>)> {
        self.shown
            .iter()
            .filter(|s| s.stamp_ns + min_gap_ns <= stamp_ns && s.stamp_ns + CONFIRM_NS >= stamp_ns)
            .find_map(|s| {
                let b = s.people.iter().filter_map(|p| p.bbox).find(|b| same_person(&b.centre_m, centre))?;
                Some((s.stamp_ns, b.centre_m))
            })
    }

    /// Where the person seen at `centre` at `stamp_ns` was last seen by `t_ns`, followed window
    /// by window (`centre` itself when they were not seen again).
    fn latest_sighting(&self, stamp_ns: u64, centre: &Vector3<f64>, t_ns: u64) -> Vector3<f64> {
        let mut last = (stamp_ns, centre.xy());
        for s in self.shown.iter().filter(|s| s.stamp_ns > stamp_ns && s.stamp_ns <= t_ns) {
            let centres = s.people.iter().filter_map(|p| p.bbox).map(|b| b.centre_m);
            if let Some(c) = person_motion::next_sighting(last, s.stamp_ns, centres) {
                last = (s.stamp_ns, c);
            }
        }
        Vector3::new(last.1.x, last.1.y, centre.z)
    }

    /// Floor speed of the person seen at `centre` at `stamp_ns`, over at least
    /// `MIN_SPEED_BASELINE_NS` (0 when they were not seen that long before).
    fn speed_mps(&self, stamp_ns: u64, centre: &Vector3<f64>) -> f64 {
        self.earlier_sighting(stamp_ns, MIN_SPEED_BASELINE_NS, centre)
            .map_or(0.0, |(t, at)| (at - centre).xy().norm() / ((stamp_ns - t) as f64 * 1e-9))
    }
}

/// Whether two sightings' centres are one person's.
fn same_person(a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
    (a - b).xy().norm() < SAME_PERSON_M
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ar::OrientedBox;
    use nalgebra::Vector3;

    fn person(x: f64) -> ArPerson {
        ArPerson {
            points_world: vec![Vector3::new(x, 0.0, 1.0)],
            bbox: Some(OrientedBox {
                centre_m: Vector3::new(x, 0.0, 0.9),
                size_m: Vector3::new(0.5, 0.5, 1.8),
                yaw_rad: 0.0,
            }),
            age_ns: 0,
            pose: None,
        }
    }

    #[test]
    fn latest_sighting_wins_and_expires() {
        let mut o = Overlay::new(1_000);
        o.push(100, vec![person(0.0), person(5.0)]);
        o.push(200, vec![person(0.1), person(5.1)]);
        o.push(300, vec![person(0.2)]);
        let now = o.at(400);
        assert_eq!(now.len(), 2);
        let near = now.iter().find(|p| p.bbox.is_some_and(|b| b.centre_m.x < 1.0)).map(|p| p.age_ns);
        assert_eq!(near, Some(100));
        assert!(o.at(50).is_empty(), "nothing before the first detection");
        assert_eq!(o.at(1_250).len(), 1, "the person last seen at 200 expired");
    }

    #[test]
    fn one_window_alone_is_not_drawn() {
        let mut o = Overlay::new(2_000_000_000);
        o.push(0, vec![person(0.0)]);
        assert!(o.at(100_000_000).is_empty(), "seen once: unconfirmed");
        // Seen again long after: still a single sighting within the confirmation window.
        o.push(1_000_000_000, vec![person(0.1)]);
        assert!(o.at(1_000_000_000).is_empty());
        o.push(1_100_000_000, vec![person(0.2)]);
        assert_eq!(o.at(1_100_000_000).len(), 1, "confirmed by the window before");
    }

    #[test]
    fn a_walker_keeps_only_their_box_once_they_may_have_walked_away_and_a_standing_person_is_held() {
        const MS: u64 = 1_000_000;
        let mut o = Overlay::new(1_000 * MS);
        // A walker at 1.4 m/s and a person standing 5 m away, seen every 100 ms to 500 ms.
        for k in 1..=5u32 {
            o.push(u64::from(k) * 100 * MS, vec![person(0.14 * f64::from(k)), person(5.0 + 0.01 * f64::from(k % 2))]);
        }
        // The walker as drawn: (people, points) near them.
        let walker = |o: &Overlay, t_ms: u64| {
            let near: Vec<ArPerson> =
                o.at(t_ms * MS).into_iter().filter(|p| p.bbox.is_some_and(|b| b.centre_m.x < 2.0)).collect();
            (near.len(), near.iter().map(|p| p.points_world.len()).sum::<usize>())
        };
        assert_eq!(walker(&o, 550), (1, 1), "0.07 m since their last sighting: their points");
        assert_eq!(walker(&o, 600), (1, 0), "0.14 m: no longer where their points are; their box stays");
        assert_eq!(walker(&o, 1_400), (1, 0), "once, at their latest sighting, not at an older one");
        assert_eq!(walker(&o, 1_550), (0, 0), "gone after the hold");
        // Later detections without the walker do not make them stand still.
        o.push(1_200 * MS, vec![person(5.0)]);
        o.push(1_450 * MS, vec![person(5.0)]);
        assert_eq!(walker(&o, 1_450), (1, 0), "their speed outlives the sightings it was measured on");
        let standing = o.at(1_400 * MS).into_iter().filter(|p| !p.points_world.is_empty()).count();
        assert_eq!(standing, 1, "the standing person is held, points and all, for the whole second");
    }

    #[test]
    fn only_an_upright_person_faster_than_a_stroll_walks_away_from_their_points() {
        const MS: u64 = 1_000_000;
        let lying = |x: f64| {
            let mut p = person(x);
            if let Some(b) = p.bbox.as_mut() {
                b.size_m = Vector3::new(1.7, 0.5, 0.3);
            }
            p
        };
        let mut o = Overlay::new(1_000 * MS);
        // A standing person's centre wandering at 0.2 m/s, a lying person's sliding at 0.5 m/s.
        for k in 1..=5u32 {
            o.push(u64::from(k) * 100 * MS, vec![person(0.02 * f64::from(k)), lying(5.0 + 0.05 * f64::from(k))]);
        }
        assert_eq!(o.at(1_400 * MS).len(), 2, "both held for the whole second");
    }

    #[test]
    fn a_walker_seen_a_second_ago_is_not_drawn_again_where_they_were() {
        const MS: u64 = 1_000_000;
        let mut o = Overlay::new(1_000 * MS);
        // Walking at 0.7 m/s, seen every 100 ms: their first sightings are 0.7 m behind them
        // a second later, as far as two people's sightings are apart.
        for k in 0..=10u32 {
            o.push(u64::from(k) * 100 * MS, vec![person(0.07 * f64::from(k))]);
        }
        let drawn = o.at(1_000 * MS);
        assert_eq!(drawn.len(), 1, "{drawn:?}");
        assert_eq!(drawn[0].age_ns, 0);
        // Someone else standing 1 m away, seen only until 500 ms, is still held.
        let mut o = Overlay::new(1_000 * MS);
        for k in 0..=10u32 {
            let mut people = vec![person(0.07 * f64::from(k))];
            if k <= 5 {
                people.push(person(-1.0));
            }
            o.push(u64::from(k) * 100 * MS, people);
        }
        assert_eq!(o.at(1_000 * MS).len(), 2);
    }

    #[test]
    fn late_arrivals_are_sorted_in() {
        let mut o = Overlay::new(1_000);
        o.push(300, vec![person(0.0)]);
        o.push(200, vec![person(0.1)]);
        o.push(100, vec![person(0.1)]);
        assert_eq!(o.newest_ns(), Some(300));
        assert_eq!(o.at(350).first().map(|p| p.age_ns), Some(50));
    }
}
