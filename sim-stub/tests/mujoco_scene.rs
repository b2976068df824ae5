//! Scenes the stub refuses or accepts: a user MJCF must name the arm's joints and actuators, bad
//! files and bad target meshes give errors that say what is wrong, and the plant can move to the
//! server's thread.

use hitl_sim_stub::mjcf::{lab_mjcf, TargetModel};
use hitl_sim_stub::mujoco_plant::{LabModel, MujocoPlant, StubSceneError};
use hitl_sim_stub::plant::Plant;
use hitl_trajectories::lab::LabConfig;
use std::path::PathBuf;

fn write(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hitl-h5-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write scene");
    path
}

fn generated() -> String {
    let lab = LabConfig::default();
    lab_mjcf(&lab, &TargetModel::for_lab(&lab)).expect("mjcf")
}

#[test]
fn a_user_scene_with_the_arm_names_is_used() {
    // The generated lab with the target moved: the plant must run the file, not the generated one.
    let xml = generated();
    let key = "<body name=\"target\" pos=\"";
    let at = xml.find(key).expect("target body") + key.len();
    let close = at + xml[at..].find('"').expect("quote");
    let xml = format!("{}1.5 0.3 0.7{}", &xml[..at], &xml[close..]);
    let path = write("ok.xml", &xml);
    let mut plant = MujocoPlant::new(&LabConfig::default(), Some(&path)).expect("user scene");
    plant.reset(&[0.0, -0.3, 0.0, 1.0, 0.0, 1.3, 0.0]);
    plant.advance(0.1);
    assert!((plant.time() - 0.1).abs() < 1e-9);
    let model = plant.lab_model();
    let target = model.target_body.expect("target body");
    assert_eq!(model.model.body_pos()[target], [1.5, 0.3, 0.7]);
}

#[test]
fn a_user_scene_without_an_actuator_is_refused_by_name() {
    let xml = generated();
    let start = xml.find("<position name=\"act3\"").expect("act3");
    let end = start + xml[start..].find("/>").expect("end") + 2;
    let path = write("no-act3.xml", &format!("{}{}", &xml[..start], &xml[end..]));
    let err = MujocoPlant::new(&LabConfig::default(), Some(&path)).expect_err("refused");
    assert!(matches!(err, StubSceneError::Missing { kind: "actuator", .. }), "{err}");
    assert!(err.to_string().contains("act3"), "{err}");
}

#[test]
fn an_actuator_on_the_wrong_joint_is_refused() {
    let xml = generated().replace(
        "<position name=\"act2\" joint=\"joint2\"",
        "<position name=\"act2\" joint=\"joint5\"",
    );
    let err = LabModel::from_xml(&xml, "swapped").expect_err("refused");
    assert!(err.to_string().contains("act2") && err.to_string().contains("joint2"), "{err}");
}

#[test]
fn unreadable_and_invalid_files_say_so() {
    let missing = std::env::temp_dir().join("hitl-h5-no-such-scene.xml");
    let err = MujocoPlant::new(&LabConfig::default(), Some(&missing)).expect_err("missing");
    assert!(matches!(err, StubSceneError::Read { .. }), "{err}");
    let path = write("garbage.xml", "<mujoco><worldbody><geom type=\"nonsense\"/></worldbody>");
    let err = MujocoPlant::new(&LabConfig::default(), Some(&path)).expect_err("garbage");
    assert!(matches!(err, StubSceneError::Compile { .. }), "{err}");
    let path = write("empty.xml", "<mujoco/>");
    let err = MujocoPlant::new(&LabConfig::default(), Some(&path)).expect_err("no arm");
    assert!(err.to_string().contains("joint1"), "{err}");
}

#[test]
fn bad_target_meshes_are_refused() {
    let lab = LabConfig::default();
    let cube: Vec<[f32; 3]> =
        (0..8).map(|i| [(i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32]).collect();
    let tris = vec![[0, 1, 2], [1, 3, 2], [4, 6, 5], [5, 6, 7]];
    let bad_index = TargetModel {
        mesh: Some((cube.clone(), vec![[0, 1, 8]; 4])),
        greatest_dimension_m: 0.1,
        parts: Vec::new(),
    };
    let e = lab_mjcf(&lab, &bad_index).expect_err("index");
    assert!(e.to_string().contains("indexes past"), "{e}");
    let mut nan = cube.clone();
    nan[3][1] = f32::NAN;
    let e = lab_mjcf(
        &lab,
        &TargetModel {
            mesh: Some((nan, tris.clone())),
            greatest_dimension_m: 0.1,
            parts: Vec::new(),
        },
    )
    .expect_err("nan");
    assert!(e.to_string().contains("finite"), "{e}");
    let e =
        lab_mjcf(&lab, &TargetModel { mesh: None, greatest_dimension_m: 0.0, parts: Vec::new() })
            .expect_err("size");
    assert!(e.to_string().contains("greatest_dimension_m"), "{e}");
    // A good mesh is scaled to the greatest dimension: a 1 m cube becomes 0.1 m.
    let xml = lab_mjcf(
        &lab,
        &TargetModel { mesh: Some((cube, tris)), greatest_dimension_m: 0.1, parts: Vec::new() },
    )
    .expect("cube");
    assert!(xml.contains("vertex=\"-5e-2 -5e-2 -5e-2"), "{}", &xml[..400.min(xml.len())]);
}

#[test]
fn the_plant_can_move_to_the_server_thread() {
    fn assert_send<T: Send + 'static>(_: &T) {}
    let plant = MujocoPlant::new(&LabConfig::default(), None).expect("plant");
    assert_send(&plant);
    let handle = std::thread::spawn(move || {
        let mut p: Box<dyn Plant> = Box::new(plant);
        p.advance(0.02);
        p.time()
    });
    assert!((handle.join().expect("thread") - 0.02).abs() < 1e-9);
}

#[test]
fn a_blown_up_simulation_keeps_its_clock_and_says_so() {
    let mut plant = MujocoPlant::new(&LabConfig::default(), None).expect("plant");
    plant.advance(0.1);
    assert!(!plant.diverged());
    // Garbage commands are ignored: the targets stay.
    plant.command(&[1e12; 7]);
    plant.command(&[f64::NAN; 7]);
    plant.advance(0.01);
    assert!(!plant.diverged() && plant.joints().iter().all(|q| q.abs() < 1e-3));
    // A scene MuJoCo cannot integrate: stiff servos on a 0.5 s timestep, given a step.
    let xml = generated();
    let at = xml.find("timestep=\"").expect("timestep") + "timestep=\"".len();
    let close = at + xml[at..].find('"').expect("quote");
    let path = write("unstable.xml", &format!("{}0.5{}", &xml[..at], &xml[close..]));
    let mut plant = MujocoPlant::new(&LabConfig::default(), Some(&path)).expect("scene");
    plant.advance(0.1);
    plant.command(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]);
    for _ in 0..20 {
        plant.advance(0.5);
    }
    assert!(plant.diverged(), "MuJoCo should have reset the absurd state");
    let t = plant.time();
    assert!(t >= 10.1 - 0.5, "time went back to {t}");
    plant.advance(0.5);
    assert!(plant.time() > t, "{}", plant.time());
    plant.reset(&[0.0; 7]);
    assert!(!plant.diverged());
}
