//! The people of a robot detection as they travel to the rig (points as f32, boxes required)
//! and as the rig draws them: offline runs go through the same conversion as the link, so an
//! offline report and a live one see the same people.

use super::RobotDetection;
use crate::ar::ArPerson;
use crate::link::LinkPerson;

/// What the robot sends for `det` (a person without a box is not sent).
pub fn people_to_send(det: &RobotDetection) -> Vec<LinkPerson> {
    det.people
        .iter()
        .zip(&det.scores)
        .filter_map(|(p, score)| {
            Some(LinkPerson {
                score: *score as f32,
                bbox: p.bbox?,
                pose: p.pose,
                points_world: p.points_world.iter().map(|v| [v.x as f32, v.y as f32, v.z as f32]).collect(),
            })
        })
        .collect()
}

/// What the rig draws of people received.
pub fn people_to_draw(people: &[LinkPerson]) -> Vec<ArPerson> {
    people.iter().map(|p| p.to_ar_person(0)).collect()
}
