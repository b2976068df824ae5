//! The lab configuration (TOML): where things are in the enclosure, and the limits every motion
//! must respect. Every field has a documented default, so an empty file is the default lab.
//!
//! Frames: the **lab frame** has its origin at a floor corner of the enclosure, x along its 8 ft
//! length, y along its 4 ft width, z up. The **base frame** is the arm's (xArm7 base, z up). The
//! arm base sits in the lab at `arm.base_in_lab_m` turned by `arm.base_yaw_deg` about z.

use crate::geometry::Capsule;
use crate::joint_table::JointTable;
use crate::kinematics::{CameraBody, DOF, MAX_JOINT_SPEED};
use hitl_hal::Pose;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Why a lab configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read lab config {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("lab config {path} is not valid TOML for hitl: {message}")]
    Parse { path: String, message: String },
    #[error("lab config: {0}")]
    Invalid(String),
}

/// The whole lab configuration. `LabConfig::default()` is the DreamSat-Bench enclosure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct LabConfig {
    pub enclosure: Enclosure,
    pub arm: ArmPlacement,
    pub target: Target,
    pub light: LightPlacement,
    pub camera: CameraMount,
    pub margins: Margins,
    pub limits: JointLimits,
    pub interlocks: Interlocks,
    pub scene: SceneConfig,
    /// The calibration board on the target's mount (`hitl calibrate`); absent: none mounted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub board: Option<BoardPlacement>,
    /// Where the camera mount and target pose came from: absent means nominal (hand-measured);
    /// `hitl calibrate` writes this block with the values it recovered.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationProvenance>,
}

/// The enclosure box in the lab frame, from the origin to `size_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Enclosure {
    /// Inner size (x, y, z), metres. Default 8 ft x 4 ft x 4 ft = 2.438 x 1.219 x 1.219 m.
    pub size_m: [f64; 3],
}

impl Default for Enclosure {
    fn default() -> Self {
        Self { size_m: [2.438, 1.219, 1.219] }
    }
}

/// The arm: where its base sits in the lab, and which joint-limit table it enforces.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArmPlacement {
    /// Base origin in the lab frame, metres. Default: 0.9 m along, centred across, on the floor.
    pub base_in_lab_m: [f64; 3],
    /// Base rotation about the lab's z axis, degrees. Default 0 (base x along the lab's x).
    pub base_yaw_deg: f64,
    /// The xArm7 joint-limit table offline checks and plans use: `xarm7-current` (default, the
    /// tighter one: arms whose serial digits [2:6] are 1305..8499) or `xarm7-legacy` (the first
    /// arms). On connect the arm's own table, from its serial number, is checked too.
    pub joint_table: JointTable,
    /// The arm's rest pose, radians: where a completed run's retreat and `hitl park` bring the
    /// arm, and where `hitl check` and `hitl plan` plan the approach from. Default
    /// [`DEFAULT_REST_Q`], the pose the embedded stub powers up in. Within the joint table less
    /// `margins.joint_limit_rad`.
    pub rest_q: [f64; DOF],
}

/// The default rest pose, radians: the embedded stub's power-up pose. In the default lab the
/// camera is 0.16 m from the target centre, every capsule at least 0.098 m from the keep-outs and
/// 0.2 m from the enclosure's faces.
pub const DEFAULT_REST_Q: [f64; DOF] = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];

impl Default for ArmPlacement {
    fn default() -> Self {
        Self {
            base_in_lab_m: [0.9, 0.6095, 0.0],
            base_yaw_deg: 0.0,
            joint_table: JointTable::default(),
            rest_q: DEFAULT_REST_Q,
        }
    }
}

/// The target (spacecraft model) on its tripod.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Target {
    /// Target centre in the arm-base frame, metres. Default (0.45, 0, 0.30).
    pub position_base_m: [f64; 3],
    /// Target orientation in the base frame as roll, pitch, yaw (degrees, applied z-y-x).
    pub rpy_deg: [f64; 3],
    /// Radius of the keep-out sphere around the target centre, metres. Default 0.04.
    pub keepout_radius_m: f64,
    /// Radius of the tripod column from the floor up to the target, metres. Default 0.03.
    pub tripod_radius_m: f64,
    /// Greatest dimension of the real spacecraft, metres (the paper scales every model to 2 m).
    pub real_size_m: f64,
    /// Greatest dimension of the physical (printed) model, metres. When set, the planner's scale
    /// is `model_size_m / real_size_m` instead of the paper's workspace scale.
    pub model_size_m: Option<f64>,
}

