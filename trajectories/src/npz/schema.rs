//! The NPZ schema of docs/architecture.md: which keys exist, their shapes and dtypes, and the value
//! rules (finite numbers, `t` strictly increasing, light in [0, 1], one row per waypoint).

use super::error::{ColumnLabel, NpzError};
use super::read::{Data, RawArray};
use crate::kinematics::DOF;
use crate::trajectory::Trajectory;
use std::collections::BTreeMap;

/// The schema's keys, each with the dtype(s) it accepts (for messages).
pub const KEYS: [(&str, &str); 9] = [
    ("qpos", "float64 or float32"),
    ("t", "float64 (float32 accepted with a warning)"),
    ("capture", "bool"),
    ("light", "float32 or float64"),
    ("u_rad", "float64 or float32"),
    ("rel_pos_rtn_m", "float64 or float32"),
    ("cam_pose_base", "float64 or float32"),
    ("sun_phase_deg", "float64 or float32"),
    ("meta", "a 0-d unicode string (np.array(json_text))"),
];

/// Whether `key` is one of the schema's keys.
pub fn is_known(key: &str) -> bool {
    KEYS.iter().any(|(k, _)| *k == key)
}

/// The dtype(s) the schema accepts for `key`.
pub fn expected_dtype(key: &str) -> &'static str {
    KEYS.iter().find(|(k, _)| *k == key).map_or("a schema dtype", |(_, d)| d)
}

/// Highest `--waypoint-rate` accepted, Hz.
pub const MAX_WAYPOINT_RATE_HZ: f64 = 100_000.0;

/// Build the trajectory from decoded arrays, checking shapes and dtypes per key, then values
/// with [`validate`]. A file without `t` takes `t[i] = i / waypoint_rate_hz` when a rate is
/// given and is refused ([`NpzError::MissingTime`]) when not; a rate for a file with `t` is
/// refused too ([`NpzError::RateWithTime`]), so the file's own times are never silently replaced.
pub fn build(
    mut arrays: BTreeMap<String, RawArray>,
    waypoint_rate_hz: Option<f64>,
    warnings: &mut Vec<String>,
) -> Result<Trajectory, NpzError> {
    if let Some(rate) = waypoint_rate_hz {
        if !(rate > 0.0 && rate <= MAX_WAYPOINT_RATE_HZ) {
            return Err(NpzError::WaypointRate { rate, max: MAX_WAYPOINT_RATE_HZ });
        }
    }
    let qpos = arrays.remove("qpos").ok_or(NpzError::Missing { key: "qpos" })?;
    let t = arrays.remove("t");
    let (n, qrows) = rows::<DOF>("qpos", &qpos)?;
    if n < 2 {
        return Err(NpzError::TooFew { n });
    }
    let t = match (t, waypoint_rate_hz) {
        (Some(_), Some(rate)) => return Err(NpzError::RateWithTime { rate }),
        (None, None) => return Err(NpzError::MissingTime),
        (None, Some(rate)) => (0..n).map(|i| i as f64 / rate).collect(),
        (Some(t), None) => {
            if matches!(t.data, Data::F32(_)) {
                warnings.push(
                    "key 't' is float32: times keep ~7 significant digits; the schema asks for \
                     float64"
                        .into(),
                );
            }
            column("t", &t, n)?
        }
    };
    let capture = match arrays.remove("capture") {
        None => None,
        Some(a) => {
            expect_1d("capture", &a, n)?;
            match a.data {
                Data::Bool(v) => Some(v),
                _ => return Err(dtype_error("capture", &a)),
            }
        }
    };
    let light = match arrays.remove("light") {
        None => None,
        Some(a) => {
            let v = column("light", &a, n)?;
            check_finite("light", &v)?;
            if let Some((index, value)) =
                v.iter().enumerate().find(|(_, x)| !(0.0..=1.0).contains(*x))
            {
                return Err(NpzError::LightRange { index, value: *value });
            }
            Some(v.into_iter().map(|x| x as f32).collect())
        }
    };
    let u_rad = arrays.remove("u_rad").map(|a| column("u_rad", &a, n)).transpose()?;
    let rel_pos_rtn_m = match arrays.remove("rel_pos_rtn_m") {
        None => None,
        Some(a) => {
            let (m, r) = rows::<3>("rel_pos_rtn_m", &a)?;
            same_length("rel_pos_rtn_m", m, n)?;
            Some(r)
        }
    };
    let cam_pose_base = arrays.remove("cam_pose_base").map(|a| matrices(&a, n)).transpose()?;
    let sun_phase_deg =
        arrays.remove("sun_phase_deg").map(|a| column("sun_phase_deg", &a, n)).transpose()?;
    let meta = match arrays.remove("meta") {
        None => None,
        Some(a) => {
            if !a.shape.is_empty() {
                return Err(NpzError::Shape {
                    key: "meta".into(),
                    found: a.shape,
                    expected: "() (a 0-d string)".into(),
                });
            }
            match a.data {
                Data::Str(s) => {
                    if let Err(e) = serde_json::from_str::<serde_json::Value>(&s) {
                        warnings.push(format!("key 'meta' is not valid JSON ({e}); kept as text"));
                    }
                    Some(s)
                }
                _ => return Err(dtype_error("meta", &a)),
            }
        }
    };
    let traj = Trajectory {
        qpos: qrows,
        t,
        capture,
        light,
        u_rad,
        rel_pos_rtn_m,
        cam_pose_base,
        sun_phase_deg,
        meta,
    };
    validate(&traj)?;
    if traj.t[0] != 0.0 {
        warnings.push(format!(
            "key 't' starts at {} s, not 0: playback starts at waypoint 0",
            traj.t[0]
        ));
    }
    Ok(traj)
}

