//! Scoring detections against true people (from a simulator or a labelled recording).
//!
//! The rule, per window:
//! - A true person is *visible* when at least `min_returns` of the window's returns hit them;
//!   only visible people count towards recall.
//! - A detection and a person *match* when the detection's centre lies within
//!   `max_centre_distance_m` of the true box centre over the floor (x, y), or inside the true box
//!   grown by `box_margin_m` (a lying person seen from one end is found off their centre).
//! - Matches are assigned one to one, nearest first, visible people before the others. A
//!   detection assigned to a visible person is a true positive; one assigned to a person who is
//!   not visible (too few returns to demand a detection) is ignored; every other detection,
//!   duplicates included, is a false positive. Visible people left unassigned are misses.

use super::Detection;
use nalgebra::Vector3;

/// One true person in a window.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthPerson {
    pub label: u16,
    pub centre_m: Vector3<f64>,
    /// Length (along the heading), width, height.
    pub size_m: Vector3<f64>,
    pub yaw_rad: f64,
    /// Returns of the window that hit this person.
    pub returns: usize,
}

impl TruthPerson {
    /// Whether `p` lies inside this person's box grown by `margin_m` on every side.
    pub fn contains(&self, p: &Vector3<f64>, margin_m: f64) -> bool {
        let (s, c) = self.yaw_rad.sin_cos();
        let d = p - self.centre_m;
        let local = [c * d.x + s * d.y, -s * d.x + c * d.y, d.z];
        (0..3).all(|i| local[i].abs() <= self.size_m[i] / 2.0 + margin_m)
    }
}

/// The matching rule (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatchRule {
    pub min_returns: usize,
    pub max_centre_distance_m: f64,
    pub box_margin_m: f64,
}

impl Default for MatchRule {
    fn default() -> Self {
        Self { min_returns: 30, max_centre_distance_m: 0.5, box_margin_m: 0.2 }
    }
}

/// Counts over one or many windows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub true_positives: usize,
    pub false_positives: usize,
    pub misses: usize,
    pub ignored: usize,
}

impl Counts {
    pub fn add(&mut self, o: &Counts) {
        self.true_positives += o.true_positives;
        self.false_positives += o.false_positives;
        self.misses += o.misses;
        self.ignored += o.ignored;
    }

    /// TP / (TP + FP); 1 when nothing was detected.
    pub fn precision(&self) -> f64 {
        let d = self.true_positives + self.false_positives;
        if d == 0 {
            1.0
        } else {
            self.true_positives as f64 / d as f64
        }
    }

    /// TP / (TP + misses); 1 when nobody was visible.
    pub fn recall(&self) -> f64 {
        let d = self.true_positives + self.misses;
        if d == 0 {
            1.0
        } else {
            self.true_positives as f64 / d as f64
        }
    }
}

/// What happened to each detection and person of one window.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WindowMatch {
    pub counts: Counts,
    /// Per detection: the label of the person it was assigned to, if any.
    pub detection_label: Vec<Option<u16>>,
    /// Labels of the visible people that were missed.
    pub missed: Vec<u16>,
}

/// Matches one window's detections against its true people.
pub fn match_window(detections: &[Detection], truth: &[TruthPerson], rule: &MatchRule) -> WindowMatch {
    let mut pairs: Vec<(bool, f64, usize, usize)> = Vec::new();
    for (di, d) in detections.iter().enumerate() {
        for (ti, t) in truth.iter().enumerate() {
            let dist = (d.centre_m.x - t.centre_m.x).hypot(d.centre_m.y - t.centre_m.y);
            if dist <= rule.max_centre_distance_m || t.contains(&d.centre_m, rule.box_margin_m) {
                // Visible people first, then nearest first.
                pairs.push((t.returns < rule.min_returns, dist, di, ti));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut det_taken = vec![None; detections.len()];
    let mut truth_taken = vec![false; truth.len()];
    for (_, _, di, ti) in pairs {
        let (Some(dt), Some(tt)) = (det_taken.get_mut(di), truth_taken.get_mut(ti)) else { continue };
        if dt.is_some() || *tt {
            continue;
        }
        *dt = Some(ti);
        *tt = true;
    }
    let mut m = WindowMatch::default();
    for taken in &det_taken {
        match taken.and_then(|ti| truth.get(ti)) {
            Some(t) if t.returns >= rule.min_returns => m.counts.true_positives += 1,
            Some(_) => m.counts.ignored += 1,
            None => m.counts.false_positives += 1,
        }
        m.detection_label.push(taken.and_then(|ti| truth.get(ti)).map(|t| t.label));
    }
    for (t, taken) in truth.iter().zip(&truth_taken) {
        if t.returns >= rule.min_returns && !taken {
            m.counts.misses += 1;
            m.missed.push(t.label);
        }
    }
    m
}