impl Default for Target {
    fn default() -> Self {
        Self {
            position_base_m: [0.45, 0.0, 0.30],
            rpy_deg: [0.0, 0.0, 0.0],
            keepout_radius_m: 0.04,
            tripod_radius_m: 0.03,
            real_size_m: 2.0,
            model_size_m: None,
        }
    }
}

/// The studio light that plays the Sun.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LightPlacement {
    /// Light position in the lab frame, metres. Default near the far end, high.
    pub position_lab_m: [f64; 3],
    /// Keep-out sphere radius around the light and its Fresnel, metres. Default 0.2.
    pub keepout_radius_m: f64,
    /// How much earlier than its scheduled tick a level change goes out, milliseconds: the
    /// light path's latency, so that captures see the level the schedule gives them. Absent: the
    /// light kind's default (DMX 25, trigger box 2, the stub's light 0; docs/lights.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lead_ms: Option<f64>,
}

impl Default for LightPlacement {
    fn default() -> Self {
        Self { position_lab_m: [2.2, 0.3, 0.9], keepout_radius_m: 0.2, lead_ms: None }
    }
}

/// The camera on the flange.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraMount {
    /// Optical centre in the flange frame, metres. Default 6 cm out along the flange's z.
    pub translation_m: [f64; 3],
    /// Camera axes (OpenCV: x right, y down, z forward) in the flange frame as roll, pitch, yaw
    /// (degrees, z-y-x). Default 0: the optical axis is the flange's z.
    pub rpy_deg: [f64; 3],
    /// The camera body as a capsule behind the optical centre.
    pub body: CameraBody,
    /// Nearest the optical centre may come to the target centre, metres. Default 0.06.
    pub min_target_distance_m: f64,
    /// The lens's distortion, OpenCV's five Brown-Conrady coefficients `[k1, k2, p1, p2, k3]`.
    /// Absent (the default): a pinhole. Only the stub's simulated camera reads it, rendering
    /// through it and announcing it as a real camera announces its factory calibration; the
    /// controller takes a camera's distortion from the camera itself (docs/sim-camera.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distortion: Option<[f64; 5]>,
}

impl Default for CameraMount {
    fn default() -> Self {
        Self {
            translation_m: [0.0, 0.0, 0.06],
            rpy_deg: [0.0, 0.0, 0.0],
            body: CameraBody::default(),
            min_target_distance_m: 0.06,
            distortion: None,
        }
    }
}

/// Safety margins added to every limit and clearance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Margins {
    /// Distance kept from each joint limit, radians. Default 0.05 (about 3 degrees).
    pub joint_limit_rad: f64,
    /// Clearance kept from every enclosure wall, floor and ceiling, metres. Default 0.05.
    pub wall_m: f64,
    /// Clearance kept from the target, tripod and light keep-outs, metres. Default 0.03.
    pub keepout_m: f64,
}

impl Default for Margins {
    fn default() -> Self {
        Self { joint_limit_rad: 0.05, wall_m: 0.05, keepout_m: 0.03 }
    }
}

/// The TCP linear speed above which an xArm control box (firmware 2.3.0 on) raises error 60 in
/// servo_j: 1.2 x its 1000 mm/s TCP speed limit, m/s.
pub const SERVO_J_TCP_SPEED_LIMIT: f64 = 1.2;

/// Per-joint kinematic limits for playback. Defaults are well below the xArm7's 180 deg/s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JointLimits {
    /// Peak joint speed, rad/s. Default 1.0 (57 deg/s) for every joint.
    pub velocity_rad_s: [f64; DOF],
    /// Peak joint acceleration, rad/s^2. Default 4.0.
    pub acceleration_rad_s2: [f64; DOF],
    /// Peak joint jerk, rad/s^3. Default 60.
    pub jerk_rad_s3: [f64; DOF],
    /// Largest change of any joint between two setpoints, radians. Default 0.01: servo mode
    /// runs each step at full speed, so a large step is a violent motion.
    pub max_step_rad: f64,
    /// Peak linear speed of the TCP (flange origin, and the camera's optical centre), m/s, from
    /// forward kinematics between successive setpoints. Default 1.0: in servo_j the control box
    /// (firmware 2.3.0 on) raises error 60 above 1.2 x its 1000 mm/s TCP speed, 1.2 m/s
    /// (docs/preflight.md gives the sources); at most 1.2.
    pub tcp_speed_m_s: f64,
    /// Limits of the slow approach from the arm's pose to the first waypoint: speed (rad/s).
    pub approach_velocity_rad_s: f64,
    /// Approach acceleration, rad/s^2.
    pub approach_acceleration_rad_s2: f64,
    /// Approach jerk, rad/s^3.
    pub approach_jerk_rad_s3: f64,
}

