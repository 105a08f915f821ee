//! One simulator run: builds the world and the devices from a scenario, steps the virtual
//! network on the simulator's clock (as fast as it can, or paced to the wall clock), and writes
//! the pcap of all Avia traffic and every ground-truth file into the output directory.
//!
//! The simulator clock starts at 0; PTP time (what the packets carry, and the time column of
//! every truth file) is simulator time + [`AviaLink::ptp_offset_ns`] (2026-01-01T00:00:00).

use crate::error::{HilError, Result};
use crate::rng::hash2;
use crate::sim::camera::{write_png, PinholeCamera};
use crate::sim::devices::{ExternalImu, WheelCan};
use crate::sim::imu::ImuSim;
use crate::sim::lan::{AviaLink, LinkStats, Wire};
use crate::sim::lidar::{avia_lidar_imu, AviaSim, LabelSink, LABEL_EMPTY};
use crate::sim::motion::{mount_pose, Motion, ResponderMotion, RobotMotion};
use crate::sim::scenario::{ImuNoise, Scenario};
use crate::sim::truth::{out_err, LabelsWriter, OutFile};
use crate::sim::wheels::WheelOdometry;
use crate::sim::world::World;
use crate::tum::tum_line;
use nalgebra::Isometry3;
use serde::Serialize;
use starc_livox::capture::{PcapWriter, TsPrecision};
use starc_livox::control::BroadcastCode;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Network step: the virtual network's latency and the resolution of pcap times.
const STEP_NS: u64 = 100_000;
/// Ground-truth pose rate.
const TRUTH_HZ: u64 = 200;
/// People's boxes and wheel odometry rate.
const PEOPLE_HZ: u64 = 10;
const WHEEL_HZ: u64 = 100;

/// The robot's Avia and the rig's, each on its own segment.
pub const ROBOT_AVIA_IP: Ipv4Addr = Ipv4Addr::new(192, 168, 1, 101);
pub const ROBOT_HOST_IP: Ipv4Addr = Ipv4Addr::new(192, 168, 1, 50);
pub const FPV_AVIA_IP: Ipv4Addr = Ipv4Addr::new(192, 168, 2, 102);
pub const FPV_HOST_IP: Ipv4Addr = Ipv4Addr::new(192, 168, 2, 50);
pub const ROBOT_CODE: &[u8; 15] = b"3GGDJ8E00100101";
pub const FPV_CODE: &[u8; 15] = b"3GGDJ8E00100102";

/// How to run.
#[derive(Clone, Debug)]
pub struct SimOptions {
    pub out: PathBuf,
    /// Overrides the scenario's duration.
    pub duration_s: Option<f64>,
    pub seed: u64,
    /// Pace the simulation to the wall clock.
    pub realtime: bool,
    /// Render the camera masks (the costliest output).
    pub camera: bool,
}

/// What a run did, written as run.json.
#[derive(Clone, Debug, Serialize)]
pub struct SimSummary {
    pub scenario: String,
    pub seed: u64,
    pub duration_s: f64,
    pub ptp_epoch_ns: i64,
    pub wall_s: f64,
    /// Simulated seconds per wall second.
    pub realtime_factor: f64,
    pub rays_cast: u64,
    pub pcap_records: u64,
    pub devices: Vec<DeviceSummary>,
    pub people: Vec<String>,
    pub camera_frames: u64,
}

#[derive(Clone, Debug, Serialize)]
pub struct DeviceSummary {
    pub name: String,
    pub avia_ip: Ipv4Addr,
    pub host_ip: Ipv4Addr,
    pub broadcast_code: String,
    pub power_on_s: f64,
    pub link: LinkStats,
    pub returns: u64,
    pub person_returns: u64,
}

/// Extrinsics and intrinsics, written as extrinsics.json.
#[derive(Clone, Debug, Serialize)]
struct Calibration {
    convention: &'static str,
    robot_base_lidar: PoseJson,
    robot_lidar_imu: PoseJson,
    robot_lidar_external_imu: PoseJson,
    fpv_lidar_imu: PoseJson,
    fpv_lidar_camera: PoseJson,
    imu_time_offset_ms: f64,
    camera: crate::sim::scenario::Camera,
    internal_imu_noise: ImuNoise,
    external_imu_noise: ImuNoise,
    external_imu_rate_hz: f64,
}

#[derive(Clone, Debug, Serialize)]
struct PoseJson {
    translation_m: [f64; 3],
    /// x, y, z, w
    quaternion_xyzw: [f64; 4],
}

