//! `--scene-kind` end to end: a short station-keeping run played in `orbit` records its frames,
//! which are black wherever the target (or the Earth) is not, the flag overriding the lab
//! configuration's `[scene] kind`; its Sun goes once round (Sun phase 0 to 360 deg) while the
//! camera stands still, and the target's lit share follows it (the session hands the
//! trajectory's Sun to the camera); a scene kind that does not exist is bad input.

use hitl_record::reader::{decode_image, read_recording, visit};
use hitl_trajectories::npz;
use std::ops::ControlFlow;

mod common;
use common::hitl;

#[test]
fn an_unknown_scene_kind_is_bad_input() {
    let out = hitl(&["run", "nothing.npz", "--scene-kind", "space"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("lab or orbit"), "{err}");
}

#[test]
fn an_orbit_run_records_frames_on_a_black_sky() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("fly.npz");
    let mcap = dir.path().join("run.mcap");
    let config = dir.path().join("lab.toml");
    // The shared-VM lab (tests/data/shared-vm-lab.toml says why) asking for the lab scene.
    let shared = std::fs::read_to_string(common::SHARED_VM_LAB).expect("shared-vm lab");
    std::fs::write(&config, format!("{shared}\n[scene]\nkind = \"lab\"\n")).expect("config");
    let (t, m, c) = (
        traj.to_str().expect("utf-8"),
        mcap.to_str().expect("utf-8"),
        config.to_str().expect("utf-8"),
    );
    // Alpha 0.3: the point 21 cm from the target, where the approach from the stub's start pose
    // keeps its clearances (the default 7.7 cm does not).
    let plan = hitl(&[
        "plan",
        "--preset",
        "station-keeping",
        "--range-m",
        "10",
        "--duration-s",
        "4",
        "--alpha",
        "0.3",
        "--capture-every",
        "8",
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
        "96x76",
        "--light",
        "sim",
        "--plain",
        "--clock",
        "sim",
        "--config",
        c,
        "--scene-kind",
        "orbit",
    ]);
    let out =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert_eq!(run.status.code(), Some(0), "{out}");

    let captures = npz::load(&traj).expect("plan").trajectory.capture_count() as u64;
    assert!(captures >= 4, "{captures} captures");
    let rec = read_recording(&mcap).expect("recording");
    assert_eq!(rec.topic_counts.get("/camera/color").copied(), Some(captures), "{out}");
    // The flag won over the file: the recorded lab configuration says orbit.
    let lab = &rec.metadata["run"]["lab_config"];
    assert!(lab.contains("kind = \"orbit\""), "{lab}");

    // Every frame: the target in view, and the sky black (no enclosure, tripod or arm drawn).
    let mut colour = Vec::new();
    let mut masks = Vec::new();
    visit(
        &mcap,
        |msg| {
            let img = || decode_image(msg.data).expect("image decodes");
            match msg.topic {
                "/camera/color" => colour.push((msg.log_time, img().data.to_vec())),
                "/camera/mask" => masks.push((msg.log_time, img().data.to_vec())),
                _ => {}
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .expect("visit");
    colour.sort_by_key(|f| f.0);
    masks.sort_by_key(|f| f.0);
    assert_eq!((colour.len() as u64, masks.len() as u64), (captures, captures));
    let mut target_grey = Vec::new();
    for ((_, rgb), (_, mask)) in colour.iter().zip(&masks) {
        let px: Vec<&[u8]> = rgb.chunks_exact(3).collect();
        let black = px.iter().filter(|p| p.iter().all(|v| *v == 0)).count();
        assert!(black * 2 > px.len(), "{black} of {} pixels black", px.len());
        let on: Vec<f64> = (0..px.len())
            .filter(|&i| mask[i] == 255)
            .map(|i| px[i].iter().map(|v| f64::from(*v)).sum::<f64>() / 3.0)
            .collect();
        assert!(on.len() > 20, "the target covers {} px", on.len());
        target_grey.push(on.iter().sum::<f64>() / on.len() as f64);
    }
    // Sun phase 0 (Sun behind the camera) lights the side in view; near 180 deg it is in shadow.
    let max = target_grey.iter().copied().fold(0.0, f64::max);
    let min = target_grey.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(max > 2.0 * min + 10.0, "the target's mean grey per capture: {target_grey:.1?}");
}