impl Default for JointLimits {
    fn default() -> Self {
        Self {
            velocity_rad_s: [1.0; DOF],
            acceleration_rad_s2: [4.0; DOF],
            jerk_rad_s3: [60.0; DOF],
            max_step_rad: 0.01,
            tcp_speed_m_s: 1.0,
            approach_velocity_rad_s: 0.3,
            approach_acceleration_rad_s2: 0.8,
            approach_jerk_rad_s3: 8.0,
        }
    }
}

/// What the stub's simulated camera shows (docs/stub-scene.md). Nothing here changes what the
/// preflight or the stub's physics check: both scenes have the same collision geometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct SceneConfig {
    /// `lab` (default: the enclosure's twin, lit by the studio light) or `orbit` (black sky, the
    /// Earth, a directional Sun that follows the trajectory's Sun phase). `hitl run
    /// --scene-kind` overrides it.
    pub kind: SceneKind,
}

/// The two looks of the stub's scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum SceneKind {
    /// The enclosure's twin: curtains, tripod, the printed target, the studio light as a spot.
    #[default]
    Lab,
    /// The paper's SITL look: black background, the Earth, a directional Sun, no stand drawn.
    Orbit,
}

/// Why a scene kind was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not a scene kind: expected lab or orbit")]
pub struct SceneKindError(pub String);

impl std::str::FromStr for SceneKind {
    type Err = SceneKindError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "lab" => Ok(SceneKind::Lab),
            "orbit" => Ok(SceneKind::Orbit),
            other => Err(SceneKindError(other.to_string())),
        }
    }
}

impl std::fmt::Display for SceneKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SceneKind::Lab => "lab",
            SceneKind::Orbit => "orbit",
        })
    }
}

/// Run-time interlock thresholds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Interlocks {
    /// Longest gap between arm reports before the watchdog trips, milliseconds. Default 100.
    pub report_timeout_ms: u64,
    /// Largest |commanded - measured| on any joint, radians. Default 0.08.
    pub max_deviation_rad: f64,
    /// Trip on any arm warning code, not only on errors. Default true.
    pub trip_on_warning: bool,
    /// Longest the arm may leave setpoints unanswered (the command channel silent while the
    /// connection stays open) before the run holds, milliseconds. Default 250: a real xArm7's
    /// replies have been seen to stall about 190 ms; the run rides such a stall through while
    /// the reports (watchdog) and the deviation interlock keep watching the arm (docs/safety.md).
    pub reply_stall_ms: u64,
}

impl Default for Interlocks {
    fn default() -> Self {
        Self {
            report_timeout_ms: 100,
            max_deviation_rad: 0.08,
            trip_on_warning: true,
            reply_stall_ms: 250,
        }
    }
}

/// Longest report watchdog or reply stall a lab configuration may set, milliseconds.
pub const MAX_WATCHDOG_MS: f64 = 2000.0;

/// The documented range of one lab-configuration number.
#[derive(Debug, Clone, Copy)]
enum Range {
    /// `> 0`.
    Positive,
    /// `>= 0`.
    NonNegative,
    /// `(0, max]`, with the reason for the maximum.
    UpTo(f64, &'static str),
    /// `[lo, hi]`.
    Within(f64, f64),
    /// An angle in degrees, `[-360, 360]`.
    Angle,
}

impl Range {
    fn holds(self, v: f64) -> bool {
        match self {
            Range::Positive => v > 0.0,
            Range::NonNegative => v >= 0.0,
            Range::UpTo(max, _) => v > 0.0 && v <= max,
            Range::Within(lo, hi) => (lo..=hi).contains(&v),
            Range::Angle => (-360.0..=360.0).contains(&v),
        }
    }

    fn describe(self) -> String {
        match self {
            Range::Positive => "must be positive".into(),
            Range::NonNegative => "must be zero or positive".into(),
            Range::UpTo(max, why) => format!("must be in (0, {max:.4}] ({why})"),
            Range::Within(lo, hi) => format!("must be in [{lo}, {hi}]"),
            Range::Angle => "must be an angle in [-360, 360] degrees".into(),
        }
    }
}

/// A key (or array of keys) and the range its values must lie in.
struct Rule<'a> {
    key: &'static str,
    values: std::borrow::Cow<'a, [f64]>,
    array: bool,
    range: Range,
}