impl From<&Isometry3<f64>> for PoseJson {
    fn from(p: &Isometry3<f64>) -> Self {
        let t = p.translation.vector;
        let q = p.rotation.coords;
        Self { translation_m: [t.x, t.y, t.z], quaternion_xyzw: [q.x, q.y, q.z, q.w] }
    }
}

fn code(bytes: &[u8; 15]) -> BroadcastCode {
    let mut c = [0u8; 16];
    c[..15].copy_from_slice(bytes);
    BroadcastCode(c)
}

fn secs_ns(s: f64) -> u64 {
    (s.max(0.0) * 1e9).round() as u64
}

/// One simulated device: its motion, point source and where its truth goes.
struct DeviceRun {
    name: &'static str,
    motion: Arc<dyn Motion>,
    power_on_ns: u64,
    link: AviaLink,
    labels: LabelSink,
    labels_out: LabelsWriter,
    tum: OutFile,
    returns: u64,
    person_returns: u64,
}

impl DeviceRun {
    fn drain_labels(&mut self) -> Result<()> {
        let batch = std::mem::take(&mut *self.labels.lock().unwrap_or_else(|e| e.into_inner()));
        for p in &batch {
            for &l in &p.labels {
                if l != LABEL_EMPTY {
                    self.returns += 1;
                    self.person_returns += u64::from(l != 0);
                }
            }
            self.labels_out.write(p)?;
        }
        Ok(())
    }
}

