//! The real camera's path in SITL (issue 23): `--camera sim --mask rendered --depth-model orbbec`
//! hands perception what an Orbbec frame hands it (stereo depth, no simulator mask); the mask is
//! drawn from the controller's (calibrated) lab while the stub shows the hidden truth
//! (`--stub-config`), recorded on `/camera/mask` and named in the metadata. A controller that
//! believes the target 2 cm from where the stub has it draws a mask that misses it. With the
//! controller's lab equal to the stub's, at the Orbbec preset's 1280x800 over a short arc of the
//! fly-around, the drawn mask meets issue 23's figures against the simulator's own silhouette
//! (default margin: covers >= 98 %, at most 1.5x its area; margin 0: mean IoU >= 0.95). The
//! calibrated-lab runs are short at 320x256; the full fly-around's figures are docs/perception.md's.

use hitl_record::reader::read_recording;

mod common;
use common::{hitl, num, plan_flyaround_arc, text};

const TRUE_LAB: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/calib/tests/data/true-lab.toml");
const CALIBRATED: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/calibrated-lab.toml");
const OFF_2CM: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/target-2cm-off-lab.toml");

/// A 5 s arc of the 10 m fly-around (about 13 captures) planned in `lab`.
fn plan(dir: &std::path::Path, lab: &str) -> String {
    let out = dir.join("arc.npz").to_str().expect("utf-8").to_string();
    let plan = hitl(&[
        "plan",
        "--preset",
        "flyaround",
        "--range-m",
        "10",
        "--duration-s",
        "5",
        "--arc",
        "282:327",
        "--capture-every",
        "4",
        "--config",
        lab,
        "--out",
        &out,
    ]);
    assert_eq!(plan.status.code(), Some(0), "{}", String::from_utf8_lossy(&plan.stderr));
    out
}

/// `hitl run` on the real path; its stdout and stderr.
fn run_real_path(traj: &str, lab: &str, record: &str) -> (Option<i32>, String) {
    let run = hitl(&[
        "run",
        traj,
        "--record",
        record,
        "--camera",
        "sim",
        "--camera-preset",
        "wfov",
        "--camera-size",
        "320x256",
        "--light",
        "sim",
        "--plain",
        "--clock",
        "sim",
        "--mask",
        "rendered",
        "--depth-model",
        "orbbec",
        "--perception",
        "icp",
        "--stub-config",
        TRUE_LAB,
        "--config",
        lab,
    ]);
    let out =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    (run.status.code(), out)
}

/// The number after `key` in the run's summary (`covers mean 99.5 %` -> 99.5 for `covers mean `).
fn figure(out: &str, key: &str) -> f64 {
    let tail = out.split(key).nth(1).unwrap_or_else(|| panic!("no {key:?}: {out}"));
    let num: String = tail
        .trim_start_matches('x')
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    num.parse().unwrap_or_else(|_| panic!("{key:?} is not followed by a number: {out}"))
}

/// The summary's line comparing the drawn masks with the simulator's.
fn compared(out: &str) -> &str {
    out.lines()
        .find(|l| l.contains("against the simulator's over "))
        .unwrap_or_else(|| panic!("no mask comparison: {out}"))
}

/// The `covers mean X %` figure of the run's summary.
fn coverage_pct(out: &str) -> f64 {
    figure(out, "covers mean ")
}

/// `hitl run` on the simulated clock with the Orbbec preset at its 1280x800, the simulated
/// light, drawn masks and the Orbbec depth model, then `extra`; its exit code, stdout and stderr.
fn run_orbbec(traj: &str, record: &str, extra: &[&str]) -> (Option<i32>, String) {
    let mut args = vec![
        "run",
        traj,
        "--record",
        record,
        "--camera",
        "sim",
        "--camera-preset",
        "orbbec",
        "--camera-size",
        "1280x800",
        "--light",
        "sim",
        "--plain",
        "--clock",
        "sim",
        "--mask",
        "rendered",
        "--depth-model",
        "orbbec",
    ];
    args.extend_from_slice(extra);
    let run = hitl(&args);
    (run.status.code(), text(&run))
}

