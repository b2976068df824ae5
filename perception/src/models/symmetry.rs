//! A target's symmetry group: the proper rotations that map it onto itself, and the pose error up
//! to them.
//!
//! A target that looks the same turned by `S` (a rotation of its body frame about an axis through
//! [`Symmetry::point`]) cannot be told from its turned twin by any camera: ground truth `T_gt` and
//! `T_gt * S` are the same picture. The symmetry-aware error of a (calibrated) estimate is its error
//! against the nearest twin: `e_r_sym = min over S of |log(R_corr^T R_gt R_S)|`, and `e_t_sym` the
//! translation error against that same twin (equal to `e_t` when every axis passes through the
//! body origin, as for the built-ins). It is never above the paper's `e_r` (the identity is in
//! every group). This is how the BOP benchmark's symmetric measures (MSSD, ADD-S) treat a
//! symmetric object: the error is taken against the closest of the object's indistinguishable
//! poses (docs/perception.md).
//!
//! Mirror planes are not proper rotations: a target with one mirror plane has no twin pose (a
//! mirror image cannot be reached by turning), so its group is the identity alone. Two mirror
//! planes meeting at a line make the 180 deg turn about that line a symmetry.
//!
//! Declarations ([`Symmetry::parse`]; `hitl eval --target-symmetry`, a `.symmetry` file next to an
//! OBJ/STL, the built-ins' own):
//!
//! | text | group |
//! | --- | --- |
//! | `none` | identity only (no symmetry) |
//! | `one-plane` | identity only (a mirror plane is no proper rotation) |
//! | `two-planes:AXIS` | identity and the 180 deg turn about AXIS (where the planes meet) |
//! | `N-fold:AXIS` | the N turns by 360/N deg about AXIS (N from 2 to 360) |
//! | `revolution:AXIS` | every turn about AXIS (a body of revolution) |
//! | `A+B+...` | the group the parts generate together (for example `2-fold:z+2-fold:x`) |
//!
//! AXIS is `x`, `y`, `z` (optionally with a sign) or three numbers `a,b,c`, in the model's
//! body frame (an OBJ/STL file's own axes: centring and scaling turn nothing).

use crate::PerceptionError;
use hitl_hal::Pose;
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

/// Largest finite group a declaration may generate (the icosahedral group has 60).
pub const MAX_GROUP_SIZE: usize = 720;

/// Two rotations closer than this (radians) are the same group element.
const SAME_ROTATION_RAD: f64 = 1e-6;

/// A symmetry group of a target, body frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Symmetry {
    /// The declaration, normalised (`none`, `two-planes:z`, `2-fold:z+2-fold:x`, ...).
    pub spec: String,
    /// The finite proper rotations (about axes through `point`), identity first.
    pub rotations: Vec<UnitQuaternion<f64>>,
    /// An axis of revolution (every turn about it, through `point`), if any.
    pub revolution: Option<Unit<Vector3<f64>>>,
    /// A point every axis passes through, body frame (real metres for a target).
    pub point: Point3<f64>,
}

/// A symmetry-aware error: the paper's metrics against the nearest twin of the ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetricError {
    /// Translation error against the chosen twin, in the poses' units.
    pub et: f64,
    /// Rotation error against the chosen twin, radians.
    pub er_rad: f64,
    /// The twin: ground truth turned by the group element nearest the estimate.
    pub twin: Pose,
}

impl Symmetry {
    /// No symmetry: the identity alone.
    pub fn none() -> Symmetry {
        Symmetry {
            spec: "none".into(),
            rotations: vec![UnitQuaternion::identity()],
            revolution: None,
            point: Point3::origin(),
        }
    }

