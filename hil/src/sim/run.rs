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
use crate::sim::driven::DrivenTrack;
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
use std::fs::File;
use std::io::BufWriter;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
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
    /// Rays its point source has cast.
    casts: Arc<AtomicU64>,
    labels: LabelSink,
    labels_out: LabelsWriter,
    tum: OutFile,
    returns: u64,
    person_returns: u64,
}

/// What sets one device apart: name, motion, power-on time (s), addresses, broadcast code.
type DeviceSpec = (&'static str, Arc<dyn Motion>, f64, Ipv4Addr, Ipv4Addr, &'static [u8; 15]);

impl DeviceRun {
    /// Device `i` of the run (its seed derives from `i`), its truth files created in `out`.
    fn create(
        i: usize,
        spec: DeviceSpec,
        scenario: &Scenario,
        world: &Arc<World>,
        out: &Path,
        seed: u64,
    ) -> Result<Self> {
        let (name, motion, start_s, avia_ip, host_ip, code_bytes) = spec;
        let device_seed = hash2(seed, i as u64 + 1);
        let imu_offset_s = scenario.avia.imu_time_offset_ms * 1e-3;
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
        let casts = source.cast_counter();
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
        Ok(Self {
            name,
            motion,
            power_on_ns,
            link,
            casts,
            labels,
            labels_out: LabelsWriter::create(&out.join(format!("labels_{name}.bin")), AviaLink::ptp_offset_ns())?,
            tum: OutFile::create(&out.join(format!("gt_{name}.tum")))?,
            returns: 0,
            person_returns: 0,
        })
    }

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

    /// What the device did, once its truth files are closed.
    fn finish(self) -> Result<DeviceSummary> {
        let summary = DeviceSummary {
            name: self.name.into(),
            avia_ip: self.link.device_ip(),
            host_ip: self.link.host_ip(),
            broadcast_code: self.link.broadcast_code().to_string(),
            power_on_s: self.power_on_ns as f64 * 1e-9,
            link: self.link.stats(),
            returns: self.returns,
            person_returns: self.person_returns,
        };
        self.labels_out.finish()?;
        self.tum.finish()?;
        Ok(summary)
    }
}

/// What a link's traffic goes to: the pcap, and the robot's driver when there is one.
fn tap<'a, 'd: 'a>(
    pcap: &'a mut PcapWriter<BufWriter<File>>,
    pcap_path: &'a Path,
    mut driver: Option<&'a mut (dyn RobotDriver + 'd)>,
) -> impl FnMut(Wire<'_>) -> Result<()> + use<'a, 'd> {
    move |w: Wire<'_>| {
        pcap.write_udp(ptp_ns(w.time_ns), w.src, w.dst, w.payload).map_err(|e| out_err(pcap_path, e))?;
        match driver.as_deref_mut() {
            Some(d) => d.on_wire(&w),
            None => Ok(()),
        }
    }
}

/// PTP time of simulator time `t_ns` (see the module docs).
fn ptp_ns(t_ns: u64) -> u64 {
    t_ns.saturating_add_signed(AviaLink::ptp_offset_ns())
}