/// [`run_orbbec`] with the controller's lab equal to the stub's (no `--stub-config`), rendered
/// masks with `margin` pixels, no estimator.
fn run_equal_lab(traj: &str, margin: &str, record: &str) -> (Option<i32>, String) {
    run_orbbec(
        traj,
        record,
        &["--mask-margin-px", margin, "--perception", "none", "--config", TRUE_LAB],
    )
}

#[test]
fn with_the_stubs_lab_the_rendered_mask_matches_the_simulators_at_1280x800() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), TRUE_LAB);
    let rec = dir.path().join("m2.mcap");
    let (code, out) = run_equal_lab(&traj, "2", rec.to_str().expect("utf-8"));
    assert!(matches!(code, Some(0 | 4)), "{out}");
    let line = compared(&out);
    assert!(figure(line, "against the simulator's over ") >= 5.0, "{out}");
    // Default margin: the drawn mask covers the true silhouette on every frame, at most 1.5x it.
    assert!(figure(line, "covers mean ") >= 98.0, "{out}");
    assert!(figure(line, "% (min ") >= 98.0, "{out}");
    assert!(figure(line, "(max x") <= 1.5, "{out}");
    assert!(figure(line, "area x") >= 1.0, "{out}");

    // No margin: the drawing is the silhouette itself.
    let rec = dir.path().join("m0.mcap");
    let (code, out) = run_equal_lab(&traj, "0", rec.to_str().expect("utf-8"));
    assert!(matches!(code, Some(0 | 4)), "{out}");
    assert!(out.contains("mask: rendered, margin 0 px;"), "{out}");
    let line = compared(&out);
    assert!(figure(line, "against the simulator's over ") >= 5.0, "{out}");
    assert!(figure(line, "silhouette IoU mean ") >= 0.95, "{out}");
}

#[test]
fn the_rendered_mask_follows_the_controllers_lab_and_is_recorded() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), CALIBRATED);
    let mcap = dir.path().join("run.mcap");
    let m = mcap.to_str().expect("utf-8");
    let (code, out) = run_real_path(&traj, CALIBRATED, m);
    // 4: an interlock the shared machine's load tripped late in the arc (the captures so far are
    // recorded; at least 8 are asked below).
    assert!(matches!(code, Some(0 | 4)), "{out}");
    assert!(out.contains("mask: rendered, margin 2 px;"), "{out}");
    assert!(out.contains(" 0 empty"), "{out}");
    // Drawn from the calibrated lab, it covers what the stub (the truth) draws.
    assert!(coverage_pct(&out) >= 98.0, "{out}");

    let rec = read_recording(&mcap).expect("recording");
    let meta = &rec.metadata["run"];
    assert_eq!(meta["mask_source"], "rendered");
    assert_eq!(meta["mask_margin_px"], "2");
    let frames = rec.topic_counts.get("/camera/depth").copied().unwrap_or(0);
    assert!(frames >= 8, "{frames} frames: {out}");
    assert_eq!(rec.topic_counts.get("/camera/mask").copied(), Some(frames));
    assert_eq!(rec.pose_estimate.len() as u64, frames, "every frame estimated: {out}");

    // The same arc with a controller that believes the target 2 cm off: its masks follow that
    // belief and miss most of the target the stub shows.
    let traj = plan(dir.path(), OFF_2CM);
    let off = dir.path().join("off.mcap");
    let (code, out) = run_real_path(&traj, OFF_2CM, off.to_str().expect("utf-8"));
    assert!(matches!(code, Some(0 | 4)), "{out}");
    assert!(!out.contains("over 0 frames"), "{out}");
    assert!(coverage_pct(&out) < 50.0, "{out}");
}