impl<'a> Rule<'a> {
    fn one(key: &'static str, v: f64, range: Range) -> Self {
        Rule { key, values: std::borrow::Cow::Owned(vec![v]), array: false, range }
    }

    fn each(key: &'static str, v: &'a [f64], range: Range) -> Self {
        Rule { key, values: std::borrow::Cow::Borrowed(v), array: true, range }
    }

    fn check(&self) -> Result<(), ConfigError> {
        match self.values.iter().enumerate().find(|(_, v)| !self.range.holds(**v)) {
            None => Ok(()),
            Some((i, v)) => {
                let key =
                    if self.array { format!("{}[{i}]", self.key) } else { self.key.to_string() };
                Err(ConfigError::Invalid(format!("{key} = {v} {}", self.range.describe())))
            }
        }
    }
}

fn rpy(deg: &[f64; 3]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(deg[0].to_radians(), deg[1].to_radians(), deg[2].to_radians())
}

impl LabConfig {
    /// Read and validate a TOML lab configuration.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| ConfigError::Read { path: path.display().to_string(), source })?;
        Self::from_toml(&text).map_err(|e| match e {
            ConfigError::Parse { message, .. } => {
                ConfigError::Parse { path: path.display().to_string(), message }
            }
            ConfigError::Invalid(m) => ConfigError::Invalid(format!("{}: {m}", path.display())),
            other => other,
        })
    }

    /// Parse and validate TOML text.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let config: LabConfig = toml::from_str(text)
            .map_err(|e| ConfigError::Parse { path: "<text>".into(), message: e.to_string() })?;
        config.validate()?;
        Ok(config)
    }

    /// The configuration as TOML (for the `run` metadata record and `--print-config`).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }

    /// Refuse values that make no physical sense: every number finite and in the range
    /// docs/lab-config.md gives for its key, the error naming the key. One pass, run by every
    /// loader (`check`, `plan`, `run`, `calibrate`, `stub`, their `--stub-config`) before any
    /// device opens.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Some((key, v)) = self.first_non_finite()? {
            return Err(ConfigError::Invalid(format!("{key} = {v} must be a finite number")));
        }
        for rule in self.range_rules() {
            rule.check()?;
        }
        let margin = self.margins.joint_limit_rad;
        let limits = self.arm.joint_table.limits();
        for (j, v) in self.arm.rest_q.iter().enumerate() {
            let (lo, hi) = (limits[j].0 + margin, limits[j].1 - margin);
            if !(lo..=hi).contains(v) {
                return Err(ConfigError::Invalid(format!(
                    "arm.rest_q[{j}] = {v} must be in [{lo:.4}, {hi:.4}] (joint table {} less \
                     margins.joint_limit_rad)",
                    self.arm.joint_table
                )));
            }
        }
        let lo = Point3::origin();
        let hi = Point3::from(Vector3::from(self.enclosure.size_m));
        let base = Point3::from(Vector3::from(self.arm.base_in_lab_m));
        if (0..3).any(|a| base[a] < lo[a] || base[a] > hi[a]) {
            return Err(ConfigError::Invalid(format!(
                "arm.base_in_lab_m {:?} is outside the enclosure",
                self.arm.base_in_lab_m
            )));
        }
        Ok(())
    }

    /// The first number anywhere in the configuration that is NaN or infinite, with its key
    /// path (`target.rpy_deg[0]`). Walks the serialised form, so a key added later is covered.
    fn first_non_finite(&self) -> Result<Option<(String, f64)>, ConfigError> {
        fn walk(v: &toml::Value, key: &str) -> Option<(String, f64)> {
            match v {
                toml::Value::Float(f) if !f.is_finite() => Some((key.to_string(), *f)),
                toml::Value::Array(a) => {
                    a.iter().enumerate().find_map(|(i, x)| walk(x, &format!("{key}[{i}]")))
                }
                toml::Value::Table(t) => t.iter().find_map(|(k, x)| {
                    walk(x, &if key.is_empty() { k.clone() } else { format!("{key}.{k}") })
                }),
                _ => None,
            }
        }
        let v = toml::Value::try_from(self)
            .map_err(|e| ConfigError::Invalid(format!("cannot be read back as TOML: {e}")))?;
        Ok(walk(&v, ""))
    }

    /// The documented range of every number (docs/lab-config.md).
    fn range_rules(&self) -> Vec<Rule<'_>> {
        use Range::*;
        let l = &self.limits;
        let mut rules = vec![
            Rule::each("enclosure.size_m", &self.enclosure.size_m, Positive),
            Rule::one("arm.base_yaw_deg", self.arm.base_yaw_deg, Angle),
            Rule::each("target.rpy_deg", &self.target.rpy_deg, Angle),
            Rule::one("target.keepout_radius_m", self.target.keepout_radius_m, NonNegative),
            Rule::one("target.tripod_radius_m", self.target.tripod_radius_m, NonNegative),
            Rule::one("target.real_size_m", self.target.real_size_m, Positive),
            Rule::one("light.keepout_radius_m", self.light.keepout_radius_m, NonNegative),
            Rule::each("camera.rpy_deg", &self.camera.rpy_deg, Angle),
            Rule::one("camera.body.half_width_m", self.camera.body.half_width_m, NonNegative),
            Rule::one("camera.body.depth_m", self.camera.body.depth_m, NonNegative),
            Rule::one("camera.body.radius_m", self.camera.body.radius_m, Positive),
            Rule::one(
                "camera.min_target_distance_m",
                self.camera.min_target_distance_m,
                NonNegative,
            ),
            Rule::one("margins.joint_limit_rad", self.margins.joint_limit_rad, Within(0.0, 0.5)),
            Rule::one("margins.wall_m", self.margins.wall_m, NonNegative),
            Rule::one("margins.keepout_m", self.margins.keepout_m, NonNegative),
            Rule::each(
                "limits.velocity_rad_s",
                &l.velocity_rad_s,
                UpTo(MAX_JOINT_SPEED, "the xArm7's 180 deg/s"),
            ),
            Rule::each("limits.acceleration_rad_s2", &l.acceleration_rad_s2, Positive),
            Rule::each("limits.jerk_rad_s3", &l.jerk_rad_s3, Positive),
            Rule::one("limits.max_step_rad", l.max_step_rad, Positive),
            Rule::one(
                "limits.tcp_speed_m_s",
                l.tcp_speed_m_s,
                UpTo(
                    SERVO_J_TCP_SPEED_LIMIT,
                    "the control box's servo_j TCP speed limit, error 60",
                ),
            ),
            Rule::one(
                "limits.approach_velocity_rad_s",
                l.approach_velocity_rad_s,
                UpTo(MAX_JOINT_SPEED, "the xArm7's 180 deg/s"),
            ),
            Rule::one(
                "limits.approach_acceleration_rad_s2",
                l.approach_acceleration_rad_s2,
                Positive,
            ),
            Rule::one("limits.approach_jerk_rad_s3", l.approach_jerk_rad_s3, Positive),
            Rule::one(
                "interlocks.report_timeout_ms",
                self.interlocks.report_timeout_ms as f64,
                UpTo(MAX_WATCHDOG_MS, "a watchdog slower than that watches nothing"),
            ),
            Rule::one("interlocks.max_deviation_rad", self.interlocks.max_deviation_rad, Positive),
            Rule::one(
                "interlocks.reply_stall_ms",
                self.interlocks.reply_stall_ms as f64,
                UpTo(MAX_WATCHDOG_MS, "a stall that long is a fault"),
            ),
        ];
        if let Some(m) = self.target.model_size_m {
            rules.push(Rule::one("target.model_size_m", m, Positive));
        }
        if let Some(d) = &self.camera.distortion {
            // Wider than any lens a Gemini-class camera has (|k1| about 0.1, |p| about 1e-3).
            rules.push(Rule::each("camera.distortion", d, Within(-1.0, 1.0)));
        }
        if let Some(lead) = self.light.lead_ms {
            rules.push(Rule::one("light.lead_ms", lead, Within(0.0, 1000.0)));
        }
        if let Some(b) = &self.board {
            rules.push(Rule::one("board.rows", b.rows as f64, Within(1.0, 64.0)));
            rules.push(Rule::one("board.cols", b.cols as f64, Within(1.0, 64.0)));
            rules.push(Rule::one("board.tag_size_m", b.tag_size_m, Positive));
            rules.push(Rule::one("board.tag_spacing_m", b.tag_spacing_m, NonNegative));
            rules.push(Rule::each("board.rpy_deg", &b.rpy_deg, Angle));
        }
        if let Some(c) = &self.calibration {
            rules.push(Rule::one("calibration.rms_px", c.rms_px, NonNegative));
            rules.push(Rule::each("calibration.view_rms_px", &c.view_rms_px, NonNegative));
            rules.push(Rule::one("calibration.camera_sigma_mm", c.camera_sigma_mm, NonNegative));
            rules.push(Rule::one("calibration.camera_sigma_deg", c.camera_sigma_deg, NonNegative));
            rules.push(Rule::one("calibration.target_sigma_mm", c.target_sigma_mm, NonNegative));
            rules.push(Rule::one("calibration.target_sigma_deg", c.target_sigma_deg, NonNegative));
        }
        rules
    }

    /// The arm base's pose in the lab frame.
    pub fn base_in_lab(&self) -> Pose {
        let p = self.arm.base_in_lab_m;
        Isometry3::from_parts(
            Translation3::new(p[0], p[1], p[2]),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.arm.base_yaw_deg.to_radians()),
        )
    }

    /// Flange-to-camera transform (camera in OpenCV axes).
    pub fn camera_mount(&self) -> Pose {
        let t = self.camera.translation_m;
        Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), rpy(&self.camera.rpy_deg))
    }

    /// The target's pose in the base frame.
    pub fn target_in_base(&self) -> Pose {
        let p = self.target.position_base_m;
        Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), rpy(&self.target.rpy_deg))
    }

    /// Target centre in the base frame.
    pub fn target_position_base(&self) -> Point3<f64> {
        Point3::from(Vector3::from(self.target.position_base_m))
    }

    /// The enclosure box in the lab frame: (lower corner, upper corner).
    pub fn enclosure_box(&self) -> (Point3<f64>, Point3<f64>) {
        (Point3::origin(), Point3::from(Vector3::from(self.enclosure.size_m)))
    }

    /// Keep-out volumes in the base frame, by name: the target sphere, the tripod column from the
    /// floor to the bottom of the target sphere, and the light.
    pub fn keepouts_base(&self) -> [(&'static str, Capsule); 3] {
        let lab_to_base = self.base_in_lab().inverse();
        let target = self.target_position_base();
        let floor_z_base = (lab_to_base * Point3::new(0.0, 0.0, 0.0)).z;
        let tripod_top = target - Vector3::z() * self.target.keepout_radius_m;
        let tripod_foot = Point3::new(target.x, target.y, floor_z_base);
        let light = lab_to_base * Point3::from(Vector3::from(self.light.position_lab_m));
        [
            ("target", Capsule::sphere(target, self.target.keepout_radius_m)),
            ("tripod", Capsule::new(tripod_foot, tripod_top, self.target.tripod_radius_m)),
            ("light", Capsule::sphere(light, self.light.keepout_radius_m)),
        ]
    }
}