    /// Parses a declaration (module docs); every axis passes through the body origin.
    pub fn parse(text: &str) -> Result<Symmetry, PerceptionError> {
        let bad = |why: String| {
            PerceptionError::BadInput(format!("symmetry {text:?}: {why} (none, one-plane, \
                 two-planes:AXIS, N-fold:AXIS, revolution:AXIS, joined by +; AXIS x, y, z or a,b,c)"))
        };
        let text = text.trim();
        if text.is_empty() {
            return Err(bad("empty".into()));
        }
        let mut generators = Vec::new();
        let mut revolution: Option<Unit<Vector3<f64>>> = None;
        let mut parts = Vec::new();
        for part in text.split('+').map(str::trim) {
            let (kind, axis_given) = match part.split_once(':') {
                Some((k, a)) => (k.trim(), Some(a.trim()).filter(|a| !a.is_empty())),
                None => (part, None),
            };
            let axis = || -> Result<Unit<Vector3<f64>>, PerceptionError> {
                let a = axis_given
                    .ok_or_else(|| bad(format!("{part:?} needs an axis ({kind}:AXIS)")))?;
                parse_axis(a).ok_or_else(|| bad(format!("{a:?} is not an axis")))
            };
            match kind {
                "none" | "one-plane" if axis_given.is_none() => parts.push(kind.to_string()),
                "two-planes" => {
                    let a = axis()?;
                    generators.push(UnitQuaternion::from_axis_angle(&a, std::f64::consts::PI));
                    parts.push(format!("two-planes:{}", axis_name(&a)));
                }
                "revolution" => {
                    let a = axis()?;
                    if revolution.is_some_and(|r| r.dot(&a).abs() < 1.0 - 1e-9) {
                        return Err(bad("two different axes of revolution".into()));
                    }
                    revolution = Some(a);
                    parts.push(format!("revolution:{}", axis_name(&a)));
                }
                k if k.ends_with("-fold") => {
                    let n: u32 = k
                        .trim_end_matches("-fold")
                        .parse()
                        .ok()
                        .filter(|n| (2..=360).contains(n))
                        .ok_or_else(|| bad(format!("{k:?}: N-fold needs N from 2 to 360")))?;
                    let a = axis()?;
                    generators.push(UnitQuaternion::from_axis_angle(
                        &a,
                        std::f64::consts::TAU / f64::from(n),
                    ));
                    parts.push(format!("{n}-fold:{}", axis_name(&a)));
                }
                _ => return Err(bad(format!("unknown part {part:?}"))),
            }
        }
        // `none` and `one-plane` add nothing; alone they are the identity.
        let spec = if generators.is_empty() && revolution.is_none() {
            parts.first().cloned().unwrap_or_else(|| "none".into())
        } else {
            parts
                .into_iter()
                .filter(|p| p != "none" && p != "one-plane")
                .collect::<Vec<_>>()
                .join("+")
        };
        let rotations = closure(&generators).ok_or_else(|| {
            bad(format!(
                "the turns generate more than {MAX_GROUP_SIZE} rotations (not a finite group: \
                 check the axes)"
            ))
        })?;
        if let Some(a) = revolution {
            if let Some(r) =
                rotations.iter().find(|r| (**r * a.into_inner()).dot(&a).abs() < 1.0 - 1e-9)
            {
                return Err(bad(format!(
                    "a turn of {:.1} deg moves the axis of revolution off itself",
                    r.angle().to_degrees()
                )));
            }
        }
        Ok(Symmetry { spec, rotations, revolution, point: Point3::origin() })
    }

    /// The group with its axes through `point` instead (body frame).
    pub fn through(mut self, point: Point3<f64>) -> Symmetry {
        self.point = point;
        self
    }

    /// The group after the body frame is moved by `-centre` and scaled by `factor` (how a file's
    /// model is centred and scaled): rotations are unchanged, the point moves with the mesh.
    pub fn transformed(mut self, centre: [f64; 3], factor: f64) -> Symmetry {
        self.point = Point3::from((self.point.coords - Vector3::from(centre)) * factor);
        self
    }

