//! `hitl report` on a real stub run: the contact sheet shows evenly spread captures at the
//! camera's size, and the run's target model, projected with the recorded intrinsics at the
//! recorded ground-truth pose, lands on the simulated camera's mask (model, scale, pose and pixel
//! conventions agree end to end); index.html shows the sheet.

mod common;
use common::{hitl, SHARED_VM_LAB};

#[test]
fn the_report_of_a_stub_run_has_a_contact_sheet_whose_model_fits_the_masks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("arc.npz");
    let mcap = dir.path().join("run.mcap");
    let out = dir.path().join("report");
    let (t, m, o) = (
        traj.to_str().expect("utf-8"),
        mcap.to_str().expect("utf-8"),
        out.to_str().expect("utf-8"),
    );
    // A 6 s arc of a 10 m fly-around, a capture every 6 waypoints (11 captures).
    let plan = hitl(&[
        "plan",
        "--preset",
        "flyaround",
        "--range-m",
        "10",
        "--duration-s",
        "6",
        "--arc",
        "272:330",
        "--capture-every",
        "6",
        "--out",
        t,
    ]);
    assert_eq!(plan.status.code(), Some(0), "{}", String::from_utf8_lossy(&plan.stderr));
    let run = hitl(&[
        "run",
        t,
        "--record",
        m,
        "--camera",
        "sim",
        "--camera-preset",
        "wfov",
        "--camera-size",
        "160x128",
        "--light",
        "sim",
        "--perception",
        "icp",
        "--plain",
        "--clock",
        "sim",
        "--config",
        SHARED_VM_LAB,
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", String::from_utf8_lossy(&run.stderr));

    let rep = hitl(&["report", m, "--out", o, "--json", "--contact-frames", "6"]);
    assert_eq!(rep.status.code(), Some(0), "{}", String::from_utf8_lossy(&rep.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&rep.stdout).expect("one JSON object");
    let sheet = &summary["contact_sheet"];
    let captures = sheet["captures"].as_u64().expect("captures");
    assert!(captures >= 8, "{sheet}");
    let frames = sheet["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 6, "{sheet}");
    assert_eq!(frames[0]["capture"], 0);
    assert_eq!(frames[5]["capture"].as_u64(), Some(captures - 1));
    assert!(sheet["notes"].as_array().is_some_and(|n| n.is_empty()), "{sheet}");
    let html = std::fs::read_to_string(out.join("index.html")).expect("index.html");
    for f in frames {
        let file = f["file"].as_str().expect("file");
        assert!(html.contains(file), "index.html does not show {file}");
        let bytes = std::fs::read(out.join(file)).expect("png");
        assert_eq!(&bytes[1..4], b"PNG");
        // IHDR: width and height, big-endian, at bytes 16..24.
        let dim = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().expect("4 bytes"));
        assert_eq!((dim(16), dim(20)), (160, 128), "{file}");
        assert_eq!(f["ground_truth"], "mask", "{f}");
        let iou = f["model_mask_iou"].as_f64().expect("model against mask");
        assert!(iou > 0.8, "{file}: model at the ground truth against the mask, IoU {iou}");
        if f["estimate"] == true {
            let iou = f["estimate_iou"].as_f64().expect("estimate against ground truth");
            assert!(iou > 0.3, "{file}: estimate IoU {iou}");
        }
    }
    assert!(frames.iter().any(|f| f["estimate"] == true), "no estimate drawn: {sheet}");
}