/// An AprilGrid calibration board (AprilTags in rows and columns) and where it is fixed on the
/// target's mount. Board frame: origin at the outer top-left corner of the first tag's black
/// square, x along the rows (to the right as printed), y down the columns, z into the board.
/// Tag `first_id + row * cols + col` is at (row, col). `Default` is the repository's board
/// (calib/boards/aprilgrid-6x6.toml) 9 cm in front of the target centre, facing the arm and
/// tilted 45 deg up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BoardPlacement {
    /// Tag family; `tag36h11` is the one hitl detects.
    pub family: String,
    /// Tag rows and columns.
    pub rows: u32,
    pub cols: u32,
    /// Side of one tag's black square, metres (as printed and measured).
    pub tag_size_m: f64,
    /// White gap between neighbouring tags, metres.
    pub tag_spacing_m: f64,
    /// Id of the tag at row 0, column 0.
    pub first_id: u32,
    /// Board-frame origin in the target frame, metres.
    pub position_target_m: [f64; 3],
    /// Board axes in the target frame as roll, pitch, yaw (degrees, z-y-x).
    pub rpy_deg: [f64; 3],
}

impl Default for BoardPlacement {
    fn default() -> Self {
        Self {
            family: "tag36h11".into(),
            rows: 6,
            cols: 6,
            tag_size_m: 0.03,
            tag_spacing_m: 0.009,
            first_id: 0,
            position_target_m: [-0.01045049, 0.1125, 0.07954951],
            rpy_deg: [-135.0, 0.0, -90.0],
        }
    }
}

