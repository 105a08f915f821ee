//! Scenario files: a building, its people, the robot's and the responder's routes, and the
//! sensors, in TOML. Every table refuses unknown keys, and every error names its line.
//!
//! Coordinates are metres in the world frame (x east, y north, z up, floor at z = 0 unless a
//! floor says otherwise); angles are degrees in the file.

use crate::error::{HilError, Result};
pub use crate::sim::furniture::{Furniture, FurnitureKind};
use serde::Deserialize;
use std::ops::Range;
use toml::Spanned;

/// The four scenarios modelled on the paper's trials.
pub const SHIPPED: [(&str, &str); 4] = [
    ("lab", include_str!("../../scenarios/lab.toml")),
    ("auditorium", include_str!("../../scenarios/auditorium.toml")),
    ("tactical", include_str!("../../scenarios/tactical.toml")),
    ("corridor", include_str!("../../scenarios/corridor.toml")),
];

/// A whole scenario file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Length of a run when the command line gives none.
    #[serde(default = "default_duration_s")]
    pub duration_s: f64,
    /// Reflectivity (Lambertian albedo, 0..1; above 1 is retro-reflective) of named materials,
    /// added to or overriding the built-in ones ([`builtin_albedo`]).
    #[serde(default)]
    pub materials: std::collections::BTreeMap<String, f64>,
    #[serde(default)]
    pub floors: Vec<Spanned<Floor>>,
    #[serde(default)]
    pub walls: Vec<Spanned<Wall>>,
    #[serde(default)]
    pub boxes: Vec<Spanned<BoxItem>>,
    #[serde(default)]
    pub clutter: Vec<Spanned<Clutter>>,
    /// Furniture by kind (chairs, racks, coat stands...), each expanded into its parts.
    #[serde(default)]
    pub furniture: Vec<Spanned<Furniture>>,
    #[serde(default)]
    pub people: Vec<Spanned<Person>>,
    pub robot: Spanned<Robot>,
    pub responder: Spanned<Responder>,
    #[serde(default)]
    pub avia: AviaModel,
    #[serde(default)]
    pub imu: ImuModels,
    #[serde(default)]
    pub camera: Camera,
}

fn default_duration_s() -> f64 {
    30.0
}

/// A rectangular floor slab with the ceiling above it.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Floor {
    pub min: [f64; 2],
    pub max: [f64; 2],
    #[serde(default)]
    pub z_m: f64,
    /// Ceiling height above this floor; none leaves it open (outdoors).
    pub ceiling_m: Option<f64>,
    #[serde(default = "default_floor_material")]
    pub material: String,
    #[serde(default = "default_ceiling_material")]
    pub ceiling_material: String,
}

fn default_floor_material() -> String {
    "floor_tile".into()
}
fn default_ceiling_material() -> String {
    "ceiling_tile".into()
}

/// A straight wall from `from` to `to` (its centre line), with doors and windows cut out.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wall {
    pub from: [f64; 2],
    pub to: [f64; 2],
    #[serde(default = "default_thickness")]
    pub thickness_m: f64,
    #[serde(default = "default_wall_height")]
    pub height_m: f64,
    #[serde(default)]
    pub base_z_m: f64,
    #[serde(default = "default_wall_material")]
    pub material: String,
    #[serde(default)]
    pub doors: Vec<Door>,
    #[serde(default)]
    pub windows: Vec<Window>,
}

fn default_thickness() -> f64 {
    0.12
}
fn default_wall_height() -> f64 {
    2.8
}
fn default_wall_material() -> String {
    "drywall".into()
}

/// A door in a wall; `at_m` is the distance from the wall's `from` end to the door's centre.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Door {
    pub at_m: f64,
    #[serde(default = "default_door_width")]
    pub width_m: f64,
    #[serde(default = "default_door_height")]
    pub height_m: f64,
    #[serde(default)]
    pub state: DoorState,
}

fn default_door_width() -> f64 {
    0.9
}
fn default_door_height() -> f64 {
    2.05
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DoorState {
    #[default]
    Open,
    Closed,
}

/// An opening in a wall without glass (a pass-through or a broken window).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    pub at_m: f64,
    pub width_m: f64,
    pub sill_m: f64,
    pub height_m: f64,
}

