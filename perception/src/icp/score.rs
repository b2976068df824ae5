//! Image-space checks of a pose hypothesis against the frame: does the projected model fall inside
//! the target's silhouette, and does it stay behind the observed surface (free space)? Samples the
//! image cannot judge are left out: those seen edge-on, and, when tracking, those hidden behind
//! another object ([`Hidden`]).

use super::model::ModelCloud;
use crate::PerceptionFrame;
use hitl_hal::Pose;

/// Samples whose surface normal is within this cosine of perpendicular to the line of sight are
/// not judged: seen edge-on, a thin part (a solar wing) covers less than a pixel and the sensor
/// misses it, so a correct pose would be blamed for it (cos 80 deg).
const GRAZING_COS: f64 = 0.17;

/// What a model sample hidden behind another object (the target's stand, the arm) counts as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Hidden {
    /// A miss. For registration: with no track saying where the target is, a view must not be
    /// explained by hiding model parts behind the stand (a flipped pose hides the part that
    /// would tell it apart).
    Miss,
    /// Not judged. For tracking, whose prediction already says where the target is: a part
    /// behind the stand is no evidence against it. Off the mask, a sample counts as hidden
    /// where its neighbourhood shows something nearer or no depth at all (a stereo camera
    /// has none on the stand's thin legs and in their projector shadow); the comparison with
    /// the frame's pixels ([`super::compare`]) still holds such pixels against the pose.
    Skipped,
}

/// Image-space agreement of a pose with the frame.
#[derive(Debug, Clone, Copy)]
pub struct ImageCheck {
    /// Fraction of the judged in-image model samples (not seen edge-on; with [`Hidden::Skipped`],
    /// not behind another object) that land on (or next to) a target pixel.
    pub silhouette: f64,
    /// Fraction of those that lie in front of the observed surface by more than the tolerance.
    pub violation: f64,
}

/// Projects every model sample at `t` and compares with the frame's target pixels and depth.
pub fn check(
    model: &ModelCloud,
    frame: &PerceptionFrame,
    t: &Pose,
    tol: f64,
    behind_others: Hidden,
    far_m: f64,
) -> ImageCheck {
    check_strided(model, frame, t, tol, 1, behind_others, far_m)
}

/// [`check`] on every `stride`-th model sample (for cheap hypothesis ranking). Depths beyond
/// `far_m` inside the mask are what lies behind the target's outline (a mask with a margin): a
/// surface there is no free-space evidence against the target in front of it.
pub fn check_strided(
    model: &ModelCloud,
    frame: &PerceptionFrame,
    t: &Pose,
    tol: f64,
    stride: usize,
    behind_others: Hidden,
    far_m: f64,
) -> ImageCheck {
    let k = &frame.intrinsics;
    let (w, h) = (k.width as i64, k.height as i64);
    let r = t.rotation.to_rotation_matrix();
    let tr = t.translation.vector;
    let (mut in_image, mut hits, mut violations) = (0usize, 0usize, 0usize);
    let samples = model.points.iter().zip(&model.normals).step_by(stride.max(1));
    for (p, n) in samples {
        let q = r * p + tr;
        if q.z <= 0.0 {
            continue;
        }
        // A surface seen edge-on covers less than a pixel: a depth sensor does not see it.
        if (r * n).dot(&q).abs() < GRAZING_COS * q.norm() {
            continue;
        }
        let (u, v) = k.project(q.x, q.y, q.z);
        let (u, v) = (u.round() as i64, v.round() as i64);
        if u < 0 || v < 0 || u >= w || v >= h {
            continue;
        }
        // Rounding to a pixel can move a sample across an edge: judge it by its 3x3 neighbourhood
        // (on the silhouette if any neighbour is target; in front of free space only if it is in
        // front of every neighbouring target surface; hidden if every neighbour is something
        // else in front of it).
        let mut near = false;
        let mut hidden = true;
        let mut nearest_surface = f64::INFINITY;
        let mut depth_missing = false;
        for dv in -1..=1 {
            for du in -1..=1 {
                let (uu, vv) = (u + du, v + dv);
                if uu >= 0 && vv >= 0 && uu < w && vv < h {
                    let j = (vv * w + uu) as usize;
                    let d = frame.depth_m[j] as f64;
                    let has_depth = d.is_finite() && d > 0.0;
                    if frame.in_silhouette(j) {
                        near = true;
                        if has_depth && d <= far_m {
                            nearest_surface = nearest_surface.min(d);
                        } else if !has_depth {
                            depth_missing = true;
                        }
                    } else if has_depth && d >= q.z - tol {
                        // Off the mask, something at or behind the sample: it is not hidden.
                        // Where the frame has no depth at all it may be (a stereo camera sees
                        // none on the stand's thin legs nor in the shadow they cast).
                        hidden = false;
                    }
                }
            }
        }
        if !near && hidden && matches!(behind_others, Hidden::Skipped) {
            continue;
        }
        in_image += 1;
        if near {
            hits += 1;
            // Next to a silhouette pixel without depth (a stereo camera has none at depth edges
            // and in the projector's shadow), the visible neighbour may be the farther surface
            // beside an edge: no evidence of free space there.
            if !depth_missing && q.z < nearest_surface - tol {
                violations += 1;
            }
        }
    }
    if in_image == 0 {
        return ImageCheck { silhouette: 0.0, violation: 1.0 };
    }
    ImageCheck {
        silhouette: hits as f64 / in_image as f64,
        violation: violations as f64 / in_image as f64,
    }
}