/// What drives the robot in a closed loop instead of its waypoints (`starc sim --explore`).
/// It sees the robot's Avia traffic as its host receives it, and keeps the robot's track
/// ([`DrivenTrack`]) a few milliseconds ahead of the simulator's clock, so that the devices
/// reading it (the LiDAR, both IMUs, the wheels) always find it known.
pub trait RobotDriver {
    /// The track the robot moves along; the simulator reads it, the driver appends to it.
    /// None: the robot follows its waypoints, and the driver only watches.
    fn track(&self) -> Option<DrivenTrack>;
    /// One datagram on the robot's Avia network (both ways), at simulator time `w.time_ns`.
    fn on_wire(&mut self, w: &Wire<'_>) -> Result<()>;
    /// Before the step at simulator time `t_ns`, when the steps before it have been seen: the
    /// track must then reach past `t_ns + 2 ms` (the IMUs' differences look 1 ms ahead).
    fn before_step(&mut self, t_ns: u64) -> Result<()>;
}

/// Runs a scenario. `progress` is called about ten times per simulated second with
/// (simulated seconds done, total).
pub fn run(
    scenario: &Scenario,
    scenario_text: &str,
    opts: &SimOptions,
    progress: &mut dyn FnMut(f64, f64),
) -> Result<SimSummary> {
    run_driven(scenario, scenario_text, opts, None, progress)
}

/// [`run`], with `driver` beside the robot when one is given: it drives the robot when it has a
/// track (its waypoints past the first are then ignored), and sees its Avia's traffic.
pub fn run_driven<'d>(
    scenario: &Scenario,
    scenario_text: &str,
    opts: &SimOptions,
    mut driver: Option<&mut (dyn RobotDriver + 'd)>,
    progress: &mut dyn FnMut(f64, f64),
) -> Result<SimSummary> {
    let duration_s = opts.duration_s.unwrap_or(scenario.duration_s);
    if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 86_400.0) {
        return Err(HilError::config("duration_s", format!("must be in (0, 86400], not {duration_s}")));
    }
    let out = &opts.out;
    std::fs::create_dir_all(out).map_err(|e| out_err(out, e))?;
    std::fs::write(out.join("scenario.toml"), scenario_text).map_err(|e| out_err(&out.join("scenario.toml"), e))?;
    let track = driver.as_ref().and_then(|d| d.track());
    let mut sim = Sim::new(scenario, opts, track)?;
    let end_ns = secs_ns(duration_s);
    let wall_start = Instant::now();
    let mut t = 0u64;
    while t <= end_ns {
        if let Some(d) = driver.as_deref_mut() {
            d.before_step(t)?;
        }
        sim.step(t, driver.as_deref_mut(), &mut |ts| progress(ts, duration_s))?;
        if opts.realtime && t.is_multiple_of(10_000_000) {
            let due = Duration::from_nanos(t);
            if let Some(wait) = due.checked_sub(wall_start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        t += STEP_NS;
    }
    for d in &mut sim.devices {
        d.drain_labels()?;
    }
    let wall_s = wall_start.elapsed().as_secs_f64();
    sim.finish(scenario, duration_s, wall_s)
}

/// One run between its steps: the world, the devices and every output file. Each step writes
/// in a fixed order, so a seed gives the same bytes.
struct Sim {
    out: PathBuf,
    seed: u64,
    world: Arc<World>,
    robot_motion: Arc<RobotMotion>,
    rig_motion: Arc<ResponderMotion>,
    devices: Vec<DeviceRun>,
    pcap: PcapWriter<BufWriter<File>>,
    pcap_path: PathBuf,
    people_csv: OutFile,
    robot: RobotSensors,
    camera: CameraFrames,
}

impl Sim {
    /// Builds the world and the devices and creates every output file in `opts.out`.
    fn new(scenario: &Scenario, opts: &SimOptions, track: Option<DrivenTrack>) -> Result<Self> {
        let out = &opts.out;
        let world = Arc::new(World::new(scenario));
        let robot_motion = Arc::new(match track {
            Some(track) => RobotMotion::driven(scenario.robot.get_ref(), track),
            None => RobotMotion::new(scenario.robot.get_ref()),
        });
        let rig_motion = Arc::new(ResponderMotion::new(scenario.responder.get_ref()));
        let specs: [DeviceSpec; 2] = [
            ("robot", robot_motion.clone(), scenario.robot.get_ref().start_s, ROBOT_AVIA_IP, ROBOT_HOST_IP, ROBOT_CODE),
            ("fpv", rig_motion.clone(), scenario.responder.get_ref().start_s, FPV_AVIA_IP, FPV_HOST_IP, FPV_CODE),
        ];
        let mut devices = Vec::new();
        for (i, spec) in specs.into_iter().enumerate() {
            devices.push(DeviceRun::create(i, spec, scenario, &world, out, opts.seed)?);
        }
        let pcap_path = out.join("avia.pcap");
        let pcap = PcapWriter::create(&pcap_path, TsPrecision::Micro).map_err(|e| out_err(&pcap_path, e))?;
        let mut people_csv = OutFile::create(&out.join("people.csv"))?;
        people_csv.line("time_s,label,name,pose,centre_x_m,centre_y_m,centre_z_m,length_m,width_m,height_m,yaw_rad")?;
        let robot = RobotSensors::create(scenario, &robot_motion, out, opts.seed)?;
        let camera = CameraFrames::create(scenario, out, opts.camera)?;
        Ok(Self {
            out: out.clone(),
            seed: opts.seed,
            world,
            robot_motion,
            rig_motion,
            devices,
            pcap,
            pcap_path,
            people_csv,
            robot,
            camera,
        })
    }

    /// One network step at simulator time `t`: the links' traffic into the pcap, then every
    /// truth file, sensor and camera frame due at `t`. `progress` gets the simulated seconds.
    fn step<'d>(
        &mut self,
        t: u64,
        driver: Option<&mut (dyn RobotDriver + 'd)>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<()> {
        self.step_links(t, driver)?;
        if t.is_multiple_of(1_000_000_000 / TRUTH_HZ) {
            for d in &mut self.devices {
                if t >= d.power_on_ns {
                    d.tum.line(&tum_line(ptp_ns(t), &d.motion.lidar_pose(t as f64 * 1e-9)))?;
                }
            }
        }
        if t.is_multiple_of(1_000_000_000 / PEOPLE_HZ) {
            self.write_people(t)?;
            for d in &mut self.devices {
                d.drain_labels()?;
            }
            progress(t as f64 * 1e-9);
        }
        if t >= self.robot.start_ns && t.is_multiple_of(1_000_000_000 / WHEEL_HZ) {
            self.robot.write_wheels(&self.robot_motion, t)?;
        }
        self.robot.ext_imu.step(t)?;
        self.camera.step(&self.world, &self.rig_motion, t)
    }

    /// Steps every device's link to `t`, their packets into the pcap (and the robot's to its
    /// driver).
    fn step_links<'d>(&mut self, t: u64, mut driver: Option<&mut (dyn RobotDriver + 'd)>) -> Result<()> {
        let (pcap, pcap_path) = (&mut self.pcap, &self.pcap_path);
        for d in &mut self.devices {
            let to_driver = if d.name == "robot" { driver.as_deref_mut() } else { None };
            let mut tap = tap(pcap, pcap_path, to_driver);
            d.link.step(t, &mut tap)?;
        }
        Ok(())
    }

