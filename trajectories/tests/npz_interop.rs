//! NPZ interop with real numpy (the venv's): files numpy writes load here with exactly the same
//! values, and files hitl writes load in numpy with exactly the same values and dtypes.

use hitl_trajectories::npz;
use hitl_trajectories::Trajectory;
use std::path::{Path, PathBuf};
use std::process::Command;

fn python() -> PathBuf {
    let p = PathBuf::from(env!("HITL_VENV_PYTHON"));
    assert!(p.exists(), "{} is missing: run make setup", p.display());
    p
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hitl-npz-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// Run a Python snippet with `args`; its stdout.
fn py(code: &str, args: &[&Path]) -> String {
    let out = Command::new(python()).arg("-c").arg(code).args(args).output().expect("run python");
    assert!(out.status.success(), "python: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// numpy writes every key in several layouts, plus a JSON of the values (floats as the bit
/// patterns of their exact float64 widening, so the comparison is exact).
const WRITE_PY: &str = r#"
import json, sys
import numpy as np
out = sys.argv[1]
n = 9
t = np.linspace(0.0, 2.0, n) ** 1.5
q = 0.1 * np.sin(np.arange(n * 7).reshape(n, 7) * 0.37) + np.array([0.0, -0.4, 0.0, 1.4, 0.0, 1.5, 0.0])
arrays = dict(
    qpos=q, t=t,
    capture=(np.arange(n) % 3 == 0),
    light=np.linspace(0.0, 1.0, n).astype(np.float32),
    u_rad=np.linspace(0.1, 0.9, n) * np.pi,
    rel_pos_rtn_m=np.cos(np.arange(n * 3).reshape(n, 3) * 1.1),
    cam_pose_base=np.sin(np.arange(n * 16).reshape(n, 4, 4) * 0.05),
    sun_phase_deg=np.linspace(0.0, 359.5, n),
    meta=np.array(json.dumps({"preset": "vbar", "scale": 0.25, "name": "\u00e9t\u00e9"}, ensure_ascii=False)),
)
np.savez(out + "/plain.npz", **arrays)
np.savez_compressed(out + "/compressed.npz", **arrays)
f = dict(arrays)
f["qpos"] = np.asfortranarray(q.astype(np.float32))
f["rel_pos_rtn_m"] = np.asfortranarray(arrays["rel_pos_rtn_m"])
f["cam_pose_base"] = np.asfortranarray(arrays["cam_pose_base"].astype(np.float32))
f["light"] = arrays["light"].astype(np.float64)
f["t"] = t.astype(">f8")
np.savez_compressed(out + "/fortran_f32.npz", **f)
import zipfile
with zipfile.ZipFile(out + "/fortran_f32.npz") as z, z.open("qpos.npy") as fh:
    np.lib.format.read_magic(fh)
    _, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
    assert fortran and dtype == np.float32, (fortran, dtype)
def plain(a):
    # Floats travel as their float64 bit patterns: exact whatever the JSON float parser does.
    return a.astype(np.float64).view(np.uint64).tolist() if a.dtype.kind == "f" else a.tolist()
json.dump({k: plain(v) for k, v in arrays.items()}, open(out + "/values.json", "w"))
json.dump({k: plain(v) for k, v in f.items()}, open(out + "/values_f.json", "w"))
"#;

fn expected(path: &Path) -> Trajectory {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("json")).expect("parse");
    let f = |x: &serde_json::Value| f64::from_bits(x.as_u64().expect("float64 bits"));
    let rows = |k: &str| -> Vec<Vec<f64>> {
        v[k].as_array()
            .expect("array")
            .iter()
            .map(|r| r.as_array().expect("row").iter().map(f).collect())
            .collect()
    };
    Trajectory {
        qpos: rows("qpos").iter().map(|r| r.as_slice().try_into().expect("7")).collect(),
        t: v["t"].as_array().expect("t").iter().map(f).collect(),
        capture: Some(
            v["capture"]
                .as_array()
                .expect("c")
                .iter()
                .map(|b| b.as_bool().expect("bool"))
                .collect(),
        ),
        light: Some(v["light"].as_array().expect("l").iter().map(|x| f(x) as f32).collect()),
        u_rad: Some(v["u_rad"].as_array().expect("u").iter().map(f).collect()),
        rel_pos_rtn_m: Some(
            rows("rel_pos_rtn_m").iter().map(|r| r.as_slice().try_into().expect("3")).collect(),
        ),
        cam_pose_base: Some(
            v["cam_pose_base"]
                .as_array()
                .expect("poses")
                .iter()
                .map(|m| {
                    let mut out = [[0.0; 4]; 4];
                    for (r, row) in m.as_array().expect("m").iter().enumerate() {
                        for (c, x) in row.as_array().expect("r").iter().enumerate() {
                            out[r][c] = f(x);
                        }
                    }
                    out
                })
                .collect(),
        ),
        sun_phase_deg: Some(v["sun_phase_deg"].as_array().expect("s").iter().map(f).collect()),
        meta: Some(v["meta"].as_str().expect("meta").to_string()),
    }
}

#[test]
fn numpy_written_files_load_with_the_same_values() {
    let dir = temp_dir("from-numpy");
    py(WRITE_PY, &[&dir]);
    let want = expected(&dir.join("values.json"));
    for name in ["plain.npz", "compressed.npz"] {
        let got = npz::load(&dir.join(name)).expect(name);
        assert_eq!(got.trajectory, want, "{name}");
        assert!(got.warnings.is_empty(), "{name}: {:?}", got.warnings);
    }
    // float32 qpos and poses, Fortran order, float64 light, big-endian t.
    let got = npz::load(&dir.join("fortran_f32.npz")).expect("fortran");
    assert_eq!(got.trajectory, expected(&dir.join("values_f.json")));
    assert!(got.trajectory.meta.as_deref().unwrap_or_default().contains("\u{e9}t\u{e9}"));
}

/// numpy loads what hitl wrote and prints dtypes, shapes and values as JSON.
const READ_PY: &str = r#"
import json, sys, zipfile
import numpy as np
path = sys.argv[1]
names = sorted(zipfile.ZipFile(path).namelist())
with np.load(path, allow_pickle=False) as z:
    out = {"names": names}
    for k in z.files:
        a = z[k]
        out[k] = {"dtype": a.dtype.str, "shape": list(a.shape),
                  "values": a.astype(np.float64).view(np.uint64).tolist() if a.dtype.kind == "f" else a.tolist()}
print(json.dumps(out))
"#;

#[test]
fn files_hitl_writes_load_in_numpy_with_the_same_values() {
    let dir = temp_dir("to-numpy");
    py(WRITE_PY, &[&dir]);
    let traj = expected(&dir.join("values.json"));
    for compressed in [false, true] {
        let path = dir.join(format!("ours-{compressed}.npz"));
        npz::save(&path, &traj, compressed).expect("save");
        let v: serde_json::Value =
            serde_json::from_str(&py(READ_PY, &[&path])).expect("numpy's view");
        let names: Vec<&str> =
            v["names"].as_array().expect("names").iter().filter_map(|x| x.as_str()).collect();
        assert_eq!(
            names,
            [
                "cam_pose_base.npy",
                "capture.npy",
                "light.npy",
                "meta.npy",
                "qpos.npy",
                "rel_pos_rtn_m.npy",
                "sun_phase_deg.npy",
                "t.npy",
                "u_rad.npy"
            ]
        );
        let dtype = |k: &str| v[k]["dtype"].as_str().unwrap_or_default().to_string();
        assert_eq!(dtype("qpos"), "<f8");
        assert_eq!(dtype("t"), "<f8");
        assert_eq!(dtype("capture"), "|b1");
        assert_eq!(dtype("light"), "<f4");
        assert!(dtype("meta").starts_with("<U"), "{}", dtype("meta"));
        assert_eq!(v["meta"]["shape"], serde_json::json!([]));
        assert_eq!(v["cam_pose_base"]["shape"], serde_json::json!([9, 4, 4]));
        // Same values, exactly: compare numpy's lists with ours through the same JSON path.
        let back = {
            let dir2 = temp_dir(&format!("to-numpy-values-{compressed}"));
            let mut m = serde_json::Map::new();
            for k in [
                "qpos",
                "t",
                "capture",
                "light",
                "u_rad",
                "rel_pos_rtn_m",
                "cam_pose_base",
                "sun_phase_deg",
                "meta",
            ] {
                m.insert(k.into(), v[k]["values"].clone());
            }
            let p = dir2.join("v.json");
            std::fs::write(&p, serde_json::Value::Object(m).to_string()).expect("write");
            expected(&p)
        };
        assert_eq!(back, traj, "compressed = {compressed}");
    }
}

#[test]
fn saving_replaces_the_file_atomically_and_leaves_no_partial() {
    let dir = temp_dir("atomic");
    py(WRITE_PY, &[&dir]);
    let traj = expected(&dir.join("values.json"));
    let path = dir.join("x.npz");
    std::fs::write(&path, b"old").expect("old");
    npz::save(&path, &traj, true).expect("save");
    assert_eq!(npz::load(&path).expect("load").trajectory, traj);
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .expect("dir")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty());
    // An invalid trajectory is refused before anything is written.
    let mut bad = traj.clone();
    bad.qpos[2][6] = f64::INFINITY;
    let e = npz::save(&path, &bad, true).expect_err("refused");
    assert!(e.to_string().contains("waypoint 2, joint 7"), "{e}");
    assert_eq!(npz::load(&path).expect("still the old file").trajectory, traj);
}
