//! Without a usable EGL device MuJoCo's renderer does not open and the camera says which
//! package to look at, instead of delivering nothing. EGL is pointed at no vendor library
//! (`__EGL_VENDOR_LIBRARY_FILENAMES`), which makes libglvnd find no device at all. Its own test
//! binary: the variable must be set before EGL first loads in the process.

use hitl_sim_stub::camera::{
    LightLevel, Preset, RendererKind, SimCamera, SimCameraConfig, SimCameraError,
};
use hitl_sim_stub::mujoco_plant::MujocoPlant;
use hitl_trajectories::lab::LabConfig;

#[test]
fn no_egl_device_is_refused_with_the_package_named() {
    std::env::set_var("__EGL_VENDOR_LIBRARY_FILENAMES", "/nonexistent");
    let lab = LabConfig::default();
    let plant = MujocoPlant::new(&lab, None).expect("plant");
    let config = SimCameraConfig {
        intrinsics: Preset::Wfov.at(160, 128),
        renderer: RendererKind::Mujoco,
        ..SimCameraConfig::default()
    };
    let err = SimCamera::new(plant.lab_model(), plant.shared_state(), LightLevel::new(1.0), config)
        .expect_err("no EGL device, no camera");
    let SimCameraError::NoRenderer(msg) = &err else { panic!("{err:?}") };
    assert!(msg.contains("EGL"), "{msg}");
    assert!(
        msg.contains("libegl-mesa0") && msg.contains("__EGL_VENDOR_LIBRARY_FILENAMES"),
        "{msg}"
    );
    assert_eq!(hitl_hal::Error::kind(&err), hitl_hal::ErrorKind::NotFound);
    // The ray cast needs no EGL and still opens.
    let config = SimCameraConfig {
        intrinsics: Preset::Wfov.at(160, 128),
        renderer: RendererKind::RayCast,
        ..SimCameraConfig::default()
    };
    SimCamera::new(plant.lab_model(), plant.shared_state(), LightLevel::new(1.0), config)
        .expect("ray cast camera");
}
