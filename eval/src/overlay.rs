//! Overlay metrics that drawing fewer points cannot raise. The paper's inlier ratio (the share
//! of drawn person points inside the see-through mask) rewards drawing only the surest points;
//! these ask the opposite question, per camera frame and per person the robot has detected in
//! the last second:
//!
//! - **person coverage**: the share of that person's see-through mask pixels within
//!   [`NEAR_PX`] of a drawn point (every person present in the mask);
//! - **people shown**: whether any drawn point lands within [`NEAR_PX`] of their mask (only the
//!   people behind a wall: at most [`HIDDEN_MAX_VISIBLE`] of their see-through pixels are in the
//!   visible mask, or every person where the run wrote no visible masks).
//!
//! A pixel is near a drawn point when the pixel's centre lies within [`NEAR_PX`] of it (the
//! disc of 13 pixels around a point drawn at a pixel's centre).

use crate::report::OverlayReport;
use crate::truth::Mask;
use std::collections::BTreeMap;

/// How close a drawn point must be to a mask pixel's centre to cover it (pixels).
pub const NEAR_PX: f64 = 2.0;
/// A person counts as behind a wall when at most this share of their see-through pixels is
/// seen directly (in the visible mask).
pub const HIDDEN_MAX_VISIBLE: f64 = 0.1;
/// A person counts when a detection matched them at most this long before the frame.
pub const DETECTED_WITHIN_NS: u64 = 1_000_000_000;

/// The pixel value of person `label` in the simulator's masks.
pub fn mask_value(label: u16) -> u8 {
    u8::try_from(label).unwrap_or(u8::MAX)
}

/// Which pixels of an image lie within a radius of a drawn point.
pub struct NearDrawn {
    width: usize,
    near: Vec<bool>,
}

impl NearDrawn {
    /// Marks every pixel of a `width` x `height` image whose centre lies within `radius_px` of
    /// one of the points `(u, v)` (pixel `(x, y)` spans `[x, x + 1) x [y, y + 1)`).
    pub fn new(width: u32, height: u32, drawn: impl IntoIterator<Item = (f64, f64)>, radius_px: f64) -> Self {
        let (w, h) = (width as usize, height as usize);
        let mut near = vec![false; w * h];
        let r = if radius_px.is_finite() { radius_px.max(0.0) } else { 0.0 };
        // The pixels whose centre is within r of c along one axis: [c - r - 0.5, c + r - 0.5].
        let span = |c: f64, n: usize| {
            let lo = (c - r - 0.5).ceil().max(0.0);
            let hi = (c + r - 0.5).floor().min(n as f64 - 1.0);
            (lo <= hi).then_some((lo as usize, hi as usize))
        };
        for (u, v) in drawn {
            if !(u.is_finite() && v.is_finite()) {
                continue;
            }
            let (Some((x0, x1)), Some((y0, y1))) = (span(u, w), span(v, h)) else { continue };
            for y in y0..=y1 {
                let dy = y as f64 + 0.5 - v;
                for x in x0..=x1 {
                    let dx = x as f64 + 0.5 - u;
                    if dx * dx + dy * dy <= r * r {
                        if let Some(n) = near.get_mut(y * w + x) {
                            *n = true;
                        }
                    }
                }
            }
        }
        Self { width: w, near }
    }

    /// Whether pixel `(x, y)` is near a drawn point.
    pub fn at(&self, x: usize, y: usize) -> bool {
        x < self.width && self.near.get(y * self.width + x).copied().unwrap_or(false)
    }

    fn index(&self, i: usize) -> bool {
        self.near.get(i).copied().unwrap_or(false)
    }
}

/// One person's pixels in one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PersonPixels {
    /// Their pixels in the see-through mask.
    pub in_mask: usize,
    /// Of those, the ones near a drawn point.
    pub near_drawn: usize,
    /// Their pixels in the visible mask (seen directly); `None` without a visible mask.
    pub visible: Option<usize>,
}

impl PersonPixels {
    /// Behind a wall: at most [`HIDDEN_MAX_VISIBLE`] of them seen directly (everyone, without a
    /// visible mask).
    pub fn hidden(&self) -> bool {
        self.visible.is_none_or(|v| v as f64 <= HIDDEN_MAX_VISIBLE * self.in_mask as f64)
    }
}