/// Furniture: a box standing on `base_z_m`, optionally repeated (rows of seats, shelves).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxItem {
    #[serde(default)]
    pub name: String,
    /// Centre of the footprint.
    pub at: [f64; 2],
    /// Length (along the box's x after yaw), width, height.
    pub size_m: [f64; 3],
    #[serde(default)]
    pub base_z_m: f64,
    #[serde(default)]
    pub yaw_deg: f64,
    #[serde(default = "default_box_material")]
    pub material: String,
    /// How many copies, each `step_m` (x, y, z) from the previous one.
    #[serde(default = "one")]
    pub count: u32,
    #[serde(default)]
    pub step_m: [f64; 3],
}

fn default_box_material() -> String {
    "wood".into()
}
fn one() -> u32 {
    1
}

/// Small objects scattered in a region, placed from the scenario's own seed (the world does not
/// change with the run's seed).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Clutter {
    pub min: [f64; 2],
    pub max: [f64; 2],
    pub count: u32,
    #[serde(default = "default_clutter_min")]
    pub size_min_m: f64,
    #[serde(default = "default_clutter_max")]
    pub size_max_m: f64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_clutter_material")]
    pub material: String,
}

fn default_clutter_min() -> f64 {
    0.15
}
fn default_clutter_max() -> f64 {
    0.6
}
fn default_clutter_material() -> String {
    "cardboard".into()
}

/// A person: a human shape in a pose, standing still or walking a path.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Person {
    pub name: String,
    #[serde(default)]
    pub pose: PoseKind,
    /// Position of the feet (or of the pelvis when lying).
    pub at: [f64; 2],
    #[serde(default)]
    pub base_z_m: f64,
    #[serde(default)]
    pub yaw_deg: f64,
    #[serde(default = "default_height")]
    pub height_m: f64,
    /// Build: scales the body's widths (limb and torso radii, shoulders and hips apart), not its
    /// height; 1 is the average adult, 0.7..=1.4.
    #[serde(default = "default_build")]
    pub build: f64,
    /// Walks from `at` through these points (only when standing).
    #[serde(default)]
    pub path: Vec<[f64; 2]>,
    #[serde(default = "default_walk_speed")]
    pub speed_m_s: f64,
    /// Walks back and forth along the path rather than stopping at its end.
    #[serde(default = "yes")]
    pub patrol: bool,
}

fn default_height() -> f64 {
    1.75
}
fn default_build() -> f64 {
    1.0
}
fn default_walk_speed() -> f64 {
    1.0
}
fn yes() -> bool {
    true
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseKind {
    #[default]
    Standing,
    Sitting,
    Crouching,
    /// Lying on the floor: a victim.
    Lying,
}

/// The omni-wheel robot.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Robot {
    /// Time the robot's Avia powers on (either device may start first).
    #[serde(default)]
    pub start_s: f64,
    /// Time it stands still after power-on, for the LIO's static initialisation.
    #[serde(default = "default_static_s")]
    pub static_s: f64,
    /// Waypoints (x, y, yaw in degrees); the first is the start pose.
    pub waypoints: Vec<[f64; 3]>,
    #[serde(default = "default_robot_speed")]
    pub max_speed_m_s: f64,
    #[serde(default = "default_robot_accel")]
    pub max_accel_m_s2: f64,
    #[serde(default = "default_robot_yaw_rate")]
    pub max_yaw_rate_deg_s: f64,
    /// Pause at each waypoint.
    #[serde(default = "default_pause")]
    pub pause_s: f64,
    /// Height of the LiDAR's optical centre above the floor.
    #[serde(default = "default_robot_lidar_z")]
    pub lidar_height_m: f64,
    /// Pitch of the LiDAR (positive looks down).
    #[serde(default)]
    pub lidar_pitch_deg: f64,
    /// Wheel layout for the wheel odometry.
    #[serde(default)]
    pub wheels: WheelLayout,
    /// What the motor controllers speak in robot_can.log.
    #[serde(default)]
    pub motors: MotorProtocol,
}

