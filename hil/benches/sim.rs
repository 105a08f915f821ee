//! Simulator speed, one core: the ray caster (rays/s) and the whole simulated Avia (simulated
//! seconds per wall second) in the auditorium, the largest shipped scene.
//!
//! cargo bench -p starc-hil --bench sim

use starc_hil::rng::SplitMix64;
use starc_hil::sim::imu::ImuSim;
use starc_hil::sim::lan::AviaLink;
use starc_hil::sim::lidar::{avia_lidar_imu, AviaSim};
use starc_hil::sim::motion::{Motion, RobotMotion};
use starc_hil::sim::pattern::AviaPattern;
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::shapes::V3;
use starc_hil::sim::world::World;
use starc_livox::capture::{PcapWriter, TsPrecision};
use starc_livox::control::BroadcastCode;
use std::net::Ipv4Addr;
use std::sync::Arc;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (scenario, _) = Scenario::load("auditorium")?;
    let world = Arc::new(World::new(&scenario));
    let motion = Arc::new(RobotMotion::new(scenario.robot.get_ref()));
    println!("auditorium: {} boxes, {} people", world.building.len(), world.people.len());

    // The ray caster alone: Avia beams from poses along the robot's route.
    let n = 3_000_000u64;
    let mut rng = SplitMix64::new(1);
    let bodies = world.bodies_at(10.0);
    let poses: Vec<_> = (0..100).map(|i| motion.lidar_pose(i as f64 * 0.3)).collect();
    let start = Instant::now();
    let mut hits = 0u64;
    for k in 0..n {
        let pose = &poses[(k / 30_000) as usize % poses.len()];
        let d = pose.rotation * V3::from(AviaPattern::direction(k * 4167 + rng.below(1000), (k % 6) as usize));
        hits += u64::from(world.cast(&pose.translation.vector, &d, 400.0, &bodies).is_some());
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "ray caster: {:.2} M rays/s ({} rays, {:.1} % hit) in {secs:.2} s",
        n as f64 / secs / 1e6,
        n,
        100.0 * hits as f64 / n as f64
    );

    // The whole device: Risley pattern, ray casting, noise, labels, packetizing, the control
    // protocol and the pcap, for one Avia on the robot's route.
    for (mode, label) in
        [(starc_hil::avia::ReturnSetting::Single, "single"), (starc_hil::avia::ReturnSetting::Dual, "dual")]
    {
        let sim_s = 10.0;
        let imu = ImuSim::new(motion.clone(), avia_lidar_imu(), scenario.imu.internal, 200.0, 0.0, 3);
        let labels = Arc::new(std::sync::Mutex::new(Vec::new()));
        let source =
            AviaSim::new(world.clone(), motion.clone(), scenario.avia.clone(), imu, 9).with_labels(labels.clone());
        let mut code = [0u8; 16];
        code[..15].copy_from_slice(b"3GGDJ8E00100101");
        let mut link = AviaLink::new(
            "robot",
            Ipv4Addr::new(192, 168, 1, 101),
            Ipv4Addr::new(192, 168, 1, 50),
            BroadcastCode(code),
            0,
            mode,
            Box::new(source),
        );
        let mut pcap = PcapWriter::new(std::io::sink(), TsPrecision::Micro)?;
        let start = Instant::now();
        let mut t = 0u64;
        let mut bytes = 0usize;
        while t <= (sim_s * 1e9) as u64 {
            link.step(t, &mut |w| {
                bytes += w.payload.len();
                pcap.write_udp(w.time_ns, w.src, w.dst, w.payload)
                    .map_err(|e| starc_hil::HilError::config("pcap", e.to_string()))
            })?;
            if t.is_multiple_of(100_000_000) {
                labels.lock().map_err(|_| "poisoned")?.clear();
            }
            t += 100_000;
        }
        let wall = start.elapsed().as_secs_f64();
        let stats = link.stats();
        println!(
            "one Avia ({label} return): {sim_s} s simulated in {wall:.2} s = {:.1}x real time ({} point packets, {:.1} MB)",
            sim_s / wall,
            stats.point_packets,
            bytes as f64 / 1e6
        );
    }
    Ok(())
}