/// Every person's pixels in one frame, indexed by mask value (0, no one, stays empty).
pub fn person_pixels(see_through: &Mask, visible: Option<&Mask>, near: &NearDrawn) -> Vec<PersonPixels> {
    let visible = visible.filter(|v| v.width == see_through.width && v.height == see_through.height);
    let mut out = vec![PersonPixels { visible: visible.map(|_| 0), ..PersonPixels::default() }; 256];
    for (i, &label) in see_through.pixels.iter().enumerate().filter(|(_, l)| **l != 0) {
        if let Some(p) = out.get_mut(usize::from(label)) {
            p.in_mask += 1;
            p.near_drawn += usize::from(near.index(i));
        }
    }
    for &label in visible.iter().flat_map(|v| v.pixels.iter()).filter(|l| **l != 0) {
        if let Some(n) = out.get_mut(usize::from(label)).and_then(|p| p.visible.as_mut()) {
            *n += 1;
        }
    }
    out
}

/// Both metrics summed over (frame, person) pairs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OverlayTally {
    coverage_sum: f64,
    coverage_pairs: usize,
    shown: usize,
    shown_pairs: usize,
    /// The same, over the frames the rig drew as aligned only.
    shown_aligned: usize,
    shown_pairs_aligned: usize,
}

impl OverlayTally {
    /// One person detected lately, in one frame (`aligned`: the rig drew it as placed in the
    /// map): counted where they are in the see-through mask.
    pub fn add(&mut self, p: &PersonPixels, aligned: bool) {
        if p.in_mask == 0 {
            return;
        }
        self.coverage_sum += p.near_drawn as f64 / p.in_mask as f64;
        self.coverage_pairs += 1;
        if p.hidden() {
            let shown = usize::from(p.near_drawn > 0);
            self.shown_pairs += 1;
            self.shown += shown;
            if aligned {
                self.shown_pairs_aligned += 1;
                self.shown_aligned += shown;
            }
        }
    }

    /// One camera frame: the points drawn in it (pixels), its masks, the people (labels) the
    /// robot detected lately, and whether the rig drew it aligned.
    pub fn frame(
        &mut self,
        see_through: &Mask,
        visible: Option<&Mask>,
        drawn: &[(f64, f64)],
        detected: &[u16],
        aligned: bool,
    ) {
        if detected.is_empty() {
            return;
        }
        let near = NearDrawn::new(see_through.width, see_through.height, drawn.iter().copied(), NEAR_PX);
        let pixels = person_pixels(see_through, visible, &near);
        for label in detected {
            if let Some(p) = pixels.get(usize::from(mask_value(*label))) {
                self.add(p, aligned);
            }
        }
    }

    pub fn report(&self) -> OverlayReport {
        let share = |sum: f64, n: usize| if n > 0 { sum / n as f64 } else { f64::NAN };
        OverlayReport {
            person_coverage: share(self.coverage_sum, self.coverage_pairs),
            coverage_pairs: self.coverage_pairs,
            people_shown: share(self.shown as f64, self.shown_pairs),
            shown_pairs: self.shown_pairs,
            people_shown_aligned: share(self.shown_aligned as f64, self.shown_pairs_aligned),
            shown_pairs_aligned: self.shown_pairs_aligned,
        }
    }
}

/// When detections matched each true person (PTP ns), to ask who was detected lately.
#[derive(Clone, Debug, Default)]
pub struct DetectedLog {
    by_label: BTreeMap<u16, Vec<u64>>,
}

impl DetectedLog {
    pub fn record(&mut self, label: u16, stamp_ns: u64) {
        let stamps = self.by_label.entry(label).or_default();
        let at = stamps.partition_point(|s| *s <= stamp_ns);
        stamps.insert(at, stamp_ns);
    }

