//! `hitl targets [--json]`: every built-in with its faces, size, symmetry and parts; a named
//! OBJ with its `.symmetry` declaration; an unknown name is exit 2.

mod common;
use common::hitl;

#[test]
fn the_json_lists_the_built_ins_with_faces_size_symmetry_and_parts() {
    let out = hitl(&["targets", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let targets = v["targets"].as_array().expect("targets");
    let names: Vec<&str> = targets.iter().filter_map(|t| t["name"].as_str()).collect();
    assert_eq!(
        names,
        [
            "sat1-none",
            "sat2-one-plane",
            "sat3-two-planes",
            "sat4-two-planes-slender",
            "sat5-two-planes-y",
            "asymmetric",
            "one-plane",
            "two-planes"
        ]
    );
    let detailed: Vec<&serde_json::Value> =
        targets.iter().filter(|t| t["faces"].as_u64().is_some_and(|f| f >= 4000)).collect();
    assert_eq!(detailed.len(), 5, "{v}");
    let classes: Vec<&str> = detailed.iter().filter_map(|t| t["symmetry_class"].as_str()).collect();
    assert_eq!(classes, ["none", "one_plane", "two_planes", "two_planes", "two_planes"]);
    for t in targets {
        assert_eq!(t["builtin"], true);
        assert!((t["greatest_dimension_m"].as_f64().expect("size") - 2.0).abs() < 1e-9, "{t}");
        let parts = t["parts"].as_array().expect("parts");
        let faces: u64 = parts.iter().filter_map(|p| p["faces"].as_u64()).sum();
        assert_eq!(Some(faces), t["faces"].as_u64(), "{t}");
        assert!(parts.iter().all(|p| p["material"]["rgba"].as_array().is_some()), "{t}");
    }
    let sat3 = &targets[2];
    assert_eq!(sat3["symmetry"], "two-planes:z");
    assert_eq!(sat3["symmetry_rotations"], 2);
    assert_eq!(targets[4]["symmetry"], "two-planes:y");
    assert_eq!(targets[1]["symmetry_rotations"], 1);

    let text = hitl(&["targets"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("sat3-two-planes: 55080 faces"), "{text}");
    assert!(text.contains("solar-array"), "{text}");
}

#[test]
fn a_named_file_is_described_with_its_declaration_and_a_bad_name_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let obj = dir.path().join("plate.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 1 1 0.2\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n",
    )
    .expect("write");
    std::fs::write(dir.path().join("plate.obj.symmetry"), "4-fold:z\n").expect("write");
    let out = hitl(&["targets", obj.to_str().expect("utf-8"), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let t = &v["targets"][0];
    assert_eq!(t["name"], "plate");
    assert_eq!(t["builtin"], false);
    assert_eq!(t["faces"], 4);
    assert_eq!(t["symmetry"], "4-fold:z");
    assert_eq!(t["symmetry_rotations"], 4);
    assert_eq!(t["symmetry_class"], "unknown");

    let out = hitl(&["targets", "no-such-target"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("sat1-none"));
}
