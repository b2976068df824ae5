//! `hitl calibrate` against a simulated camera with a lens: the stub's hidden true lab
//! (calib/tests/data/true-lab-lens.toml) has the mount and target off the nominal lab and a lens
//! distortion that the controller learns only from the camera's announced intrinsics; the views
//! are detected in the distorted images and solved through the recorded lens, and the lab comes
//! back within 1 mm and 0.1 deg of the truth. In a file of its own: test binaries run one after
//! another, so its 15 views of motion do not share the machine with other end-to-end tests.

use hitl_trajectories::lab::LabConfig;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// Translation (m) and rotation (deg) between two poses.
fn apart(a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.translation.vector.norm(), d.rotation.angle().to_degrees())
}

#[test]
fn calibrate_through_a_lens_recovers_the_hidden_lab() {
    let dir = tempfile::tempdir().expect("tempdir");
    let record = dir.path().join("calibration.mcap");
    let out = dir.path().join("calibrated.toml");
    let truth_file = repo("calib/tests/data/true-lab-lens.toml");
    let run = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["calibrate", "--views", "15", "--plain", "--clock", "sim", "--config"])
        .arg(repo("tests/data/shared-vm-lab.toml"))
        .arg("--stub-config")
        .arg(&truth_file)
        .arg("--record")
        .arg(&record)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    let all =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert_eq!(run.status.code(), Some(0), "{all}");

    let truth = LabConfig::load(&truth_file).expect("true lab");
    let lens = truth.camera.distortion.expect("the truth has a lens");
    let got = LabConfig::load(&out).expect("the calibrated lab loads");
    let (t, r) = apart(&got.camera_mount(), &truth.camera_mount());
    assert!(t < 1e-3 && r < 0.1, "camera mount {:.3} mm, {r:.4} deg off the truth", t * 1e3);
    let (t, r) = apart(&got.target_in_base(), &truth.target_in_base());
    assert!(t < 1e-3 && r < 0.1, "target {:.3} mm, {r:.4} deg off the truth", t * 1e3);
    let cal = got.calibration.as_ref().expect("a [calibration] provenance block");
    assert!(cal.rms_px > 0.0 && cal.rms_px < 1.0, "{cal:?}");

    // The recording holds the lens the camera announced, which the solve went through.
    let rec = hitl_record::reader::read_recording(&record).expect("the recording reads");
    assert_eq!(rec.tf.len() as u32, cal.views, "flange poses recorded");
    let mut d = None;
    hitl_record::reader::visit(
        &record,
        |m| {
            if m.topic == hitl_record::topics::CALIBRATION {
                d = hitl_record::reader::decode_intrinsics(m.data, m.log_time).ok();
            }
            std::ops::ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .expect("visit");
    let (_, k) = d.expect("a /camera/calibration");
    assert_eq!(k.distortion.d(), &lens[..]);
}