impl BoardPlacement {
    /// The board frame in the target frame.
    pub fn board_in_target(&self) -> Pose {
        let p = self.position_target_m;
        Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), rpy(&self.rpy_deg))
    }
}

/// Provenance of a calibrated camera mount and target pose (written by `hitl calibrate`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct CalibrationProvenance {
    /// When it was solved (UTC, RFC 3339).
    pub date: String,
    /// How: solver and refinement.
    pub method: String,
    /// The board it saw (family, grid, tag size).
    pub board: String,
    /// Views used in the solution.
    pub views: u32,
    /// Reprojection error over all corners, RMS, pixels.
    pub rms_px: f64,
    /// Per-view RMS reprojection error, pixels, in view order.
    pub view_rms_px: Vec<f64>,
    /// One-sigma uncertainty of the camera mount: translation (mm), rotation (deg).
    pub camera_sigma_mm: f64,
    pub camera_sigma_deg: f64,
    /// One-sigma uncertainty of the target pose: translation (mm), rotation (deg).
    pub target_sigma_mm: f64,
    pub target_sigma_deg: f64,
}

impl LabConfig {
    /// The name of the calibration the ground truth comes from: `nominal`, or
    /// `calibrated <date> (<views> views, <rms> px RMS)`.
    pub fn calibration_name(&self) -> String {
        match &self.calibration {
            None => "nominal".into(),
            Some(c) => format!("calibrated {} ({} views, {:.3} px RMS)", c.date, c.views, c.rms_px),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_is_the_default_lab() {
        let c = LabConfig::from_toml("").expect("default");
        assert_eq!(c, LabConfig::default());
        assert_eq!(c.enclosure.size_m, [2.438, 1.219, 1.219]);
    }

    #[test]
    fn round_trips_through_toml() {
        let c = LabConfig::default();
        let back = LabConfig::from_toml(&c.to_toml()).expect("round trip");
        assert_eq!(back, c);
    }

    #[test]
    fn refuses_unknown_keys_and_bad_values() {
        let e = LabConfig::from_toml("[limits]\nvelocity = 1.0\n").expect_err("refused");
        assert!(e.to_string().contains("velocity"), "{e}");
        let e = LabConfig::from_toml("[limits]\nvelocity_rad_s = [4.0,1,1,1,1,1,1]\n")
            .expect_err("refused");
        assert!(e.to_string().contains("velocity_rad_s[0]"), "{e}");
        let e =
            LabConfig::from_toml("[arm]\nbase_in_lab_m = [5.0, 0.5, 0.0]\n").expect_err("refused");
        assert!(e.to_string().contains("outside the enclosure"), "{e}");
        let e = LabConfig::from_toml("[limits]\ntcp_speed_m_s = 1.5\n").expect_err("refused");
        assert!(e.to_string().contains("tcp_speed_m_s"), "{e}");
        let e = LabConfig::from_toml("[arm]\njoint_table = \"xarm7\"\n").expect_err("refused");
        assert!(e.to_string().contains("xarm7-current"), "{e}");
    }

    #[test]
    fn every_number_must_be_finite_and_named_by_its_key() {
        for (text, key) in [
            ("[target]\nrpy_deg = [nan, 0, 0]\n", "target.rpy_deg[0] = NaN"),
            ("[camera]\nrpy_deg = [0, inf, 0]\n", "camera.rpy_deg[1] = inf"),
            ("[arm]\nbase_yaw_deg = -inf\n", "arm.base_yaw_deg = -inf"),
            ("[camera.body]\nradius_m = nan\n", "camera.body.radius_m = NaN"),
            ("[target]\nmodel_size_m = inf\n", "target.model_size_m = inf"),
            ("[light]\nlead_ms = nan\n", "light.lead_ms = NaN"),
            ("[board]\nposition_target_m = [0, 0, nan]\n", "board.position_target_m[2] = NaN"),
            ("[calibration]\nview_rms_px = [0.1, nan]\n", "calibration.view_rms_px[1] = NaN"),
            ("[interlocks]\nmax_deviation_rad = nan\n", "interlocks.max_deviation_rad = NaN"),
            ("[arm]\nrest_q = [0, nan, 0, 0.9, 0, 1.4, 0]\n", "arm.rest_q[1] = NaN"),
        ] {
            let e = LabConfig::from_toml(text).expect_err(text).to_string();
            assert!(e.contains(key) && e.contains("finite"), "{text}: {e}");
        }
    }

    #[test]
    fn every_number_must_be_in_its_documented_range() {
        for (text, key) in [
            ("[target]\nrpy_deg = [0, 400, 0]\n", "target.rpy_deg[1] = 400 must be an angle"),
            ("[camera.body]\nradius_m = 0\n", "camera.body.radius_m = 0 must be positive"),
            ("[margins]\njoint_limit_rad = 2\n", "margins.joint_limit_rad = 2 must be in [0, 0.5]"),
            ("[interlocks]\nreport_timeout_ms = 0\n", "interlocks.report_timeout_ms = 0"),
            ("[interlocks]\nreply_stall_ms = 99999\n", "interlocks.reply_stall_ms = 99999"),
            ("[board]\nrows = 0\n", "board.rows = 0"),
            ("[board]\ntag_size_m = -0.03\n", "board.tag_size_m = -0.03 must be positive"),
            ("[enclosure]\nsize_m = [2, 0, 1]\n", "enclosure.size_m[1] = 0 must be positive"),
            ("[arm]\nrest_q = [0, -0.5, 0, -0.2, 0, 1.4, 0]\n", "arm.rest_q[3] = -0.2 must be in"),
            ("[arm]\nrest_q = [7, -0.5, 0, 0.9, 0, 1.4, 0]\n", "arm.rest_q[0] = 7 must be in"),
            ("[light]\nlead_ms = -1\n", "light.lead_ms = -1 must be in [0, 1000]"),
            ("[light]\nlead_ms = 1500\n", "light.lead_ms = 1500 must be in [0, 1000]"),
            ("[camera]\ndistortion = [0, 0, 0, 2, 0]\n", "camera.distortion[3] = 2 must be in"),
            ("[camera]\ndistortion = [0, 0, 0]\n", "distortion"),
        ] {
            let e = LabConfig::from_toml(text).expect_err(text).to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        // The edges of the ranges are accepted.
        LabConfig::from_toml(
            "[target]\nrpy_deg = [-360, 360, 0]\n[interlocks]\nreply_stall_ms = 2000\n",
        )
        .expect("edges");
        let c = LabConfig::from_toml("[light]\nlead_ms = 0\n").expect("no lead");
        assert_eq!(c.light.lead_ms, Some(0.0));
        assert_eq!(LabConfig::default().light.lead_ms, None, "the light kind's default");
        let c = LabConfig::from_toml("[camera]\ndistortion = [-0.1, 0.05, 0.001, -0.002, 0]\n")
            .expect("a lens");
        assert_eq!(c.camera.distortion, Some([-0.1, 0.05, 0.001, -0.002, 0.0]));
        // Written back only when there is one (a pinhole lab's file is as before).
        let back = LabConfig::from_toml(&c.to_toml()).expect("reads back");
        assert_eq!(back.camera.distortion, c.camera.distortion);
        assert!(!LabConfig::default().to_toml().contains("distortion"));
    }

    #[test]
    fn the_joint_table_defaults_to_the_current_one() {
        assert_eq!(LabConfig::default().arm.joint_table, JointTable::Xarm7Current);
        let c = LabConfig::from_toml("[arm]\njoint_table = \"xarm7-legacy\"\n").expect("legacy");
        assert_eq!(c.arm.joint_table, JointTable::Xarm7Legacy);
    }

    #[test]
    fn the_scene_kind_defaults_to_lab_and_refuses_unknown_keys() {
        assert_eq!(LabConfig::default().scene.kind, SceneKind::Lab);
        let c = LabConfig::from_toml("[scene]\nkind = \"orbit\"\n").expect("orbit");
        assert_eq!(c.scene.kind, SceneKind::Orbit);
        assert_eq!(LabConfig::from_toml(&c.to_toml()).expect("round trip"), c);
        let e = LabConfig::from_toml("[scene]\nkind = \"space\"\n").expect_err("refused");
        assert!(e.to_string().contains("space"), "{e}");
        let e = LabConfig::from_toml("[scene]\nlook = \"lab\"\n").expect_err("refused");
        assert!(e.to_string().contains("look"), "{e}");
        assert_eq!("orbit".parse::<SceneKind>(), Ok(SceneKind::Orbit));
        assert!("Orbit".parse::<SceneKind>().is_err());
        assert_eq!(SceneKind::Orbit.to_string(), "orbit");
    }

    #[test]
    fn keepouts_sit_where_configured() {
        let c = LabConfig::default();
        let k = c.keepouts_base();
        assert_eq!(k[0].1.a, Point3::new(0.45, 0.0, 0.30));
        // The light is at lab (2.2, 0.3, 0.9); the base at lab (0.9, 0.6095, 0).
        assert!((k[2].1.a - Point3::new(1.3, -0.3095, 0.9)).norm() < 1e-9);
    }
}
