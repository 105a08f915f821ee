//! Why an alignment attempt was refused, and why a whole alignment failed: typed, so that code
//! and tests branch on the kind and the numbers, and people read the Display.

use serde::Serialize;
use std::fmt;

/// One acceptance test an attempt failed, with the figures it was judged on.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Rejection {
    /// Of the points the robot's coverage can judge, too few explained: the rest lie in space
    /// the robot saw through (`ratio` = explained over explained and contradicted).
    Contradicted { ratio: f64, min: f64, contradicted: usize },
    /// Too little of the view is explained to judge by (the robot has not mapped what the rig
    /// sees yet): waiting for more.
    TooLittleOverlap { share: f64, min: f64 },
    /// RMS point-to-plane residual above `max_rms_m`.
    Residual { rms_m: f64, max_m: f64 },
    /// Too few source points near the target (over the points judged).
    InlierRatio { ratio: f64, min: f64 },
    /// ICP had not settled (its last update too large).
    NotSettled { update_norm: f64, max: f64 },
    /// The result leaves a direction unconstrained (degeneracy index too small); `slide` is
    /// that direction in the source's (the rig's LiDAR) frame when it is mostly a translation
    /// (a corridor's axis), `None` when it is mostly a turn.
    Degenerate { index: f64, min: f64, slide: Option<[f64; 3]> },
    /// Degenerate, and what it explains does not pin it: it explains too little of the source
    /// to be judged by its slides.
    NotPinnedExplains { share: f64, asked: f64 },
    /// Degenerate, and moved `moved_m` along a weak direction it still explains `still` of the
    /// `explained` points it explains.
    NotPinnedSlides { moved_m: f64, translation_share: f64, still: usize, explained: usize },
    /// ICP from a start off the result settles elsewhere with a clearly lower residual.
    Inconsistent { start_off_m: f64, start_off_deg: f64, moved_m: f64, moved_deg: f64, rms_m: f64, here_rms_m: f64 },
    /// Another seed settles elsewhere with a fit about as good.
    Ambiguous {
        seed_yaw_deg: f64,
        moved_m: f64,
        moved_deg: f64,
        rms_m: f64,
        here_rms_m: f64,
        inliers: f64,
        here_inliers: f64,
    },
    /// Searched over the whole map (the correlative stage), another place explains the view
    /// about as well: `score` there against `here_score` here (shares of the view's points).
    ElsewhereAsGood { off_m: f64, off_deg: f64, score: f64, here_score: f64, margin: f64 },
    /// Another place, where the rig could stand, fits the part of the map it lands on as well as
    /// this one fits: the view may be of a part of the building the robot has mapped only there
    /// (`known_share` of the view on known cells at the other place, their mean value
    /// `score_on_known` against `here_score_on_known`).
    PartlyMappedRival { off_m: f64, off_deg: f64, known_share: f64, score_on_known: f64, here_score_on_known: f64 },
    /// Too many of the window's rays cross a mapped surface before their end.
    SeesThroughMap { blocked: usize, rays: usize, max_ratio: f64 },
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Residual { rms_m, max_m } => write!(f, "rms residual {rms_m:.4} m > {max_m} m"),
            Self::Contradicted { ratio, min, contradicted } => write!(
                f,
                "contradicted: {contradicted} points lie where the robot saw through (explained {ratio:.3} of the covered < {min})"
            ),
            Self::TooLittleOverlap { share, min } => {
                write!(f, "waiting for overlap: the map explains {share:.3} of the view (< {min})")
            }
            Self::InlierRatio { ratio, min } => write!(f, "inlier ratio {ratio:.3} < {min}"),
            Self::NotSettled { update_norm, max } => write!(f, "update norm {update_norm:.2e} > {max:.0e}"),
            Self::Degenerate { index, min, slide } => {
                write!(f, "degeneracy index {index:.2e} < {min:.0e}")?;
                match slide {
                    Some(d) => write!(f, " (it slides {})", slide_words(d)),
                    None => write!(f, " (it turns)"),
                }
            }
            Self::NotPinnedExplains { share, asked } => {
                write!(f, "not pinned: explains {share:.3} of the source ({asked} asked)")
            }
            Self::NotPinnedSlides { moved_m, translation_share, still, explained } => write!(
                f,
                "not pinned: moved {moved_m:+.1} m along a weak direction (translation share {translation_share:.2}) it still explains {still} of the {explained} points it explains"
            ),
            Self::Inconsistent { start_off_m, start_off_deg, moved_m, moved_deg, rms_m, here_rms_m } => write!(
                f,
                "inconsistent: ICP from a start {:.0} cm / {start_off_deg:.1} deg off settles {:.1} cm / {moved_deg:.2} deg away with residual {rms_m:.4} m < {here_rms_m:.4} m",
                start_off_m * 100.0,
                moved_m * 100.0
            ),
            Self::Ambiguous { seed_yaw_deg, moved_m, moved_deg, rms_m, here_rms_m, inliers, here_inliers } => write!(
                f,
                "ambiguous: seed yaw {seed_yaw_deg:+.0} deg settles {moved_m:.2} m / {moved_deg:.1} deg away with a fit as good (rms {rms_m:.4} vs {here_rms_m:.4} m, inliers {inliers:.3} vs {here_inliers:.3})"
            ),
            Self::ElsewhereAsGood { off_m, off_deg, score, here_score, margin } => write!(
                f,
                "another place {off_m:.1} m / {off_deg:.0} deg away explains the view as well over the whole map (score {score:.3} vs {here_score:.3} here, margin {margin})"
            ),
            Self::PartlyMappedRival { off_m, off_deg, known_share, score_on_known, here_score_on_known } => write!(
                f,
                "a place {off_m:.1} m / {off_deg:.0} deg away fits what the map knows there as well ({:.0} % of the view on mapped space, score {score_on_known:.3} vs {here_score_on_known:.3} here)",
                known_share * 100.0
            ),
            Self::SeesThroughMap { blocked, rays, max_ratio } => write!(
                f,
                "sees through the map: {blocked} of {rays} rays ({:.0} %) cross a mapped surface before their end (at most {:.0} %)",
                *blocked as f64 / (*rays).max(1) as f64 * 100.0,
                max_ratio * 100.0
            ),
        }
    }
}