    /// The people matched by a detection stamped in `[t_ns - within_ns, t_ns]`.
    pub fn recent(&self, t_ns: u64, within_ns: u64) -> Vec<u16> {
        let from = t_ns.saturating_sub(within_ns);
        self.by_label
            .iter()
            .filter(|(_, stamps)| {
                let i = stamps.partition_point(|s| *s < from);
                stamps.get(i).is_some_and(|s| *s <= t_ns)
            })
            .map(|(label, _)| *label)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use starc_pipeline::ar::{mask_inlier_ratio, ProjectedPoint};

    /// A `w` x `h` mask with person `label` on the pixels `(x, y)` that `on` picks.
    fn mask(w: u32, h: u32, label: u8, on: impl Fn(u32, u32) -> bool) -> Mask {
        let pixels = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| if on(x, y) { label } else { 0 });
        Mask { width: w, height: h, pixels: pixels.collect() }
    }

    /// Points at the centres of the pixels of `label`.
    fn at_centres(m: &Mask, label: u8) -> Vec<(f64, f64)> {
        let w = m.width as usize;
        let on = m.pixels.iter().enumerate().filter(|(_, l)| **l == label);
        on.map(|(i, _)| ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5)).collect()
    }

    fn one_frame(see: &Mask, visible: Option<&Mask>, drawn: &[(f64, f64)], detected: &[u16]) -> OverlayReport {
        let mut t = OverlayTally::default();
        t.frame(see, visible, drawn, detected, true);
        t.report()
    }

    #[test]
    fn people_shown_while_aligned_counts_only_the_frames_drawn_aligned() {
        let see = mask(20, 20, 1, |x, y| (5..9).contains(&x) && (5..9).contains(&y));
        let on = at_centres(&see, 1);
        let mut t = OverlayTally::default();
        // Two frames before the rig was placed (nothing drawn), one after (drawn on them).
        t.frame(&see, None, &[], &[1], false);
        t.frame(&see, None, &[], &[1], false);
        t.frame(&see, None, &on, &[1], true);
        let r = t.report();
        assert_eq!((r.shown_pairs, r.shown_pairs_aligned), (3, 1));
        assert!((r.people_shown - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(r.people_shown_aligned, 1.0);
        // Aligned but drawn elsewhere (a wrong alignment) counts against it.
        t.frame(&see, None, &[(19.5, 19.5)], &[1], true);
        assert_eq!(t.report().people_shown_aligned, 0.5);
    }

    #[test]
    fn near_means_the_pixel_centre_within_two_pixels() {
        let near = NearDrawn::new(10, 10, [(4.5, 4.5)], NEAR_PX);
        let count = (0..10).flat_map(|y| (0..10).map(move |x| (x, y))).filter(|&(x, y)| near.at(x, y)).count();
        assert_eq!(count, 13, "the disc of radius 2 around a pixel centre");
        assert!(near.at(6, 4) && near.at(4, 2) && !near.at(6, 5) && !near.at(7, 4));
        // At a corner: clipped, no panic; far off the image: nothing.
        let corner = NearDrawn::new(10, 10, [(0.0, 0.0), (1e300, -1e300), (f64::NAN, 1.0)], NEAR_PX);
        assert!(corner.at(0, 0) && corner.at(1, 0) && corner.at(0, 1) && !corner.at(1, 1) && !corner.at(10, 0));
    }

    #[test]
    fn coverage_is_one_when_every_mask_pixel_is_near_a_drawn_point() {
        // A 3 x 3 person, one point at their centre pixel's centre: every pixel within sqrt(2).
        let see = mask(8, 8, 1, |x, y| (2..5).contains(&x) && (2..5).contains(&y));
        let r = one_frame(&see, None, &[(3.5, 3.5)], &[1]);
        assert_eq!((r.person_coverage, r.coverage_pairs), (1.0, 1));
        assert_eq!((r.people_shown, r.shown_pairs), (1.0, 1), "no visible mask: everyone counts as hidden");
    }

    #[test]
    fn coverage_is_the_share_of_mask_pixels_near_a_drawn_point() {
        // A row of ten pixels; a point at pixel 2's centre reaches pixels 0-4.
        let see = mask(16, 4, 3, |x, y| y == 1 && x < 10);
        let r = one_frame(&see, None, &[(2.5, 1.5)], &[3]);
        assert_eq!((r.person_coverage, r.coverage_pairs), (0.5, 1));
    }

    #[test]
    fn nobody_is_shown_when_nothing_is_drawn() {
        let see = mask(16, 16, 2, |x, y| x > 4 && y > 4);
        let hidden = mask(16, 16, 2, |_, _| false);
        let r = one_frame(&see, Some(&hidden), &[], &[2]);
        assert_eq!((r.people_shown, r.shown_pairs), (0.0, 1));
        assert_eq!((r.person_coverage, r.coverage_pairs), (0.0, 1));
    }

    #[test]
    fn drawing_fewer_points_lowers_coverage_while_the_inlier_ratio_stays_one() {
        // A hidden person 20 x 4 pixels; every point drawn at one of their pixels' centres.
        let see = mask(32, 8, 1, |x, y| (4..24).contains(&x) && (2..6).contains(&y));
        let all = at_centres(&see, 1);
        let inlier = |drawn: &[(f64, f64)]| {
            let projected: Vec<ProjectedPoint> =
                drawn.iter().map(|&(u, v)| ProjectedPoint { u, v, depth_m: 5.0, person: 0 }).collect();
            let (inside, in_image) = mask_inlier_ratio(&projected, &see.pixels, see.width, see.height);
            inside as f64 / in_image as f64
        };
        let full = one_frame(&see, None, &all, &[1]);
        assert_eq!((inlier(&all), full.person_coverage), (1.0, 1.0));
        // Only the left half of the points: just as precise, far less of the person shown.
        let half: Vec<(f64, f64)> = all.iter().copied().filter(|(u, _)| *u < 14.0).collect();
        assert_eq!(half.len() * 2, all.len());
        let fewer = one_frame(&see, None, &half, &[1]);
        assert_eq!(inlier(&half), 1.0, "the inlier ratio does not notice");
        assert_eq!(fewer.person_coverage, 0.6, "columns 4-15 of 4-23 covered");
        assert_eq!(fewer.people_shown, 1.0, "still shown");
    }

    #[test]
    fn only_people_detected_lately_in_the_mask_and_hidden_count() {
        // Person 1 hidden, person 2 seen directly (all their pixels visible), person 3 not in
        // the frame, person 4 in the frame but not detected.
        let see = mask(16, 4, 0, |_, _| false);
        let mut see = see;
        for x in 0..4 {
            see.pixels[x] = 1;
            see.pixels[16 + 4 + x] = 2;
            see.pixels[32 + 8 + x] = 4;
        }
        let visible = Mask { pixels: see.pixels.iter().map(|&l| if l == 2 { 2 } else { 0 }).collect(), ..see.clone() };
        let r = one_frame(&see, Some(&visible), &[(1.5, 0.5)], &[1, 2, 3]);
        assert_eq!(r.coverage_pairs, 2, "people 1 and 2");
        assert_eq!(r.person_coverage, (1.0 + 0.0) / 2.0, "a point on person 1 reaches all four of their pixels");
        assert_eq!((r.people_shown, r.shown_pairs), (1.0, 1), "only person 1 is behind a wall");
        let nobody = one_frame(&see, Some(&visible), &[(1.5, 0.5)], &[]);
        assert_eq!(nobody.coverage_pairs, 0);
        assert!(nobody.person_coverage.is_nan() && nobody.people_shown.is_nan());
    }

    #[test]
    fn a_person_mostly_behind_a_wall_is_hidden() {
        let p = |visible| PersonPixels { in_mask: 100, near_drawn: 0, visible };
        assert!(p(None).hidden() && p(Some(0)).hidden() && p(Some(10)).hidden());
        assert!(!p(Some(11)).hidden());
    }

    #[test]
    fn recent_detections_are_those_of_the_last_second() {
        let mut log = DetectedLog::default();
        log.record(1, 5_000_000_000);
        log.record(2, 3_000_000_000);
        log.record(2, 1_000_000_000); // out of order
        assert_eq!(log.recent(5_500_000_000, DETECTED_WITHIN_NS), vec![1]);
        assert_eq!(log.recent(4_000_000_000, DETECTED_WITHIN_NS), vec![2], "at the window's edge");
        assert_eq!(log.recent(4_000_000_001, DETECTED_WITHIN_NS), Vec::<u16>::new());
        assert_eq!(log.recent(1_500_000_000, DETECTED_WITHIN_NS), vec![2]);
        assert_eq!(log.recent(4_999_999_999, DETECTED_WITHIN_NS), Vec::<u16>::new(), "not before it happened");
    }
}
