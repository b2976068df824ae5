//! `hitl calibrate` end to end on the embedded stub, as a user runs it in SITL: the views played
//! through the loop, the interlocks and the recorder against a hidden true lab
//! (calib/tests/data/true-lab.toml), the lab recovered within the bounds; then the
//! refusals judged on that same recording with `--from-recording`, so one run of motion (about
//! 100 s) serves every case: every row of docs/calibration.md's table that applies to
//! `--from-recording` (copies of the recording made unsolvable, cut short or damaged give the
//! rows the recording itself cannot). In a file of its own: test binaries run one after another, so the run
//! does not share the machine with other end-to-end tests.

use hitl_trajectories::lab::LabConfig;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hitl() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hitl"))
}

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Translation (m) and rotation (deg) between two poses.
fn apart(a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.translation.vector.norm(), d.rotation.angle().to_degrees())
}

/// A board file as the repository's, but whose tag ids start at `first_id`.
fn board_with_first_id(dir: &Path, first_id: u32) -> PathBuf {
    let text = std::fs::read_to_string(repo("calib/boards/aprilgrid-6x6.toml")).expect("board");
    assert!(text.contains("first_id = 0\n"));
    let path = dir.join(format!("board-{first_id}.toml"));
    std::fs::write(&path, text.replace("first_id = 0\n", &format!("first_id = {first_id}\n")))
        .expect("write board");
    path
}

/// `src` written again to `dst` message by message, each message's bytes as `f(topic, data)`
/// gives them (the metadata is not copied: calibrate does not read it).
fn rewrite(src: &Path, dst: &Path, mut f: impl FnMut(&str, &[u8]) -> Vec<u8>) {
    let bytes = std::fs::read(src).expect("read the recording");
    let out = std::io::BufWriter::new(std::fs::File::create(dst).expect("create"));
    let mut w = mcap::Writer::new(out).expect("writer");
    for m in mcap::MessageStream::new(&bytes).expect("stream") {
        let m = m.expect("message");
        let data = f(&m.channel.topic, &m.data);
        w.write(&mcap::Message { data: data.into(), ..m }).expect("write");
    }
    w.finish().expect("finish");
}