impl Robot {
    /// A robot with the file's defaults but for its waypoints and top speed (what `starc gen`
    /// writes), to time its route before the file exists.
    pub fn with_route(waypoints: Vec<[f64; 3]>, max_speed_m_s: f64) -> Self {
        Robot {
            start_s: 0.0,
            static_s: default_static_s(),
            waypoints,
            max_speed_m_s,
            max_accel_m_s2: default_robot_accel(),
            max_yaw_rate_deg_s: default_robot_yaw_rate(),
            pause_s: default_pause(),
            lidar_height_m: default_robot_lidar_z(),
            lidar_pitch_deg: 0.0,
            wheels: WheelLayout::default(),
            motors: MotorProtocol::default(),
        }
    }
}

impl Responder {
    /// A helmet-mounted responder with the file's defaults but for its route, start and speed.
    pub fn with_route(waypoints: Vec<[f64; 2]>, start_s: f64, speed_m_s: f64) -> Self {
        Responder {
            start_s,
            static_s: default_static_s(),
            mount: Mount::Helmet,
            waypoints,
            yaw_deg: None,
            speed_m_s,
            pause_s: default_pause(),
            rig_height_m: None,
            rig_pitch_deg: 0.0,
            legs: crate::sim::motion::LegProfile::default(),
        }
    }
}

fn default_static_s() -> f64 {
    2.0
}
fn default_robot_speed() -> f64 {
    0.5
}
fn default_robot_accel() -> f64 {
    0.5
}
fn default_robot_yaw_rate() -> f64 {
    45.0
}
fn default_pause() -> f64 {
    0.5
}
fn default_robot_lidar_z() -> f64 {
    0.45
}

/// Wheel layouts the odometry knows (the same models as drivers/base).
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WheelLayout {
    #[default]
    Omni3,
    Omni4,
    Mecanum,
}

/// Motor controllers of the base: DJI C620 feedback (0x201..) or CiA 402 TPDO1 (0x181..).
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MotorProtocol {
    #[default]
    C620,
    Cia402,
}

/// The responder with the helmet or handheld rig.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Responder {
    #[serde(default)]
    pub start_s: f64,
    #[serde(default = "default_static_s")]
    pub static_s: f64,
    #[serde(default)]
    pub mount: Mount,
    /// Waypoints (x, y); the responder faces where it walks.
    pub waypoints: Vec<[f64; 2]>,
    /// Initial heading (the direction of the first leg when absent).
    pub yaw_deg: Option<f64>,
    #[serde(default = "default_responder_speed")]
    pub speed_m_s: f64,
    #[serde(default = "default_pause")]
    pub pause_s: f64,
    /// Overrides the mount's rig height above the floor.
    pub rig_height_m: Option<f64>,
    /// Pitch of the rig (positive looks down).
    #[serde(default)]
    pub rig_pitch_deg: f64,
    /// How each leg of the walk speeds up and slows down (`min_jerk`, the default: over the
    /// whole leg; `walk`: within about a second and a half, as people walk).
    #[serde(default)]
    pub legs: crate::sim::motion::LegProfile,
}

fn default_responder_speed() -> f64 {
    1.0
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mount {
    #[default]
    Helmet,
    Handheld,
}

/// The simulated Avias (both devices).
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct AviaModel {
    pub return_mode: crate::avia::ReturnSetting,
    /// Range noise, 1 sigma (the Avia's datasheet: 2 cm).
    pub range_sigma_m: f64,
    pub min_range_m: f64,
    /// Range at 100 % albedo; darker surfaces fade out earlier (as sqrt of albedo).
    pub max_range_m: f64,
    /// Beam divergence (horizontal, vertical), deg: edges inside the beam give several echoes.
    pub divergence_deg: [f64; 2],
    /// Echoes closer than this merge into one.
    pub min_echo_separation_m: f64,
    /// IMU sample time minus LiDAR time for the same instant (a deliberate sync error).
    pub imu_time_offset_ms: f64,
}

impl Default for AviaModel {
    fn default() -> Self {
        Self {
            return_mode: crate::avia::ReturnSetting::Single,
            range_sigma_m: 0.02,
            min_range_m: 1.0,
            max_range_m: 320.0,
            divergence_deg: [0.28, 0.03],
            min_echo_separation_m: 0.5,
            imu_time_offset_ms: 0.0,
        }
    }
}

/// Noise of the IMUs (continuous-time densities, as datasheets give them).
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuModels {
    /// The Avia's internal IMU (a BMI088), 200 Hz.
    pub internal: ImuNoise,
    /// The robot's external serial IMU.
    pub external: ImuNoise,
    pub external_rate_hz: f64,
    /// Position (m) and roll, pitch, yaw (deg) of the external IMU in the robot's LiDAR frame.
    pub external_mount: [f64; 6],
}

impl Default for ImuModels {
    fn default() -> Self {
        Self {
            internal: ImuNoise::BMI088,
            external: ImuNoise::GX5,
            external_rate_hz: 500.0,
            external_mount: [-0.10, 0.0, -0.12, 0.0, 0.0, 90.0],
        }
    }
}

#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ImuNoise {
    pub gyro_noise_rad_s_sqrt_hz: f64,
    pub accel_noise_m_s2_sqrt_hz: f64,
    pub gyro_bias_walk_rad_s2_sqrt_hz: f64,
    pub accel_bias_walk_m_s3_sqrt_hz: f64,
    /// Spread (1 sigma) of the turn-on biases.
    pub gyro_bias_sigma_rad_s: f64,
    pub accel_bias_sigma_m_s2: f64,
}