    /// True when the identity is the only element.
    pub fn is_trivial(&self) -> bool {
        self.rotations.len() == 1 && self.revolution.is_none()
    }

    /// The number of proper rotations, `None` for infinitely many (an axis of revolution).
    pub fn order(&self) -> Option<usize> {
        self.revolution.is_none().then_some(self.rotations.len())
    }

    /// The finite part's elements as body-frame transforms, identity first: a pose `T` and
    /// `T * S` show the same target (an axis of revolution's turns are not listed).
    pub fn elements(&self) -> Vec<Isometry3<f64>> {
        self.rotations.iter().map(|r| self.element(r)).collect()
    }

    /// Element `r` of the finite part as a body-frame transform (turning about `point`).
    fn element(&self, r: &UnitQuaternion<f64>) -> Isometry3<f64> {
        let p = self.point.coords;
        Isometry3::from_parts(Translation3::from(p - r * p), *r)
    }

    /// The error of `corr` against the nearest twin of `gt` (`gt * S` over the group): the
    /// smallest rotation error, ties (within 1e-12 rad) broken by the translation error. Never
    /// above the plain rotation error.
    pub fn error(&self, corr: &Pose, gt: &Pose) -> SymmetricError {
        let plain = hitl_hal::pose::difference(corr, gt);
        let mut best = SymmetricError { et: plain.0, er_rad: plain.1, twin: *gt };
        for r in &self.rotations {
            let mut twin = gt * self.element(r);
            if let Some(a) = self.revolution {
                // Q R_a(phi) over phi is every rotation taking a to Q a; the smallest of them
                // turns about a x Q a by the angle between a and Q a.
                let q = corr.rotation.inverse() * twin.rotation;
                let qa = q * a.into_inner();
                let smallest = UnitQuaternion::rotation_between(&a.into_inner(), &qa)
                    .unwrap_or_else(|| {
                        UnitQuaternion::from_axis_angle(&perpendicular(&a), std::f64::consts::PI)
                    });
                let about_a = q.inverse() * smallest;
                let spin = self.element(&about_a);
                twin *= spin;
            }
            let (et, er) = hitl_hal::pose::difference(corr, &twin);
            if er < best.er_rad - 1e-12 || (er <= best.er_rad + 1e-12 && et < best.et) {
                best = SymmetricError { et, er_rad: er, twin };
            }
        }
        if best.er_rad > plain.1 {
            // Rounding in the revolution's closed form: the identity is in the group.
            best = SymmetricError { et: plain.0, er_rad: plain.1, twin: *gt };
        }
        best
    }

    /// The declaration next to a mesh file: `FILE.symmetry` (for `sat.obj`, `sat.obj.symmetry`).
    pub fn sidecar_path(mesh: &Path) -> PathBuf {
        let mut name = mesh.as_os_str().to_owned();
        name.push(".symmetry");
        PathBuf::from(name)
    }

    /// Reads the declaration next to `mesh` (see [`Symmetry::sidecar_path`]): `None` when there is
    /// none. The file holds one declaration line and optionally a line `point X Y Z` (a point on
    /// the axes, in the mesh file's coordinates; default: its bounding-box midpoint, `centre`);
    /// `#` starts a comment. `centre` and `factor` are how the model is centred and scaled.
    pub fn read_sidecar(
        mesh: &Path,
        centre: [f64; 3],
        factor: f64,
    ) -> Result<Option<Symmetry>, PerceptionError> {
        let path = Symmetry::sidecar_path(mesh);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => {
                return Err(PerceptionError::BadModel { path, reason: format!("cannot read: {e}") })
            }
        };
        let bad = |reason: String| PerceptionError::BadModel { path: path.clone(), reason };
        let mut spec = None;
        let mut point = Point3::from(centre);
        for line in text.lines() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            if let Some(rest) = line.strip_prefix("point") {
                let v: Vec<f64> = rest
                    .split([' ', ',', '\t'])
                    .filter(|s| !s.is_empty())
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|e| bad(format!("{line:?}: {e}")))?;
                if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                    return Err(bad(format!("{line:?}: `point` needs three finite numbers")));
                }
                point = Point3::new(v[0], v[1], v[2]);
            } else if spec.is_some() {
                return Err(bad(format!("{line:?}: a second declaration (join parts with +)")));
            } else {
                spec = Some(Symmetry::parse(line).map_err(|e| bad(e.to_string()))?);
            }
        }
        let spec = spec.ok_or_else(|| bad("no declaration (for example two-planes:z)".into()))?;
        Ok(Some(spec.through(point).transformed(centre, factor)))
    }
}