    /// Every person's box at `t`, one line each.
    fn write_people(&mut self, t: u64) -> Result<()> {
        let ts = t as f64 * 1e-9;
        for p in &self.world.people {
            let b = p.body_at(ts);
            self.people_csv.line(&format!(
                "{:.6},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.5}",
                ptp_ns(t) as f64 * 1e-9,
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
        Ok(())
    }

    /// Closes every output file and writes extrinsics.json and run.json.
    fn finish(self, scenario: &Scenario, duration_s: f64, wall_s: f64) -> Result<SimSummary> {
        let pcap_records = self.pcap.records();
        self.pcap.finish().map_err(|e| out_err(&self.pcap_path, e))?;
        let rays_cast = self.devices.iter().map(|d| d.casts.load(Ordering::Relaxed)).sum();
        let mut summaries = Vec::new();
        for d in self.devices {
            summaries.push(d.finish()?);
        }
        self.people_csv.finish()?;
        let lidar_ext_imu = self.robot.finish()?;
        let (lidar_camera, camera_frames) = (self.camera.camera.lidar_camera, self.camera.frames);
        self.camera.finish()?;
        write_json(&self.out.join("extrinsics.json"), &calibration(scenario, &lidar_ext_imu, &lidar_camera))?;
        let summary = SimSummary {
            scenario: scenario.name.clone(),
            seed: self.seed,
            duration_s,
            ptp_epoch_ns: AviaLink::ptp_offset_ns(),
            wall_s,
            realtime_factor: duration_s / wall_s.max(1e-9),
            rays_cast,
            pcap_records,
            devices: summaries,
            people: self.world.people.iter().map(|p| p.name.clone()).collect(),
            camera_frames,
        };
        write_json(&self.out.join("run.json"), &summary)?;
        Ok(summary)
    }
}

/// The robot's sensors beside its Avia, from the robot's start: the external IMU and the wheel
/// odometry (its CAN log, CSV and TUM).
struct RobotSensors {
    start_ns: u64,
    /// Where the external IMU sits on the LiDAR.
    lidar_ext_imu: Isometry3<f64>,
    ext_imu: ExternalImu,
    wheels: WheelOdometry,
    wheel_csv: OutFile,
    wheel_can: WheelCan,
    wheel_tum: OutFile,
}

impl RobotSensors {
    fn create(scenario: &Scenario, robot_motion: &Arc<RobotMotion>, out: &Path, seed: u64) -> Result<Self> {
        let ext = &scenario.imu;
        let lidar_ext_imu = mount_pose(&ext.external_mount);
        let ext_imu_sim =
            ImuSim::new(robot_motion.clone(), lidar_ext_imu, ext.external, ext.external_rate_hz, 0.0, hash2(seed, 77));
        let start_ns = secs_ns(scenario.robot.get_ref().start_s);
        let ptp_offset = AviaLink::ptp_offset_ns();
        let ext_imu = ExternalImu::create(out, ext_imu_sim, ext.external_rate_hz, start_ns, ptp_offset)?;
        let wheels = WheelOdometry::new(scenario.robot.get_ref().wheels, hash2(seed, 78))?;
        let mut wheel_csv = OutFile::create(&out.join("robot_wheels.csv"))?;
        let n_wheels = wheels.wheels();
        let wheel_cols: Vec<String> = (0..n_wheels).map(|i| format!("wheel{i}_rad_s")).collect();
        wheel_csv.line(&format!("time_s,{},vx_m_s,vy_m_s,wz_rad_s", wheel_cols.join(",")))?;
        let wheel_can = WheelCan::create(out, scenario.robot.get_ref().motors, n_wheels)?;
        let wheel_tum = OutFile::create(&out.join("robot_wheel_odom.tum"))?;
        Ok(Self { start_ns, lidar_ext_imu, ext_imu, wheels, wheel_csv, wheel_can, wheel_tum })
    }

    /// One wheel odometry sample at `t`: the motors' rates on CAN and in the CSV, the integrated
    /// pose in the TUM file.
    fn write_wheels(&mut self, robot_motion: &RobotMotion, t: u64) -> Result<()> {
        let r = self.wheels.sample(robot_motion, t as f64 * 1e-9);
        self.wheel_can.write(ptp_ns(t), &r.wheel_rad_s)?;
        let rates: Vec<String> = r.wheel_rad_s.iter().map(|w| format!("{w:.5}")).collect();
        self.wheel_csv.line(&format!(
            "{:.6},{},{:.5},{:.5},{:.5}",
            ptp_ns(t) as f64 * 1e-9,
            rates.join(","),
            r.body[0],
            r.body[1],
            r.body[2]
        ))?;
        let odom =
            crate::sim::motion::pose_xyz_rpy(nalgebra::Vector3::new(r.pose[0], r.pose[1], 0.0), 0.0, 0.0, r.pose[2]);
        self.wheel_tum.line(&tum_line(ptp_ns(t), &odom))
    }

    /// Closes the files; returns the external IMU's mount (for the calibration).
    fn finish(self) -> Result<Isometry3<f64>> {
        for f in [self.wheel_csv, self.wheel_tum] {
            f.finish()?;
        }
        self.ext_imu.finish()?;
        self.wheel_can.finish()?;
        Ok(self.lidar_ext_imu)
    }
}

/// The rig camera's masks and poses, one frame per camera period from the responder's start.
struct CameraFrames {
    camera: PinholeCamera,
    dir: PathBuf,
    /// frames.csv; None when the masks are not rendered.
    csv: Option<OutFile>,
    period_ns: u64,
    next_ns: u64,
    /// Frames written so far.
    frames: u64,
}

impl CameraFrames {
    fn create(scenario: &Scenario, out: &Path, render: bool) -> Result<Self> {
        let camera = PinholeCamera::new(scenario.camera.clone());
        let dir = out.join("camera");
        let mut csv = None;
        if render {
            for sub in ["see_through", "visible"] {
                std::fs::create_dir_all(dir.join(sub)).map_err(|e| out_err(&dir, e))?;
            }
            let mut f = OutFile::create(&dir.join("frames.csv"))?;
            f.line("frame,time_s,tx,ty,tz,qx,qy,qz,qw")?;
            csv = Some(f);
        }
        let period_ns = (1e9 / scenario.camera.rate_hz).round().max(1.0) as u64;
        let next_ns = secs_ns(scenario.responder.get_ref().start_s);
        Ok(Self { camera, dir, csv, period_ns, next_ns, frames: 0 })
    }

    /// Renders and writes the frame due at `t`, if one is.
    fn step(&mut self, world: &World, rig_motion: &ResponderMotion, t: u64) -> Result<()> {
        let Some(csv) = self.csv.as_mut() else { return Ok(()) };
        if t < self.next_ns {
            return Ok(());
        }
        let ts = t as f64 * 1e-9;
        let lidar = rig_motion.lidar_pose(ts);
        let masks = self.camera.render(world, &world.bodies_at(ts), &lidar);
        let name = format!("{:06}.png", self.frames);
        write_png(&self.dir.join("see_through").join(&name), masks.width, masks.height, &masks.see_through)?;
        write_png(&self.dir.join("visible").join(&name), masks.width, masks.height, &masks.visible)?;
        let pose = tum_line(ptp_ns(t), &(lidar * self.camera.lidar_camera));
        csv.line(&format!("{},{}", self.frames, pose.replace(' ', ",")))?;
        self.frames += 1;
        self.next_ns += self.period_ns;
        Ok(())
    }

    fn finish(self) -> Result<()> {
        match self.csv {
            Some(f) => f.finish(),
            None => Ok(()),
        }
    }
}

/// The extrinsics and intrinsics of the run (extrinsics.json).
fn calibration(scenario: &Scenario, lidar_ext_imu: &Isometry3<f64>, lidar_camera: &Isometry3<f64>) -> Calibration {
    let robot = scenario.robot.get_ref();
    Calibration {
        convention: "T_a_b maps points in frame b into frame a; quaternions x, y, z, w",
        robot_base_lidar: (&crate::sim::motion::pose_xyz_rpy(
            nalgebra::Vector3::new(0.0, 0.0, robot.lidar_height_m),
            0.0,
            robot.lidar_pitch_deg.to_radians(),
            0.0,
        ))
            .into(),
        robot_lidar_imu: (&avia_lidar_imu()).into(),
        robot_lidar_external_imu: lidar_ext_imu.into(),
        fpv_lidar_imu: (&avia_lidar_imu()).into(),
        fpv_lidar_camera: lidar_camera.into(),
        imu_time_offset_ms: scenario.avia.imu_time_offset_ms,
        camera: scenario.camera.clone(),
        internal_imu_noise: scenario.imu.internal,
        external_imu_noise: scenario.imu.external,
        external_imu_rate_hz: scenario.imu.external_rate_hz,
    }
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| out_err(path, e))?;
    std::fs::write(path, text + "\n").map_err(|e| out_err(path, e))
}
