//! The arm as the run holds it. The controller has one arm driver, the xArm's (its command
//! client and its report reader, `hitl_drivers::xarm`); it is named here, and the session uses
//! these names, so that `src/control` names no driver. A second kind of arm would become an enum
//! or a trait object here, as the camera and the light are.

pub use hitl_drivers::xarm::{ClientConfig, ReportConfig, ReportKind, ServoReplies, COMMAND_PORT};

/// The arm's command side: servo setpoints, enable, stop, identity.
pub type RunArm = hitl_drivers::xarm::XarmClient;

/// The arm's report side, read on a thread of its own.
pub type RunArmReports = hitl_drivers::xarm::ReportReader;