/// A direction in the Avia's frame (x forward, y left, z up) in words, by its largest part.
pub fn slide_words(d: &[f64; 3]) -> &'static str {
    let [x, y, z] = d.map(f64::abs);
    if x >= y && x >= z {
        "forward/back"
    } else if y >= z {
        "left/right"
    } else {
        "up/down"
    }
}

/// Why an alignment accepted nothing.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum AlignFailure {
    /// No attempt ran (nothing to align).
    NoAttempt,
    /// Every attempt was refused; the best one's reasons.
    NoneAccepted { attempts: usize, seeds: usize, best_seed_yaw_deg: f64, because: Vec<Rejection> },
}

impl AlignFailure {
    /// The best attempt's reasons (none when no attempt ran).
    pub fn because(&self) -> &[Rejection] {
        match self {
            Self::NoAttempt => &[],
            Self::NoneAccepted { because, .. } => because,
        }
    }
}

/// The reasons joined by "; ".
pub struct Reasons<'a>(pub &'a [Rejection]);

impl fmt::Display for Reasons<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, r) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{r}")?;
        }
        Ok(())
    }
}

impl fmt::Display for AlignFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoAttempt => f.write_str("no attempt ran"),
            Self::NoneAccepted { attempts, seeds, best_seed_yaw_deg, because } => write!(
                f,
                "none of {attempts} attempt(s) from {seeds} seed(s) passed; the best (seed yaw {best_seed_yaw_deg:+.0} deg) failed: {}",
                Reasons(because)
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{AlignFailure, Rejection};

    #[test]
    fn reasons_read_as_sentences() {
        let f = AlignFailure::NoneAccepted {
            attempts: 3,
            seeds: 60,
            best_seed_yaw_deg: 150.0,
            because: vec![
                Rejection::InlierRatio { ratio: 0.396, min: 0.5 },
                Rejection::SeesThroughMap { blocked: 43, rays: 400, max_ratio: 0.1 },
            ],
        };
        assert_eq!(
            f.to_string(),
            "none of 3 attempt(s) from 60 seed(s) passed; the best (seed yaw +150 deg) failed: inlier ratio 0.396 < 0.5; sees through the map: 43 of 400 rays (11 %) cross a mapped surface before their end (at most 10 %)"
        );
        assert_eq!(f.because().len(), 2);
        assert_eq!(AlignFailure::NoAttempt.to_string(), "no attempt ran");
    }
}