/// `x`, `-y`, `+z` or `a,b,c` (not all zero), normalised.
fn parse_axis(s: &str) -> Option<Unit<Vector3<f64>>> {
    let s = s.trim();
    let (sign, name) = match s.strip_prefix('-') {
        Some(rest) => (-1.0, rest),
        None => (1.0, s.strip_prefix('+').unwrap_or(s)),
    };
    let v = match name {
        "x" => Vector3::x() * sign,
        "y" => Vector3::y() * sign,
        "z" => Vector3::z() * sign,
        _ => {
            let c: Vec<f64> = s.split(',').map(|c| c.trim().parse().ok()).collect::<Option<_>>()?;
            if c.len() != 3 || c.iter().any(|x| !x.is_finite()) {
                return None;
            }
            Vector3::new(c[0], c[1], c[2])
        }
    };
    Unit::try_new(v, 1e-12)
}

/// `x`, `-z`, ... for the coordinate axes, else `a,b,c`.
fn axis_name(a: &Unit<Vector3<f64>>) -> String {
    for (name, v) in [("x", Vector3::x()), ("y", Vector3::y()), ("z", Vector3::z())] {
        if (a.into_inner() - v).norm() < 1e-12 {
            return name.into();
        }
        if (a.into_inner() + v).norm() < 1e-12 {
            return format!("-{name}");
        }
    }
    format!("{},{},{}", a.x, a.y, a.z)
}

/// A unit vector perpendicular to `a`.
fn perpendicular(a: &Unit<Vector3<f64>>) -> Unit<Vector3<f64>> {
    let other = if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    Unit::new_normalize(a.cross(&other))
}

