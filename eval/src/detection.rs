//! The true people of a detection window, in the robot's LIO world, each with the window's
//! returns on them: what the robot's detections are matched against
//! (`starc_pipeline::detect::eval::match_window`).

use crate::truth::{PersonBox, PersonReturns};
use nalgebra::{Isometry3, Point3};
use starc_pipeline::detect::eval::TruthPerson;
use starc_pipeline::detect::WindowPoint;

/// The true people in the LIO world, each with the window's returns on them: from the simulator's
/// labels where it wrote them (as the detect bench counts), else those inside their box grown by
/// 0.1 m ([`box_returns`], which also counts the floor and furniture around them).
pub fn truth_in_world(
    people: &[PersonBox],
    lio_t_world: &Isometry3<f64>,
    points: &[WindowPoint],
    labelled: Option<&PersonReturns>,
) -> Vec<TruthPerson> {
    let yaw = lio_t_world.rotation.euler_angles().2;
    let (from_ns, to_ns) = points.iter().fold((u64::MAX, 0), |(a, b), p| (a.min(p.t_ns), b.max(p.t_ns)));
    people
        .iter()
        .map(|p| {
            let centre = (lio_t_world * Point3::from(p.centre_m)).coords;
            let yaw_rad = p.yaw_rad + yaw;
            let mut t = TruthPerson { label: p.label, centre_m: centre, size_m: p.size_m, yaw_rad, returns: 0 };
            t.returns = match labelled {
                Some(l) => l.on_person(p.label, from_ns, to_ns),
                None => box_returns(&t, points),
            };
            t
        })
        .collect()
}

/// The window's returns inside a person's box grown by 0.1 m on every side.
pub fn box_returns(t: &TruthPerson, points: &[WindowPoint]) -> usize {
    points.iter().filter(|q| t.contains(&q.xyz(), 0.1)).count()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn a_person_is_visible_by_the_returns_on_them_not_by_what_lies_in_their_box() {
        let person = PersonBox {
            t_ns: 0,
            pose: crate::truth::TruePose::Standing,
            label: 1,
            centre_m: Vector3::new(2.0, 0.0, 0.9),
            size_m: Vector3::new(0.4, 0.5, 1.8),
            yaw_rad: 0.0,
        };
        // 40 floor returns inside the box grown by 0.1 m, fired over [1000, 1039] ns.
        let points: Vec<WindowPoint> = (0..40u64)
            .map(|i| WindowPoint { x_m: 1.85 + 0.0075 * i as f32, y_m: 0.2, z_m: -0.05, t_ns: 1_000 + i })
            .collect();
        let by_box = truth_in_world(std::slice::from_ref(&person), &Isometry3::identity(), &points, None);
        assert_eq!(by_box[0].returns, 40);
        // The labels say none of them hit the person, and 5 of a packet in the window did.
        let file = crate::truth::tests::labels_file(&[(999, &[1; 9]), (1_010, &[0, 1, 1, 1, 1, 1])]);
        let labels = PersonReturns::read(file.path()).unwrap();
        let by_label = truth_in_world(&[person], &Isometry3::identity(), &points, Some(&labels));
        assert_eq!(by_label[0].returns, 5, "only the packet first fired inside the window counts");
    }
}