impl ImuNoise {
    /// Bosch BMI088 (the Avia's IMU): 0.014 deg/s/sqrt(Hz), 175 ug/sqrt(Hz).
    pub const BMI088: Self = Self {
        gyro_noise_rad_s_sqrt_hz: 2.4e-4,
        accel_noise_m_s2_sqrt_hz: 1.7e-3,
        gyro_bias_walk_rad_s2_sqrt_hz: 2.0e-5,
        accel_bias_walk_m_s3_sqrt_hz: 3.0e-4,
        gyro_bias_sigma_rad_s: 3.0e-3,
        accel_bias_sigma_m_s2: 0.05,
    };
    /// MicroStrain 3DM-GX5 class: 0.005 deg/s/sqrt(Hz), 25 ug/sqrt(Hz).
    pub const GX5: Self = Self {
        gyro_noise_rad_s_sqrt_hz: 8.7e-5,
        accel_noise_m_s2_sqrt_hz: 2.5e-4,
        gyro_bias_walk_rad_s2_sqrt_hz: 4.0e-6,
        accel_bias_walk_m_s3_sqrt_hz: 4.0e-5,
        gyro_bias_sigma_rad_s: 5.0e-4,
        accel_bias_sigma_m_s2: 0.01,
    };
}

/// The responder's first-person camera (a pinhole), for the person masks.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Camera {
    pub width_px: u32,
    pub height_px: u32,
    pub fx_px: f64,
    pub fy_px: f64,
    pub cx_px: f64,
    pub cy_px: f64,
    pub rate_hz: f64,
    /// Camera position (m) and roll, pitch, yaw (deg) in the rig's LiDAR frame; the camera looks
    /// along its own +z (optical frame: x right, y down), so zero angles mean it looks along the
    /// LiDAR's +x.
    pub mount: [f64; 6],
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            width_px: 640,
            height_px: 480,
            fx_px: 460.0,
            fy_px: 460.0,
            cx_px: 320.0,
            cy_px: 240.0,
            rate_hz: 10.0,
            mount: [0.0, 0.0, -0.06, 0.0, 0.0, 0.0],
        }
    }
}

/// Built-in albedos (0..1).
pub fn builtin_albedo(material: &str) -> Option<f64> {
    Some(match material {
        "drywall" => 0.75,
        "concrete" => 0.35,
        "brick" => 0.3,
        "wood" => 0.45,
        "door" => 0.55,
        "metal" => 0.6,
        "fabric" => 0.2,
        "cardboard" => 0.5,
        "plastic" => 0.5,
        "foliage" => 0.25,
        "floor_tile" => 0.4,
        "carpet" => 0.15,
        "ceiling_tile" => 0.8,
        "glass_frame" => 0.3,
        "clothing" => 0.3,
        "skin" => 0.45,
        "retroreflector" => 2.0,
        _ => return None,
    })
}