/// Check a trajectory's values against the schema's rules: at least two waypoints, every
/// per-waypoint array as long as `qpos`, every number finite, `t` from 0 or later and strictly
/// increasing, light levels in [0, 1]. `save` calls it too, so hitl never writes a file it
/// would refuse to read.
pub fn validate(traj: &Trajectory) -> Result<(), NpzError> {
    let n = traj.qpos.len();
    if n < 2 {
        return Err(NpzError::TooFew { n });
    }
    same_length("t", traj.t.len(), n)?;
    let opt_len = [
        ("capture", traj.capture.as_ref().map(Vec::len)),
        ("light", traj.light.as_ref().map(Vec::len)),
        ("u_rad", traj.u_rad.as_ref().map(Vec::len)),
        ("rel_pos_rtn_m", traj.rel_pos_rtn_m.as_ref().map(Vec::len)),
        ("cam_pose_base", traj.cam_pose_base.as_ref().map(Vec::len)),
        ("sun_phase_deg", traj.sun_phase_deg.as_ref().map(Vec::len)),
    ];
    for (key, len) in opt_len {
        if let Some(len) = len {
            same_length(key, len, n)?;
        }
    }
    for (index, row) in traj.qpos.iter().enumerate() {
        if let Some((j, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(non_finite("qpos", index, ColumnLabel::Joint(j), *v));
        }
    }
    check_finite("t", &traj.t)?;
    if traj.t[0] < 0.0 {
        return Err(NpzError::NegativeStart { value: traj.t[0] });
    }
    if let Some(i) = traj.t.windows(2).position(|w| w[1] <= w[0]) {
        return Err(NpzError::NotIncreasing {
            index: i + 1,
            prev_index: i,
            prev: traj.t[i],
            value: traj.t[i + 1],
        });
    }
    if let Some(light) = &traj.light {
        for (index, v) in light.iter().enumerate() {
            if !v.is_finite() {
                return Err(non_finite("light", index, ColumnLabel::None, f64::from(*v)));
            }
            if !(0.0..=1.0).contains(v) {
                return Err(NpzError::LightRange { index, value: f64::from(*v) });
            }
        }
    }
    if let Some(v) = &traj.u_rad {
        check_finite("u_rad", v)?;
    }
    if let Some(v) = &traj.sun_phase_deg {
        check_finite("sun_phase_deg", v)?;
    }
    if let Some(rows) = &traj.rel_pos_rtn_m {
        for (index, row) in rows.iter().enumerate() {
            if let Some((c, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(non_finite("rel_pos_rtn_m", index, ColumnLabel::Column(c), *v));
            }
        }
    }
    if let Some(mats) = &traj.cam_pose_base {
        for (index, m) in mats.iter().enumerate() {
            for (r, row) in m.iter().enumerate() {
                if let Some((c, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    return Err(non_finite("cam_pose_base", index, ColumnLabel::Cell(r, c), *v));
                }
            }
        }
    }
    Ok(())
}

fn non_finite(key: &str, index: usize, column: ColumnLabel, value: f64) -> NpzError {
    NpzError::NonFinite { key: key.to_string(), index, column, value }
}

fn check_finite(key: &str, v: &[f64]) -> Result<(), NpzError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(non_finite(key, i, ColumnLabel::None, v[i])),
        None => Ok(()),
    }
}

fn same_length(key: &str, len: usize, expected: usize) -> Result<(), NpzError> {
    if len == expected {
        Ok(())
    } else {
        Err(NpzError::Length { key: key.to_string(), len, expected })
    }
}

fn dtype_error(key: &str, a: &RawArray) -> NpzError {
    NpzError::DType { key: key.to_string(), found: a.dtype.clone(), expected: expected_dtype(key) }
}

/// The values as f64, in stored order (f32 widens exactly).
fn floats(key: &str, a: &RawArray) -> Result<Vec<f64>, NpzError> {
    match &a.data {
        Data::F64(v) => Ok(v.clone()),
        Data::F32(v) => Ok(v.iter().map(|x| f64::from(*x)).collect()),
        _ => Err(dtype_error(key, a)),
    }
}

fn expect_1d(key: &str, a: &RawArray, n: usize) -> Result<(), NpzError> {
    match a.shape.as_slice() {
        [m] => same_length(key, *m as usize, n),
        _ => Err(NpzError::Shape {
            key: key.to_string(),
            found: a.shape.clone(),
            expected: format!("({n},)"),
        }),
    }
}

/// A one-dimensional per-waypoint float array.
fn column(key: &str, a: &RawArray, n: usize) -> Result<Vec<f64>, NpzError> {
    expect_1d(key, a, n)?;
    floats(key, a)
}

/// A two-dimensional (N, C) float array as rows, honouring C or Fortran order.
fn rows<const C: usize>(key: &str, a: &RawArray) -> Result<(usize, Vec<[f64; C]>), NpzError> {
    let n = match a.shape.as_slice() {
        [n, c] if *c as usize == C => *n as usize,
        _ => {
            return Err(NpzError::Shape {
                key: key.to_string(),
                found: a.shape.clone(),
                expected: format!("(N, {C})"),
            })
        }
    };
    let flat = floats(key, a)?;
    let out = (0..n)
        .map(|i| {
            let mut row = [0.0; C];
            for (c, x) in row.iter_mut().enumerate() {
                *x = if a.fortran { flat[c * n + i] } else { flat[i * C + c] };
            }
            row
        })
        .collect();
    Ok((n, out))
}

/// `cam_pose_base`, (N, 4, 4), honouring C or Fortran order.
fn matrices(a: &RawArray, n: usize) -> Result<Vec<[[f64; 4]; 4]>, NpzError> {
    let key = "cam_pose_base";
    match a.shape.as_slice() {
        [m, 4, 4] => same_length(key, *m as usize, n)?,
        _ => {
            return Err(NpzError::Shape {
                key: key.into(),
                found: a.shape.clone(),
                expected: format!("({n}, 4, 4)"),
            })
        }
    }
    let flat = floats(key, a)?;
    let out = (0..n)
        .map(|i| {
            let mut m = [[0.0; 4]; 4];
            for (r, row) in m.iter_mut().enumerate() {
                for (c, x) in row.iter_mut().enumerate() {
                    *x = if a.fortran {
                        flat[i + n * (r + 4 * c)]
                    } else {
                        flat[(i * 4 + r) * 4 + c]
                    };
                }
            }
            m
        })
        .collect();
    Ok(out)
}
