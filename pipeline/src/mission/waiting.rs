//! What a rig that is not placed in the robot's map yet is waiting for, in words an operator
//! can act on: the status line of the AR view says it.

use crate::align::{slide_words, AlignFailure, Rejection};
use std::fmt;

/// Why the rig has no world pose yet, from its last refused registration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Waiting {
    /// The robot's map has not arrived, or is too small to align to.
    Map,
    /// No registration has run yet.
    FirstAttempt,
    /// The robot has mapped too little of what the rig sees (`share` of the view explained).
    Overlap { share: f64 },
    /// The view leaves a direction free (a corridor): it slides along `slide` (the rig's frame),
    /// or turns (`None`).
    Constraint { slide: Option<[f64; 3]> },
    /// A fit was found, but another place `off_m` away fits the view as well (a symmetric
    /// building, rooms alike, a corridor's repeated doors): more of the building must come into
    /// view to tell them apart.
    Lookalike { off_m: f64 },
    /// Refused for other reasons (a poor fit): the search goes on.
    Search,
    /// A fit passed; `searches` searches agree on it so far, and more must before it is used.
    Confirming { searches: u32 },
}

impl Waiting {
    /// What the last refused registration says the rig waits for.
    pub fn from_failure(failure: &AlignFailure) -> Self {
        let because = failure.because();
        if let Some(share) = because.iter().find_map(|r| match r {
            Rejection::TooLittleOverlap { share, .. } => Some(*share),
            _ => None,
        }) {
            return Self::Overlap { share };
        }
        if let Some(off_m) = because.iter().find_map(|r| match r {
            Rejection::ElsewhereAsGood { off_m, .. } | Rejection::PartlyMappedRival { off_m, .. } => Some(*off_m),
            _ => None,
        }) {
            return Self::Lookalike { off_m };
        }
        let slide = because.iter().find_map(|r| match r {
            Rejection::Degenerate { slide, .. } => Some(*slide),
            _ => None,
        });
        let unpinned = because
            .iter()
            .any(|r| matches!(r, Rejection::NotPinnedExplains { .. } | Rejection::NotPinnedSlides { .. }));
        match (slide, unpinned) {
            (Some(slide), _) => Self::Constraint { slide },
            (None, true) => Self::Constraint { slide: None },
            _ if because.is_empty() => Self::FirstAttempt,
            _ => Self::Search,
        }
    }
}

impl fmt::Display for Waiting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Map => f.write_str("waiting for the robot's map"),
            Self::FirstAttempt => f.write_str("aligning to the robot's map"),
            Self::Overlap { share } => {
                write!(f, "map covers {:.0} % of view: go where the robot went", share * 100.0)
            }
            Self::Constraint { slide: Some(d) } => write!(f, "view slides {}: face a corner", slide_words(d)),
            Self::Constraint { slide: None } => f.write_str("view does not pin the pose: look around"),
            Self::Lookalike { off_m } => write!(f, "map has a lookalike {off_m:.1} m away: keep moving"),
            Self::Search => f.write_str("searching the robot's map"),
            Self::Confirming { searches } => write!(f, "found a fit ({searches}x): confirming, keep moving"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(because: Vec<Rejection>) -> AlignFailure {
        AlignFailure::NoneAccepted { attempts: 3, seeds: 12, best_seed_yaw_deg: 0.0, because }
    }

    #[test]
    fn the_operator_is_told_what_to_do() {
        let corridor = refused(vec![Rejection::Degenerate { index: 1e-4, min: 0.02, slide: Some([0.98, 0.1, 0.0]) }]);
        let w = Waiting::from_failure(&corridor);
        assert_eq!(w, Waiting::Constraint { slide: Some([0.98, 0.1, 0.0]) });
        assert!(w.to_string().contains("slides forward/back"), "{w}");
        let unmapped = refused(vec![
            Rejection::TooLittleOverlap { share: 0.12, min: 0.3 },
            Rejection::Degenerate { index: 1e-4, min: 0.02, slide: None },
        ]);
        assert!(Waiting::from_failure(&unmapped).to_string().contains("12 %"));
        let ambiguous = refused(vec![Rejection::Residual { rms_m: 0.2, max_m: 0.05 }]);
        assert_eq!(Waiting::from_failure(&ambiguous), Waiting::Search);
        assert_eq!(Waiting::from_failure(&AlignFailure::NoAttempt), Waiting::FirstAttempt);
        let lookalike = refused(vec![Rejection::ElsewhereAsGood {
            off_m: 1.8,
            off_deg: 0.2,
            score: 0.88,
            here_score: 0.91,
            margin: 0.05,
        }]);
        let w = Waiting::from_failure(&lookalike);
        assert_eq!(w, Waiting::Lookalike { off_m: 1.8 });
        assert_eq!(w.to_string(), "map has a lookalike 1.8 m away: keep moving");
        let mirror = refused(vec![Rejection::PartlyMappedRival {
            off_m: 16.2,
            off_deg: 179.5,
            known_share: 0.45,
            score_on_known: 0.88,
            here_score_on_known: 0.89,
        }]);
        assert_eq!(Waiting::from_failure(&mirror), Waiting::Lookalike { off_m: 16.2 });
    }
}