impl Scenario {
    /// Parses and validates a scenario; `origin` names it in errors (a path or a shipped name).
    pub fn parse(text: &str, origin: &str) -> Result<Self> {
        let scenario: Self = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_of(text, s.start));
            HilError::Scenario { origin: origin.into(), line, reason: e.message().trim().to_string() }
        })?;
        scenario.validate(text, origin)?;
        Ok(scenario)
    }

    /// A shipped scenario by name, or a file.
    pub fn load(name_or_path: &str) -> Result<(Self, String)> {
        if let Some((_, text)) = SHIPPED.iter().find(|(n, _)| *n == name_or_path) {
            return Ok((Self::parse(text, name_or_path)?, (*text).to_string()));
        }
        let text = std::fs::read_to_string(name_or_path).map_err(|e| HilError::Scenario {
            origin: name_or_path.into(),
            line: None,
            reason: format!(
                "{e} (not a file, nor a shipped scenario: {})",
                SHIPPED.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
            ),
        })?;
        Ok((Self::parse(&text, name_or_path)?, text))
    }

    /// The albedo of a material, or an error naming it.
    pub fn albedo(&self, material: &str) -> Option<f64> {
        self.materials.get(material).copied().or_else(|| builtin_albedo(material))
    }

    fn validate(&self, text: &str, origin: &str) -> Result<()> {
        let fail = |span: Range<usize>, reason: String| HilError::Scenario {
            origin: origin.into(),
            line: Some(line_of(text, span.start)),
            reason,
        };
        let material = |span: &Range<usize>, m: &str| match self.albedo(m) {
            Some(a) if a.is_finite() && a >= 0.0 => Ok(()),
            _ => Err(fail(span.clone(), format!("unknown material {m:?} (add it under [materials])"))),
        };
        let positive = |span: &Range<usize>, what: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(fail(span.clone(), format!("{what} must be positive, not {v}")))
            }
        };
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Err(fail(0..0, format!("duration_s must be positive, not {}", self.duration_s)));
        }
        for f in &self.floors {
            let (span, f) = (f.span(), f.get_ref());
            if !(f.max[0] > f.min[0] && f.max[1] > f.min[1]) {
                return Err(fail(span, "floor: max must exceed min on both axes".into()));
            }
            if let Some(c) = f.ceiling_m {
                positive(&span, "ceiling_m", c)?;
            }
            material(&span, &f.material)?;
            material(&span, &f.ceiling_material)?;
        }
        for w in &self.walls {
            let (span, w) = (w.span(), w.get_ref());
            let len = (w.to[0] - w.from[0]).hypot(w.to[1] - w.from[1]);
            positive(&span, "wall length", len)?;
            positive(&span, "thickness_m", w.thickness_m)?;
            positive(&span, "height_m", w.height_m)?;
            material(&span, &w.material)?;
            let mut cuts: Vec<(f64, f64)> = Vec::new();
            for d in &w.doors {
                positive(&span, "door width_m", d.width_m)?;
                positive(&span, "door height_m", d.height_m)?;
                if d.height_m > w.height_m {
                    return Err(fail(span.clone(), format!("door taller ({} m) than its wall", d.height_m)));
                }
                cuts.push((d.at_m - d.width_m / 2.0, d.at_m + d.width_m / 2.0));
            }
            for o in &w.windows {
                positive(&span, "window width_m", o.width_m)?;
                positive(&span, "window height_m", o.height_m)?;
                if o.sill_m < 0.0 || o.sill_m + o.height_m > w.height_m {
                    return Err(fail(span.clone(), "window does not fit in the wall's height".into()));
                }
                cuts.push((o.at_m - o.width_m / 2.0, o.at_m + o.width_m / 2.0));
            }
            cuts.sort_by(|a, b| a.0.total_cmp(&b.0));
            for c in &cuts {
                if c.0 < 0.0 || c.1 > len {
                    return Err(fail(
                        span.clone(),
                        format!("opening {:.2}..{:.2} m outside the {len:.2} m wall", c.0, c.1),
                    ));
                }
            }
            if cuts.windows(2).any(|p| p[1].0 < p[0].1) {
                return Err(fail(span, "openings overlap".into()));
            }
        }
        for b in &self.boxes {
            let (span, b) = (b.span(), b.get_ref());
            for (i, s) in b.size_m.iter().enumerate() {
                positive(&span, ["length", "width", "height"][i], *s)?;
            }
            if b.count == 0 || b.count > 10_000 {
                return Err(fail(span, format!("count must be 1..=10000, not {}", b.count)));
            }
            material(&span, &b.material)?;
        }
        for c in &self.clutter {
            let (span, c) = (c.span(), c.get_ref());
            if !(c.max[0] > c.min[0] && c.max[1] > c.min[1]) {
                return Err(fail(span, "clutter: max must exceed min on both axes".into()));
            }
            positive(&span, "size_min_m", c.size_min_m)?;
            if c.size_max_m < c.size_min_m || c.count > 10_000 {
                return Err(fail(span, "clutter: size_max_m below size_min_m, or count above 10000".into()));
            }
            material(&span, &c.material)?;
        }
        for f in &self.furniture {
            let (span, f) = (f.span(), f.get_ref());
            f.check().map_err(|reason| fail(span.clone(), format!("furniture {reason}")))?;
            for m in f.materials() {
                material(&span, m)?;
            }
        }
        if self.people.len() > 250 {
            return Err(fail(0..0, "at most 250 people (mask values are one byte)".into()));
        }
        for p in &self.people {
            let (span, p) = (p.span(), p.get_ref());
            if !(0.5..=2.5).contains(&p.height_m) {
                return Err(fail(span, format!("height_m {} is not a person's", p.height_m)));
            }
            if !(0.7..=1.4).contains(&p.build) {
                return Err(fail(span, format!("build {} must be in 0.7..=1.4", p.build)));
            }
            if !p.path.is_empty() && p.pose != PoseKind::Standing {
                return Err(fail(span, "only a standing person walks a path".into()));
            }
            positive(&span, "speed_m_s", p.speed_m_s)?;
        }
        let robot = &self.robot;
        let span = robot.span();
        let robot = robot.get_ref();
        if robot.waypoints.is_empty() {
            return Err(fail(span, "robot needs at least one waypoint".into()));
        }
        for (what, v) in [
            ("max_speed_m_s", robot.max_speed_m_s),
            ("max_accel_m_s2", robot.max_accel_m_s2),
            ("max_yaw_rate_deg_s", robot.max_yaw_rate_deg_s),
            ("lidar_height_m", robot.lidar_height_m),
        ] {
            positive(&span, what, v)?;
        }
        if robot.start_s < 0.0 || robot.static_s < 0.0 || robot.pause_s < 0.0 {
            return Err(fail(span, "start_s, static_s and pause_s must not be negative".into()));
        }
        let responder = &self.responder;
        let span = responder.span();
        let responder = responder.get_ref();
        if responder.waypoints.is_empty() {
            return Err(fail(span, "responder needs at least one waypoint".into()));
        }
        positive(&span, "speed_m_s", responder.speed_m_s)?;
        if responder.start_s < 0.0 || responder.static_s < 0.0 || responder.pause_s < 0.0 {
            return Err(fail(span, "start_s, static_s and pause_s must not be negative".into()));
        }
        let a = &self.avia;
        if !(a.range_sigma_m >= 0.0 && a.min_range_m >= 0.0 && a.max_range_m > a.min_range_m) {
            return Err(fail(0..0, "[avia]: need range_sigma_m >= 0 and max_range_m > min_range_m >= 0".into()));
        }
        let c = &self.camera;
        if c.width_px == 0 || c.height_px == 0 || c.width_px > 8192 || c.height_px > 8192 {
            return Err(fail(0..0, "[camera]: width_px and height_px must be 1..=8192".into()));
        }
        if !(c.fx_px > 0.0 && c.fy_px > 0.0 && c.rate_hz > 0.0 && c.rate_hz <= 120.0) {
            return Err(fail(0..0, "[camera]: fx_px, fy_px must be positive and rate_hz in (0, 120]".into()));
        }
        if !(self.imu.external_rate_hz > 0.0 && self.imu.external_rate_hz <= 2000.0) {
            return Err(fail(0..0, "[imu]: external_rate_hz must be in (0, 2000]".into()));
        }
        Ok(())
    }
}

