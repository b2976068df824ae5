//! `--light` parsing: every accepted form, and errors that say what is wrong.

#![allow(clippy::unwrap_used)]

use hitl_drivers::light::{DmxResolution, LightSpec};

#[test]
fn accepted_forms() {
    assert_eq!("sim".parse::<LightSpec>().unwrap(), LightSpec::Sim);
    assert_eq!("none".parse::<LightSpec>().unwrap(), LightSpec::None);
    assert_eq!(
        "trigger:/dev/ttyACM0".parse::<LightSpec>().unwrap(),
        LightSpec::Trigger { port: "/dev/ttyACM0".into() }
    );
    let LightSpec::Dmx { port, config } = "dmx:/dev/ttyUSB0".parse::<LightSpec>().unwrap() else {
        panic!("dmx");
    };
    assert_eq!(port, "/dev/ttyUSB0");
    assert_eq!((config.start_address, config.resolution), (1, DmxResolution::Bits8));
    let LightSpec::Dmx { config, .. } = "dmx:/dev/ttyUSB1,addr=17,16bit".parse().unwrap() else {
        panic!("dmx with options");
    };
    assert_eq!((config.start_address, config.resolution), (17, DmxResolution::Bits16));
}

#[test]
fn display_round_trips() {
    for s in ["sim", "none", "trigger:/dev/ttyACM0", "dmx:/dev/ttyUSB0", "dmx:COM3,addr=9,16bit"] {
        assert_eq!(s.parse::<LightSpec>().unwrap().to_string(), s);
    }
}

#[test]
fn errors_name_the_problem() {
    let cases = [
        ("", "unknown light"),
        ("laser", "unknown light"),
        ("dmx:", "missing serial device"),
        ("trigger:", "missing serial device"),
        ("hue:bridge", "unknown light kind \"hue\""),
        ("dmx:/dev/ttyUSB0,addr=0", "not in 1..=512"),
        ("dmx:/dev/ttyUSB0,addr=513", "not in 1..=512"),
        ("dmx:/dev/ttyUSB0,addr=x", "not in 1..=512"),
        ("dmx:/dev/ttyUSB0,addr=512,16bit", "does not fit"),
        ("dmx:/dev/ttyUSB0,fast", "unknown DMX option"),
    ];
    for (input, want) in cases {
        let e = input.parse::<LightSpec>().unwrap_err().to_string();
        assert!(e.contains(want), "{input:?}: {e}");
        assert!(e.contains("expected sim, none"), "{input:?}: {e}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn non_serial_lights_open_to_none_and_a_missing_port_is_named() {
    use hitl_drivers::light::TriggerSpec;
    use hitl_hal::{Error, ErrorKind, MonotonicClock};
    let clock = MonotonicClock::new();
    assert!(LightSpec::Sim.open(clock.clone()).await.unwrap().is_none());
    assert!(LightSpec::None.open(clock.clone()).await.unwrap().is_none());
    assert!(TriggerSpec::None.open(clock.clone()).await.unwrap().is_none());
    let spec: LightSpec = "trigger:/dev/hitl-missing-box".parse().unwrap();
    let Err(e) = spec.open(clock.clone()).await else { panic!("missing port opened") };
    assert_eq!(e.kind(), ErrorKind::NotFound);
    let trigger: TriggerSpec = "trigger:/dev/hitl-missing-box".parse().unwrap();
    let Err(e) = trigger.open(clock).await else { panic!("missing port opened") };
    assert_eq!(e.kind(), ErrorKind::NotFound);
    assert!(
        e.to_string().contains("trigger box: cannot open serial port /dev/hitl-missing-box"),
        "{e}"
    );
}
