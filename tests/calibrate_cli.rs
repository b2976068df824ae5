//! `hitl calibrate` where nothing moves: the board drawing, and the refusals before motion.

use std::process::Command;

fn hitl() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hitl"))
}

#[test]
fn print_board_writes_a_true_to_scale_svg() {
    let dir = tempfile::tempdir().expect("tempdir");
    let svg = dir.path().join("board.svg");
    let out = hitl().arg("calibrate").arg("--print-board").arg(&svg).output().expect("runs");
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&svg).expect("svg");
    assert!(text.contains("width=\"285.000mm\""), "{}", &text[..200]);
    // 36 tags, each with its full top and bottom border rows: at least 72 black runs.
    assert!(text.matches("<rect").count() > 72 * 2);
}

#[test]
fn refusals_before_motion_leave_no_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_toml = dir.path().join("calibrated.toml");
    // Too few views asked for: exit 10, nothing written.
    let out =
        hitl().args(["calibrate", "--views", "10", "--out"]).arg(&out_toml).output().expect("runs");
    assert_eq!(out.status.code(), Some(10), "{}", String::from_utf8_lossy(&out.stderr));
    // A board placed where no view can see it whole (behind the target, facing away): exit 10
    // before anything moves.
    let lab = dir.path().join("lab.toml");
    std::fs::write(
        &lab,
        "[board]\nposition_target_m = [0.2, 0.1125, 0.0]\nrpy_deg = [-90.0, 0.0, 90.0]\n",
    )
    .expect("lab");
    let out = hitl()
        .args(["calibrate", "--config"])
        .arg(&lab)
        .arg("--out")
        .arg(&out_toml)
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(10), "{err}");
    assert!(err.contains("nothing moved"), "{err}");
    // No --out: usage error.
    let out = hitl().arg("calibrate").output().expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(!out_toml.exists(), "a refusal wrote {}", out_toml.display());
}

#[test]
fn recordings_name_their_calibration() {
    use hitl_record::RunMetadata;
    use hitl_trajectories::lab::{CalibrationProvenance, LabConfig};
    let m = RunMetadata::default().to_map();
    assert_eq!(m.get("calibration").map(String::as_str), Some("nominal"));
    let mut lab = LabConfig::default();
    assert_eq!(lab.calibration_name(), "nominal");
    lab.calibration = Some(CalibrationProvenance {
        date: "2026-11-23T16:00:00Z".into(),
        views: 20,
        rms_px: 0.218,
        ..Default::default()
    });
    let name = lab.calibration_name();
    assert_eq!(name, "calibrated 2026-11-23T16:00:00Z (20 views, 0.218 px RMS)");
    let m = RunMetadata { calibration: name.clone(), ..Default::default() }.to_map();
    assert_eq!(m.get("calibration"), Some(&name));
    // The provenance block survives the lab TOML round trip.
    let back = LabConfig::from_toml(&lab.to_toml()).expect("round trip");
    assert_eq!(back.calibration, lab.calibration);
}