#[test]
fn calibrate_recovers_the_hidden_lab_and_refuses_what_it_cannot_solve() {
    let dir = tempfile::tempdir().expect("tempdir");
    let record = dir.path().join("calibration.mcap");
    let out = dir.path().join("calibrated.toml");
    let scratch = dir.path().join("tmp");
    std::fs::create_dir(&scratch).expect("scratch");
    // The controller plans with the default lab (the shared-VM interlocks: CI's host takes CPUs
    // away for tens of milliseconds, tests/data/shared-vm-lab.toml says why); the stub simulates
    // the true lab, 5.4 mm / 2.2 deg (camera) and 18 mm / 3.9 deg (target) off it.
    let run = hitl()
        .args(["calibrate", "--views", "15", "--plain", "--clock", "sim", "--config"])
        .arg(repo("tests/data/shared-vm-lab.toml"))
        .arg("--stub-config")
        .arg(repo("calib/tests/data/true-lab.toml"))
        .arg("--record")
        .arg(&record)
        .arg("--out")
        .arg(&out)
        .env("TMPDIR", &scratch)
        .output()
        .expect("runs");
    let all = text(&run);
    assert_eq!(run.status.code(), Some(0), "{all}");
    assert!(all.contains("calibrated lab configuration"), "{all}");

    // Recovered within 1 mm and 0.1 deg of the truth (the bound), both quantities.
    let truth = LabConfig::load(&repo("calib/tests/data/true-lab.toml")).expect("true lab");
    let nominal = LabConfig::default();
    let got = LabConfig::load(&out).expect("the calibrated lab loads");
    let (t, r) = apart(&got.camera_mount(), &truth.camera_mount());
    assert!(t < 1e-3 && r < 0.1, "camera mount {:.3} mm, {r:.4} deg off the truth", t * 1e3);
    let (t, r) = apart(&got.target_in_base(), &truth.target_in_base());
    assert!(t < 1e-3 && r < 0.1, "target {:.3} mm, {r:.4} deg off the truth", t * 1e3);
    // ... where the nominal lab was millimetres and degrees off: the test can fail.
    let (t, r) = apart(&nominal.camera_mount(), &truth.camera_mount());
    assert!(t > 3e-3 && r > 1.0, "the nominal mount is {t} m, {r} deg off");
    let cal = got.calibration.as_ref().expect("a [calibration] provenance block");
    assert!(cal.views >= 15, "{cal:?}");
    assert!(cal.rms_px > 0.0 && cal.rms_px < 1.0, "{cal:?}");
    assert_eq!(cal.view_rms_px.len(), cal.views as usize);
    // The interlocks of --config are kept, only the geometry and the board are new.
    let vm = LabConfig::load(&repo("tests/data/shared-vm-lab.toml")).expect("vm lab");
    assert_eq!(got.interlocks.report_timeout_ms, vm.interlocks.report_timeout_ms);

    // The ground truth a run records (target in camera: (base_T_flange mount)^-1 base_T_target)
    // with the calibrated lab, at every capture's flange pose this run recorded, against the same with the
    // true lab: within 1 mm and 0.1 deg (the bound for recorded ground truth).
    let rec = hitl_record::reader::read_recording(&record).expect("the recording reads");
    // One `/tf` per capture: one per view.
    assert_eq!(rec.tf.len() as u32, cal.views, "flange poses recorded");
    // The views were handed to the run in memory (no file written): the recording names them
    // and the hash of the NPZ they would be.
    let run_md = &rec.metadata["run"];
    let config: serde_json::Value = serde_json::from_str(&run_md["config"]).expect("config");
    assert_eq!(config["trajectory"], "calibration views (planned by hitl calibrate)");
    assert_eq!(run_md["trajectory_sha256"].len(), 64, "{:?}", run_md["trajectory_sha256"]);
    let truth_in_camera = |lab: &LabConfig, base_flange: &nalgebra::Isometry3<f64>| {
        (base_flange * lab.camera_mount()).inverse() * lab.target_in_base()
    };
    let worst = rec.tf.iter().fold((0.0f64, 0.0f64), |(wt, wr), tf| {
        let base_flange = tf.base_flange;
        let (t, r) =
            apart(&truth_in_camera(&got, &base_flange), &truth_in_camera(&truth, &base_flange));
        (wt.max(t), wr.max(r))
    });
    assert!(worst.0 < 1e-3 && worst.1 < 0.1, "recorded truth off by {worst:?} (m, deg)");
    let nominal_off = apart(
        &truth_in_camera(&nominal, &rec.tf[0].base_flange),
        &truth_in_camera(&truth, &rec.tf[0].base_flange),
    );
    assert!(nominal_off.0 > 5e-3, "the nominal lab records {nominal_off:?} off the truth");

    // The same recording solved again, moving nothing: the same answer.
    let again = dir.path().join("again.toml");
    let o = hitl()
        .arg("calibrate")
        .arg("--from-recording")
        .arg(&record)
        .arg("--out")
        .arg(&again)
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("nothing moves"), "{}", text(&o));
    let twice = LabConfig::load(&again).expect("loads");
    let (t, r) = apart(&twice.camera_mount(), &got.camera_mount());
    assert!(t < 1e-6 && r < 1e-4, "{t} m, {r} deg between two solves of one recording");

    // Refusals, each with its own exit code and reason; none writes the output.
    let refused = dir.path().join("refused.toml");
    let solve_file = |rec: &Path, extra: &[&std::ffi::OsStr]| {
        let o = hitl()
            .arg("calibrate")
            .arg("--from-recording")
            .arg(rec)
            .arg("--out")
            .arg(&refused)
            .args(extra)
            .output()
            .expect("runs");
        (o.status.code(), text(&o))
    };
    let solve = |extra: &[&std::ffi::OsStr]| solve_file(&record, extra);
    // Residuals worse than accepted (as noisy corners give): exit 3, with the remedy.
    let (code, all) = solve(&["--max-rms-px".as_ref(), "0.01".as_ref()]);
    assert_eq!(code, Some(3), "{all}");
    assert!(all.contains("px"), "{all}");
    // A board definition none of whose tags is printed (ids 36-71): never detected, exit 12.
    let b = board_with_first_id(dir.path(), 36);
    let (code, all) = solve(&["--board".as_ref(), b.as_os_str()]);
    assert_eq!(code, Some(12), "{all}");
    assert!(all.contains("no tag of the board"), "{all}");
    // One that matches only two printed tags (ids 34-69): the board is seen but never whole in a
    // view, as when it sits off where the lab puts it: exit 11.
    let b = board_with_first_id(dir.path(), 34);
    let (code, all) = solve(&["--board".as_ref(), b.as_os_str()]);
    assert_eq!(code, Some(11), "{all}");
    assert!(all.contains("seen whole"), "{all}");
    assert!(!refused.exists(), "a refusal wrote {}", refused.display());

    // Every capture the first one again (same image, same flange pose): the camera never turns,
    // poor conditioning, exit 3.
    let same = dir.path().join("same-view.mcap");
    let mut first: Option<Vec<u8>> = None;
    rewrite(&record, &same, |topic, data| match topic {
        "/camera/color" => first.get_or_insert_with(|| data.to_vec()).clone(),
        _ => data.to_vec(),
    });
    let (code, all) = solve_file(&same, &[]);
    assert_eq!(code, Some(3), "{all}");
    assert!(all.contains("about one axis only"), "{all}");
    // The board blanked out of all but 6 captures: detected in fewer than 10 views, exit 10.
    let blank = dir.path().join("blanked.mcap");
    let mut seen = 0;
    rewrite(&record, &blank, |topic, data| {
        if topic != "/camera/color" {
            return data.to_vec();
        }
        seen += 1;
        let mut img =
            <foxglove::messages::RawImage as prost::Message>::decode(data).expect("image");
        if seen > 6 {
            img.data = vec![0u8; img.data.len()].into();
        }
        prost::Message::encode_to_vec(&img)
    });
    let (code, all) = solve_file(&blank, &[]);
    assert_eq!(code, Some(10), "{all}");
    assert!(all.contains("detected in only 6 of 15"), "{all}");
    // Cut short at three quarters (a crash): fewer captures than a live calibration plans, and
    // it says the file was not read to its end: exit 10.
    let cut = dir.path().join("cut.mcap");
    let bytes = std::fs::read(&record).expect("read");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).expect("write");
    let (code, all) = solve_file(&cut, &[]);
    assert_eq!(code, Some(10), "{all}");
    assert!(
        all.contains("not read to its end") && all.contains("fewer than the 15 views"),
        "{all}"
    );
    assert!(!refused.exists(), "a refusal wrote {}", refused.display());

    // Not a recording: bad input, exit 2.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").expect("write");
    let o = hitl()
        .arg("calibrate")
        .arg("--from-recording")
        .arg(&junk)
        .arg("--out")
        .arg(&refused)
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("junk.mcap"), "{}", text(&o));
    // --from-recording moves nothing: it takes no arm.
    let o = hitl()
        .args(["calibrate", "--arm", "192.0.2.1", "--from-recording"])
        .arg(&record)
        .arg("--out")
        .arg(&refused)
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(!refused.exists());
    // The run's scratch folder (views' trajectory) is gone.
    let left: Vec<_> = std::fs::read_dir(&scratch).expect("tmp").filter_map(|e| e.ok()).collect();
    assert!(left.is_empty(), "left in the temporary folder: {left:?}");
}