/// 1-based line of byte `offset`.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes().iter().take(offset).filter(|&&b| b == b'\n').count() + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_scenarios_parse() {
        for (name, text) in SHIPPED {
            let s = Scenario::parse(text, name);
            assert!(s.is_ok(), "{name}: {:?}", s.err());
        }
    }

    fn error_of(text: &str) -> String {
        match Scenario::parse(text, "t.toml") {
            Ok(_) => "parsed".into(),
            Err(e) => e.to_string(),
        }
    }

    const MINIMAL: &str = "name = \"t\"\n[robot]\nwaypoints = [[0, 0, 0]]\n[responder]\nwaypoints = [[1, 1]]\n";

    #[test]
    fn errors_name_the_line() {
        assert_eq!(error_of(MINIMAL), "parsed");
        let unknown = format!("{MINIMAL}[avia]\nrange_sigma = 0.1\n");
        assert!(error_of(&unknown).contains("line 7"), "{}", error_of(&unknown));
        assert!(error_of(&unknown).contains("range_sigma"), "{}", error_of(&unknown));
        let door = format!("{MINIMAL}\n[[walls]]\nfrom = [0, 0]\nto = [2, 0]\ndoors = [{{ at_m = 1.9 }}]\n");
        assert!(error_of(&door).contains("line 7") && error_of(&door).contains("outside"), "{}", error_of(&door));
        let mat = format!("{MINIMAL}[[boxes]]\nat = [1, 1]\nsize_m = [1, 1, 1]\nmaterial = \"unobtainium\"\n");
        assert!(error_of(&mat).contains("line 6") && error_of(&mat).contains("unobtainium"), "{}", error_of(&mat));
        let walker = format!("{MINIMAL}[[people]]\nname = \"a\"\nat = [1, 1]\npose = \"lying\"\npath = [[2, 2]]\n");
        assert!(error_of(&walker).contains("only a standing person"), "{}", error_of(&walker));
        let build = format!("{MINIMAL}[[people]]\nname = \"a\"\nat = [1, 1]\nbuild = 1.6\n");
        assert!(error_of(&build).contains("line 6") && error_of(&build).contains("build"), "{}", error_of(&build));
    }

    #[test]
    fn the_responders_legs_are_minimum_jerk_unless_asked_to_walk() {
        use crate::sim::motion::LegProfile;
        let legs = |text: &str| Scenario::parse(text, "t.toml").map(|s| s.responder.get_ref().legs);
        assert_eq!(legs(MINIMAL).ok(), Some(LegProfile::MinJerk));
        let walk = MINIMAL.replace("[responder]\n", "[responder]\nlegs = \"walk\"\n");
        assert_eq!(legs(&walk).ok(), Some(LegProfile::Walk));
        let run = MINIMAL.replace("[responder]\n", "[responder]\nlegs = \"run\"\n");
        assert!(error_of(&run).contains("line 5") && error_of(&run).contains("run"), "{}", error_of(&run));
    }

    #[test]
    fn furniture_table() {
        let ok = format!(
            "{MINIMAL}[[furniture]]\nkind = \"chair\"\nat = [1, 2]\n\n[[furniture]]\nkind = \"rack\"\nat = [5, 2]\n\
             yaw_deg = 90\nbase_z_m = 0.2\nsize_m = [2.0, 1.0, 3.0]\nmaterial = \"wood\"\nname = \"r1\"\n"
        );
        let s = Scenario::parse(&ok, "t.toml");
        let s = match s {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
        let f: Vec<&Furniture> = s.furniture.iter().map(|f| f.get_ref()).collect();
        assert_eq!((f[0].kind, f[0].size_m(), f[0].material()), (FurnitureKind::Chair, [0.45, 0.45, 0.9], "wood"));
        assert_eq!((f[1].kind, f[1].size_m(), f[1].label()), (FurnitureKind::Rack, [2.0, 1.0, 3.0], "r1".into()));
        assert_eq!(s.people.len(), 0);
        let unknown = format!("{MINIMAL}[[furniture]]\nkind = \"throne\"\nat = [1, 1]\n");
        let e = error_of(&unknown);
        assert!(e.contains("line 7") && e.contains("throne") && e.contains("coat_stand"), "{e}");
        let size = format!("{MINIMAL}[[furniture]]\nkind = \"table\"\nat = [1, 1]\nsize_m = [1, -1, 1]\n");
        assert!(error_of(&size).contains("line 6") && error_of(&size).contains("width"), "{}", error_of(&size));
        let mat = format!("{MINIMAL}[[furniture]]\nkind = \"table\"\nat = [1, 1]\nmaterial = \"jade\"\n");
        assert!(error_of(&mat).contains("line 6") && error_of(&mat).contains("jade"), "{}", error_of(&mat));
        let key = format!("{MINIMAL}[[furniture]]\nkind = \"table\"\nat = [1, 1]\ncolour = \"red\"\n");
        assert!(error_of(&key).contains("colour"), "{}", error_of(&key));
    }
}