/// The group the generators make (identity first), or `None` past [`MAX_GROUP_SIZE`].
fn closure(generators: &[UnitQuaternion<f64>]) -> Option<Vec<UnitQuaternion<f64>>> {
    let mut group = vec![UnitQuaternion::identity()];
    let mut i = 0;
    while i < group.len() {
        for g in generators {
            let p = group[i] * g;
            if !group.iter().any(|q| q.angle_to(&p) < SAME_ROTATION_RAD) {
                if group.len() == MAX_GROUP_SIZE {
                    return None;
                }
                group.push(p);
            }
        }
        i += 1;
    }
    Some(group)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn rot(axis: Vector3<f64>, deg: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), deg.to_radians())
    }

    fn gt() -> Pose {
        Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 3.0),
            rot(Vector3::new(1.0, 2.0, 0.5), 40.0),
        )
    }

    #[test]
    fn declarations_make_their_groups() {
        let order = |s: &str| Symmetry::parse(s).unwrap().order();
        assert_eq!(order("none"), Some(1));
        assert_eq!(order("one-plane"), Some(1));
        assert_eq!(order("two-planes:z"), Some(2));
        assert_eq!(order("4-fold:x"), Some(4));
        assert_eq!(order("2-fold:z+2-fold:x"), Some(4));
        assert_eq!(order("3-fold:z+2-fold:x"), Some(6));
        assert_eq!(order("revolution:z"), None);
        assert_eq!(order("revolution:z+2-fold:x"), None);
        assert_eq!(Symmetry::parse(" two-planes : -y ").unwrap().spec, "two-planes:-y");
        for bad in [
            "",
            "two-planes",
            "3-fold:w",
            "1-fold:z",
            "400-fold:z",
            "mirror",
            "2-fold:0,0,0",
            "revolution:z+4-fold:x",
            "7-fold:z+2-fold:1,2,3",
            "none:z",
        ] {
            assert!(Symmetry::parse(bad).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn a_twin_turned_about_the_axis_scores_zero_and_others_keep_their_error() {
        let s = Symmetry::parse("two-planes:z").unwrap();
        let g = gt();
        let flipped = g * Isometry3::rotation(Vector3::z() * std::f64::consts::PI);
        let e = s.error(&flipped, &g);
        assert!(e.er_rad < 1e-9 && e.et < 1e-12, "{e:?}");
        assert!((hitl_hal::pose::difference(&flipped, &g).1.to_degrees() - 180.0).abs() < 1e-9);
        // A 5 deg error on top of the flip is 5 deg up to symmetry.
        let off = flipped * Isometry3::rotation(Vector3::x() * 5f64.to_radians());
        assert!((s.error(&off, &g).er_rad.to_degrees() - 5.0).abs() < 1e-9);
        // A turn about x is no symmetry of two-planes:z.
        let x = g * Isometry3::rotation(Vector3::x() * std::f64::consts::PI);
        assert!((s.error(&x, &g).er_rad.to_degrees() - 180.0).abs() < 1e-9);
        // With no symmetry the error is the paper's.
        let n = Symmetry::none().error(&off, &g);
        assert_eq!((n.et, n.er_rad), hitl_hal::pose::difference(&off, &g));
    }

    #[test]
    fn revolution_leaves_only_the_tilt_of_the_axis() {
        let s = Symmetry::parse("revolution:z").unwrap();
        let g = gt();
        let e =
            g * Isometry3::rotation(Vector3::z() * 2.0) * Isometry3::rotation(Vector3::x() * 0.1);
        let r = s.error(&e, &g);
        assert!((r.er_rad - 0.1).abs() < 1e-9, "{r:?}");
        assert!(r.er_rad <= hitl_hal::pose::difference(&e, &g).1);
    }

    #[test]
    fn an_axis_off_the_origin_moves_the_twin() {
        // A 180 deg turn about z through (1, 0, 0): the twin's origin is at (2, 0, 0).
        let s = Symmetry::parse("two-planes:z").unwrap().through(Point3::new(1.0, 0.0, 0.0));
        let g = Pose::identity();
        let twin =
            Isometry3::from_parts(Translation3::new(2.0, 0.0, 0.0), rot(Vector3::z(), 180.0));
        let e = s.error(&twin, &g);
        assert!(e.er_rad < 1e-9 && e.et < 1e-9, "{e:?}");
    }

    #[test]
    fn sidecars_are_read_next_to_the_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("sat.obj");
        assert!(Symmetry::read_sidecar(&mesh, [0.0; 3], 1.0).unwrap().is_none());
        let side = Symmetry::sidecar_path(&mesh);
        assert!(side.ends_with("sat.obj.symmetry"));
        std::fs::write(&side, "# the dish turns\n3-fold:z  # about the boom\npoint 1 2 3\n")
            .unwrap();
        let s = Symmetry::read_sidecar(&mesh, [1.0, 1.0, 1.0], 2.0).unwrap().unwrap();
        assert_eq!(s.spec, "3-fold:z");
        assert_eq!(s.point, Point3::new(0.0, 2.0, 4.0));
        std::fs::write(&side, "point 1 2\n").unwrap();
        assert!(Symmetry::read_sidecar(&mesh, [0.0; 3], 1.0).is_err());
        std::fs::write(&side, "2-fold:z\n2-fold:x\n").unwrap();
        assert!(Symmetry::read_sidecar(&mesh, [0.0; 3], 1.0).is_err());
    }
}
