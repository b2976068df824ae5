//! Opening the Orbbec camera on a machine without one: it must fail before anything moves, with
//! kind NotFound and a message naming the Orbbec camera (and, for a missing library, its path).

use std::path::PathBuf;

use hitl_drivers::orbbec::{probe, OrbbecCamera, OrbbecOptions};
use hitl_hal::{Error, ErrorKind};

fn sdk_library() -> PathBuf {
    let p = PathBuf::from(env!("HITL_DEPS_LIB")).join("libOrbbecSDK.so");
    assert!(p.exists(), "{} is missing: run make setup", p.display());
    p
}

#[test]
fn no_camera_is_not_found_and_names_the_orbbec_camera() {
    let options = OrbbecOptions { library: sdk_library(), ..OrbbecOptions::default() };
    let Err(e) = OrbbecCamera::open(options) else {
        panic!("this machine has no Orbbec camera: open must fail");
    };
    assert_eq!(e.kind(), ErrorKind::NotFound, "{e}");
    let msg = e.to_string();
    assert!(msg.contains("no Orbbec camera found"), "{msg}");
    assert!(msg.contains("Orbbec SDK 2."), "the message names the SDK version that looked: {msg}");
}

#[test]
fn a_missing_library_is_not_found_and_says_what_is_missing() {
    let options = OrbbecOptions {
        library: PathBuf::from("/nonexistent/hitl/libOrbbecSDK.so"),
        ..OrbbecOptions::default()
    };
    let Err(e) = OrbbecCamera::open(options) else {
        panic!("a missing library must not open");
    };
    assert_eq!(e.kind(), ErrorKind::NotFound, "{e}");
    let msg = e.to_string();
    assert!(msg.contains("Orbbec camera"), "{msg}");
    assert!(msg.contains("/nonexistent/hitl/libOrbbecSDK.so"), "{msg}");
    assert!(msg.contains("make setup"), "{msg}");
}

#[test]
fn a_file_that_is_not_the_sdk_is_not_found_and_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fake = dir.path().join("libOrbbecSDK.so");
    std::fs::write(&fake, b"not an ELF file").expect("write");
    let options = OrbbecOptions { library: fake.clone(), ..OrbbecOptions::default() };
    let Err(e) = OrbbecCamera::open(options) else {
        panic!("a broken library must not open");
    };
    assert_eq!(e.kind(), ErrorKind::NotFound, "{e}");
    assert!(e.to_string().contains("cannot load the Orbbec SDK library"), "{e}");
    assert!(e.to_string().contains(&fake.display().to_string()), "{e}");
}

#[test]
fn probe_with_no_camera_lists_nothing_and_a_missing_library_is_not_found() {
    let cameras = probe(&sdk_library()).expect("the real SDK loads and lists devices");
    assert_eq!(cameras, vec![], "this machine has no Orbbec camera");
    let e = probe(std::path::Path::new("/nonexistent/hitl/libOrbbecSDK.so")).expect_err("missing");
    assert_eq!(e.kind(), ErrorKind::NotFound, "{e}");
    assert!(e.to_string().contains("/nonexistent/hitl/libOrbbecSDK.so"), "{e}");
}