#[test]
fn the_simulators_mask_is_refused_for_a_camera_without_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), CALIBRATED);
    let run = hitl(&["run", &traj, "--camera", "none", "--mask", "sim", "--config", CALIBRATED]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(err.contains("--mask sim needs --camera sim"), "{err}");
}

/// The README's real-path row for `target` (`scripts/sitl_real_path.sh TARGET`): the whole 10 m
/// fly-around (41 captures), Orbbec preset at 1280x800, stereo depth, drawn masks, ICP on the
/// default lab; `hitl eval --json` of the recording.
fn real_path_row(target: &str) -> serde_json::Value {
    real_path_row_on(target, None)
}

/// [`real_path_row`] over the arc `arc` of the fly-around (`ARC=` of the script).
fn real_path_row_on(target: &str, arc: Option<&str>) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("flyaround.npz");
    plan_flyaround_arc(&traj, "10", "5", arc);
    let traj = traj.to_str().expect("utf-8").to_string();
    let rec = dir.path().join("run.mcap").to_str().expect("utf-8").to_string();
    let (code, out) = run_orbbec(&traj, &rec, &["--perception", "icp", "--target-model", target]);
    assert!(matches!(code, Some(0 | 4)), "{out}");
    let eval = hitl(&["eval", &rec, "--json"]);
    assert_eq!(eval.status.code(), Some(0), "{}", String::from_utf8_lossy(&eval.stderr));
    let m: serde_json::Value = serde_json::from_slice(&eval.stdout).expect("eval's JSON");
    assert_eq!(m["frames"], 41, "{m}");
    m
}

#[test]
fn on_the_real_path_the_track_holds_sat2_through_the_frames_the_stand_hides() {
    // Near frame 30 the stand hides sat2's lower part and a stereo camera sees no depth on it
    // nor in its shadow: a track whose drawing falls there is not charged for it, and a track
    // start whose ICP fit ends just outside the checks is refined before the frame is given
    // up. Without that, the frame was lost.
    let m = real_path_row("sat2-one-plane");
    assert_eq!(m["failures"], 0, "{m}");
    // Its first view (end on, ~250 depth pixels) sets the figure: 2.2 deg (6.7 before the
    // track's predictions always reached registration's last comparison, 8.1 before the tracked
    // frames' pixel-wise steps).
    let er = num(&m, "mean_er_deg");
    assert!(er < 10.0, "mean e_r {er}: {m}");
}

#[test]
fn on_the_real_path_from_a_broadside_start_the_track_recovers_from_the_end_on_views() {
    // Started broadside (argument of latitude 350 deg), sat2's first frame is pinned to 0.3 deg;
    // the end-on views half a turn on are not (1-sigma bounds of 1.3-2 deg: docs/perception.md,
    // "What the first frame can say at all"). Without pixel-wise steps on the tracked frames
    // the track came out of them holding their error (mean e_r 2.11 deg, a frame lost); with
    // them it comes back to what the frame says (1.31 deg, none lost).
    let m = real_path_row_on("sat2-one-plane", Some("350:710"));
    assert_eq!(m["failures"], 0, "{m}");
    let er = num(&m, "mean_er_deg");
    assert!(er < 1.7, "mean e_r {er}: {m}");
}

#[test]
fn on_the_real_path_a_track_that_explains_nothing_is_lost_not_carried_into_a_flip() {
    // At two-planes' frame 29 the stand hides most of it and the track's drawing explains the
    // frame no better than drawing nothing (agreement -0.004). Kept as an estimate, it led the
    // next frames' registration onto a look-alike turned 180 deg, held to the end: mean e_r
    // 44.6 deg. Given up, the next registration continues the last good track.
    let m = real_path_row("two-planes");
    assert!(num(&m, "failures") <= 2.0, "{m}");
    let er = num(&m, "mean_er_deg");
    assert!(er < 5.0, "mean e_r {er}: {m}");
}