/// Runs a scenario. `progress` is called about ten times per simulated second with
/// (simulated seconds done, total).
pub fn run(
    scenario: &Scenario,
    scenario_text: &str,
    opts: &SimOptions,
    progress: &mut dyn FnMut(f64, f64),
) -> Result<SimSummary> {
    let duration_s = opts.duration_s.unwrap_or(scenario.duration_s);
    if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 86_400.0) {
        return Err(HilError::config("duration_s", format!("must be in (0, 86400], not {duration_s}")));
    }
    let out = &opts.out;
    std::fs::create_dir_all(out).map_err(|e| out_err(out, e))?;
    std::fs::write(out.join("scenario.toml"), scenario_text).map_err(|e| out_err(&out.join("scenario.toml"), e))?;
    let ptp_offset = AviaLink::ptp_offset_ns();
    let ptp = |t_ns: u64| t_ns.saturating_add_signed(ptp_offset);

    let world = Arc::new(World::new(scenario));
    let robot_motion = Arc::new(RobotMotion::new(scenario.robot.get_ref()));
    let rig_motion = Arc::new(ResponderMotion::new(scenario.responder.get_ref()));
    let imu_offset_s = scenario.avia.imu_time_offset_ms * 1e-3;
    let seed = opts.seed;

    let mut devices = Vec::new();
    let mut counters = Vec::new();
    type DeviceSpec = (&'static str, Arc<dyn Motion>, f64, Ipv4Addr, Ipv4Addr, &'static [u8; 15]);
    let specs: [DeviceSpec; 2] = [
        ("robot", robot_motion.clone(), scenario.robot.get_ref().start_s, ROBOT_AVIA_IP, ROBOT_HOST_IP, ROBOT_CODE),
        ("fpv", rig_motion.clone(), scenario.responder.get_ref().start_s, FPV_AVIA_IP, FPV_HOST_IP, FPV_CODE),
    ];
    for (i, (name, motion, start_s, avia_ip, host_ip, code_bytes)) in specs.into_iter().enumerate() {
        let device_seed = hash2(seed, i as u64 + 1);
        let imu = ImuSim::new(
            motion.clone(),
            avia_lidar_imu(),
            scenario.imu.internal,
            200.0,
            imu_offset_s,
            hash2(device_seed, 1),
        );
        let labels: LabelSink = Arc::new(Mutex::new(Vec::new()));
        let source = AviaSim::new(world.clone(), motion.clone(), scenario.avia.clone(), imu, device_seed)
            .with_labels(labels.clone());
        counters.push(source.cast_counter());
        let power_on_ns = secs_ns(start_s);
        let link = AviaLink::new(
            name,
            avia_ip,
            host_ip,
            code(code_bytes),
            power_on_ns,
            scenario.avia.return_mode,
            Box::new(source),
        );
        devices.push(DeviceRun {
            name,
            motion,
            power_on_ns,
            link,
            labels,
            labels_out: LabelsWriter::create(&out.join(format!("labels_{name}.bin")), ptp_offset)?,
            tum: OutFile::create(&out.join(format!("gt_{name}.tum")))?,
            returns: 0,
            person_returns: 0,
        });
    }

    let pcap_path = out.join("avia.pcap");
    let mut pcap = PcapWriter::create(&pcap_path, TsPrecision::Micro).map_err(|e| out_err(&pcap_path, e))?;
    let mut people_csv = OutFile::create(&out.join("people.csv"))?;
    people_csv.line("time_s,label,name,pose,centre_x_m,centre_y_m,centre_z_m,length_m,width_m,height_m,yaw_rad")?;
    let ext = &scenario.imu;
    let lidar_ext_imu = mount_pose(&ext.external_mount);
    let ext_imu_sim =
        ImuSim::new(robot_motion.clone(), lidar_ext_imu, ext.external, ext.external_rate_hz, 0.0, hash2(seed, 77));
    let robot_start_ns = secs_ns(scenario.robot.get_ref().start_s);
    let mut ext_imu = ExternalImu::create(out, ext_imu_sim, ext.external_rate_hz, robot_start_ns, ptp_offset)?;
    let mut wheels = WheelOdometry::new(scenario.robot.get_ref().wheels, hash2(seed, 78))?;
    let mut wheel_csv = OutFile::create(&out.join("robot_wheels.csv"))?;
    let n_wheels = wheels.wheels();
    let wheel_cols: Vec<String> = (0..n_wheels).map(|i| format!("wheel{i}_rad_s")).collect();
    wheel_csv.line(&format!("time_s,{},vx_m_s,vy_m_s,wz_rad_s", wheel_cols.join(",")))?;
    let mut wheel_can = WheelCan::create(out, scenario.robot.get_ref().motors, n_wheels)?;
    let mut wheel_tum = OutFile::create(&out.join("robot_wheel_odom.tum"))?;
    let camera = PinholeCamera::new(scenario.camera.clone());
    let cam_dir = out.join("camera");
    let mut frames_csv = None;
    if opts.camera {
        for sub in ["see_through", "visible"] {
            std::fs::create_dir_all(cam_dir.join(sub)).map_err(|e| out_err(&cam_dir, e))?;
        }
        let mut f = OutFile::create(&cam_dir.join("frames.csv"))?;
        f.line("frame,time_s,tx,ty,tz,qx,qy,qz,qw")?;
        frames_csv = Some(f);
    }
    let cam_period_ns = (1e9 / scenario.camera.rate_hz).round().max(1.0) as u64;
    let rig_start_ns = secs_ns(scenario.responder.get_ref().start_s);

    let end_ns = secs_ns(duration_s);
    let wall_start = Instant::now();
    let mut camera_frames = 0u64;
    let mut next_cam_ns = rig_start_ns;
    let mut t = 0u64;
    while t <= end_ns {
        let mut tap =
            |w: Wire<'_>| pcap.write_udp(ptp(w.time_ns), w.src, w.dst, w.payload).map_err(|e| out_err(&pcap_path, e));
        for d in &mut devices {
            d.link.step(t, &mut tap)?;
        }
        if t.is_multiple_of(1_000_000_000 / TRUTH_HZ) {
            for d in &mut devices {
                if t >= d.power_on_ns {
                    d.tum.line(&tum_line(ptp(t), &d.motion.lidar_pose(t as f64 * 1e-9)))?;
                }
            }
        }
        let ts = t as f64 * 1e-9;
        if t.is_multiple_of(1_000_000_000 / PEOPLE_HZ) {
            for p in &world.people {
                let b = p.body_at(ts);
                people_csv.line(&format!(
                    "{:.6},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.5}",
                    ptp(t) as f64 * 1e-9,
                    p.label,
                    p.name.replace(',', ";"),
                    serde_json::to_string(&p.pose).unwrap_or_default().trim_matches('"'),
                    b.box_centre.x,
                    b.box_centre.y,
                    b.box_centre.z,
                    b.box_size.x,
                    b.box_size.y,
                    b.box_size.z,
                    b.yaw_rad
                ))?;
            }
            for d in &mut devices {
                d.drain_labels()?;
            }
            progress(ts, duration_s);
        }
        if t >= robot_start_ns && t.is_multiple_of(1_000_000_000 / WHEEL_HZ) {
            let r = wheels.sample(&robot_motion, ts);
            wheel_can.write(ptp(t), &r.wheel_rad_s)?;
            let rates: Vec<String> = r.wheel_rad_s.iter().map(|w| format!("{w:.5}")).collect();
            wheel_csv.line(&format!(
                "{:.6},{},{:.5},{:.5},{:.5}",
                ptp(t) as f64 * 1e-9,
                rates.join(","),
                r.body[0],
                r.body[1],
                r.body[2]
            ))?;
            let odom = crate::sim::motion::pose_xyz_rpy(
                nalgebra::Vector3::new(r.pose[0], r.pose[1], 0.0),
                0.0,
                0.0,
                r.pose[2],
            );
            wheel_tum.line(&tum_line(ptp(t), &odom))?;
        }
        ext_imu.step(t)?;
        if let Some(frames) = frames_csv.as_mut() {
            if t >= next_cam_ns {
                let lidar = rig_motion.lidar_pose(ts);
                let masks = camera.render(&world, &world.bodies_at(ts), &lidar);
                let name = format!("{camera_frames:06}.png");
                write_png(&cam_dir.join("see_through").join(&name), masks.width, masks.height, &masks.see_through)?;
                write_png(&cam_dir.join("visible").join(&name), masks.width, masks.height, &masks.visible)?;
                let pose = tum_line(ptp(t), &(lidar * camera.lidar_camera));
                frames.line(&format!("{camera_frames},{}", pose.replace(' ', ",")))?;
                camera_frames += 1;
                next_cam_ns += cam_period_ns;
            }
        }
        if opts.realtime && t.is_multiple_of(10_000_000) {
            let due = Duration::from_nanos(t);
            if let Some(wait) = due.checked_sub(wall_start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        t += STEP_NS;
    }
    for d in &mut devices {
        d.drain_labels()?;
    }
    let wall_s = wall_start.elapsed().as_secs_f64();
    let pcap_records = pcap.records();
    pcap.finish().map_err(|e| out_err(&pcap_path, e))?;
    let mut summaries = Vec::new();
    for d in devices {
        summaries.push(DeviceSummary {
            name: d.name.into(),
            avia_ip: d.link.device_ip(),
            host_ip: d.link.host_ip(),
            broadcast_code: d.link.broadcast_code().to_string(),
            power_on_s: d.power_on_ns as f64 * 1e-9,
            link: d.link.stats(),
            returns: d.returns,
            person_returns: d.person_returns,
        });
        d.labels_out.finish()?;
        d.tum.finish()?;
    }
    for f in [people_csv, wheel_csv, wheel_tum] {
        f.finish()?;
    }
    ext_imu.finish()?;
    wheel_can.finish()?;
    if let Some(f) = frames_csv {
        f.finish()?;
    }
    let robot = scenario.robot.get_ref();
    let calibration = Calibration {
        convention: "T_a_b maps points in frame b into frame a; quaternions x, y, z, w",
        robot_base_lidar: (&crate::sim::motion::pose_xyz_rpy(
            nalgebra::Vector3::new(0.0, 0.0, robot.lidar_height_m),
            0.0,
            robot.lidar_pitch_deg.to_radians(),
            0.0,
        ))
            .into(),
        robot_lidar_imu: (&avia_lidar_imu()).into(),
        robot_lidar_external_imu: (&lidar_ext_imu).into(),
        fpv_lidar_imu: (&avia_lidar_imu()).into(),
        fpv_lidar_camera: (&camera.lidar_camera).into(),
        imu_time_offset_ms: scenario.avia.imu_time_offset_ms,
        camera: scenario.camera.clone(),
        internal_imu_noise: scenario.imu.internal,
        external_imu_noise: scenario.imu.external,
        external_imu_rate_hz: scenario.imu.external_rate_hz,
    };
    write_json(&out.join("extrinsics.json"), &calibration)?;
    let summary = SimSummary {
        scenario: scenario.name.clone(),
        seed,
        duration_s,
        ptp_epoch_ns: ptp_offset,
        wall_s,
        realtime_factor: duration_s / wall_s.max(1e-9),
        rays_cast: counters.iter().map(|c| c.load(Ordering::Relaxed)).sum(),
        pcap_records,
        devices: summaries,
        people: world.people.iter().map(|p| p.name.clone()).collect(),
        camera_frames,
    };
    write_json(&out.join("run.json"), &summary)?;
    Ok(summary)
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| out_err(path, e))?;
    std::fs::write(path, text + "\n").map_err(|e| out_err(path, e))
}
