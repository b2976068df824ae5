//! The committed presets: regeneration reproduces them bit for bit, they pass preflight, and
//! numpy reads what the planner writes.

use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::planner::{self, presets, PlanRequest, Timing};
use hitl_trajectories::{npz, preflight, timing};
use std::path::PathBuf;
use std::process::Command;

fn preset_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("presets")
}

/// `HITL_WRITE_PRESETS=1 cargo test -p hitl-trajectories --release --test planner_presets` writes
/// the presets (the same bytes as the `hitl plan` commands in presets/README.md) and prints their
/// summaries; without the variable it does nothing.
#[test]
fn write_presets_when_asked() {
    if std::env::var_os("HITL_WRITE_PRESETS").is_none() {
        return;
    }
    let lab = LabConfig::default();
    for p in presets::committed() {
        let plan = planner::plan(&p.request, &lab, &mut |_, _| {}).expect(p.file);
        let table = timing::SetpointTable::build(&plan.trajectory, timing::DEFAULT_RATE_HZ, 1.0)
            .expect("timing");
        let report = preflight::check(&plan.trajectory, &table, &lab);
        println!("{}: {}", p.file, serde_json::to_string(&plan.summary).unwrap_or_default());
        println!("  preflight safe: {} {:?}", report.is_safe(), report.violations);
        npz::save(&preset_dir().join(p.file), &plan.trajectory, true).expect("save");
    }
}

#[test]
fn regeneration_reproduces_the_committed_presets_bit_for_bit() {
    let lab = LabConfig::default();
    for p in presets::committed() {
        let path = preset_dir().join(p.file);
        let committed = std::fs::read(&path).unwrap_or_else(|e| {
            panic!("{}: {e} (regenerate: see presets/README.md)", path.display())
        });
        let plan = planner::plan(&p.request, &lab, &mut |_, _| {}).expect(p.file);
        let bytes = npz::to_bytes(&plan.trajectory, true).expect("encode");
        assert!(
            bytes == committed,
            "{} differs from `hitl plan {} --out ...`: regenerate it (presets/README.md)",
            p.file,
            p.flags
        );
        // And every committed preset passes the preflight at the default rate.
        let table = timing::SetpointTable::build(&plan.trajectory, timing::DEFAULT_RATE_HZ, 1.0)
            .expect("timing");
        let report = preflight::check(&plan.trajectory, &table, &lab);
        assert!(report.is_safe(), "{}: {:?}", p.file, report.violations);
    }
}

#[test]
fn numpy_reads_the_planner_output() {
    let lab = LabConfig::default();
    let req = PlanRequest {
        timing: Timing::DurationS(8.0),
        waypoints: Some(41),
        capture_every: 5,
        // Half the orbit: 41 waypoints are too coarse for the wrist's fast stretch near u = 530.
        arc_deg: Some((270.0, 450.0)),
        ..PlanRequest::default()
    };
    let plan = planner::plan(&req, &lab, &mut |_, _| {}).expect("plan");
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("fly.npz");
    npz::save(&file, &plan.trajectory, true).expect("save");
    let python = PathBuf::from(env!("HITL_VENV_PYTHON"));
    assert!(python.exists(), "no venv python at {}: run make setup", python.display());
    let script = r#"
import json, sys
import numpy as np
d = np.load(sys.argv[1])
m = json.loads(str(d["meta"]))
q = d["qpos"]; t = d["t"]; c = d["cam_pose_base"]
assert q.shape == (41, 7) and q.dtype == np.float64, q.shape
assert t.shape == (41,) and np.all(np.diff(t) > 0)
assert d["capture"].dtype == np.bool_ and int(d["capture"].sum()) == 9
assert d["light"].dtype == np.float32
assert c.shape == (41, 4, 4) and np.allclose(c[:, 3], [0, 0, 0, 1])
assert d["rel_pos_rtn_m"].shape == (41, 3) and d["u_rad"].shape == (41,)
assert d["sun_phase_deg"].shape == (41,)
# The optical axis (third column) points from the camera at the target.
tgt = np.array(m["target_pos_base_m"])
v = tgt - c[:, :3, 3]
cosang = np.einsum("ij,ij->i", v / np.linalg.norm(v, axis=1)[:, None], c[:, :3, 2])
assert np.all(cosang > 1 - 1e-12), cosang.min()
# Scaled RTN positions + target = camera positions.
R = np.array(m["rtn_to_base"])
pos = tgt + m["scale"] * d["rel_pos_rtn_m"] @ R.T
assert np.allclose(pos, c[:, :3, 3], atol=1e-12)
print(json.dumps({"n": int(q.shape[0]), "preset": m["preset"], "roe": m["roe"]}))
"#;
    let out = Command::new(&python).arg("-c").arg(script).arg(&file).output().expect("run python");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "numpy refused: {}{}",
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).expect("json");
    assert_eq!(v["n"], 41);
    assert_eq!(v["preset"], "flyaround");
}
