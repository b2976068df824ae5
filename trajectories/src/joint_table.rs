//! Which joint-limit table an xArm7 enforces, and how to tell from its serial number.
//!
//! UFACTORY ships two xArm7 tables (the official SDK's `x_config`): the first arms' (`X4`) and the
//! tighter one of current arms (`X4_1305`), chosen by the SDK from digits [2:6] of the serial
//! number (1305 to 8499 inclusive: current). Offline the lab configuration names the table; the
//! default is the current one, the tighter and so the safe choice. On connect the controller
//! reads the arm's serial number and checks the trajectory against that arm's own table.

use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

use crate::kinematics::DOF;

/// One xArm7 joint-limit table.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
pub enum JointTable {
    /// Serial digits [2:6] from 1305 to 8499: J2 and J4 tighter than the first arms.
    #[default]
    #[serde(rename = "xarm7-current")]
    Xarm7Current,
    /// The first xArm7s (any other serial number).
    #[serde(rename = "xarm7-legacy")]
    Xarm7Legacy,
}

/// Both tables, current first.
pub const ALL: [JointTable; 2] = [JointTable::Xarm7Current, JointTable::Xarm7Legacy];

const LEGACY: [(f64, f64); DOF] = [
    (-2.0 * PI, 2.0 * PI),
    (-2.059488, 2.094395),
    (-2.0 * PI, 2.0 * PI),
    (-0.191986, 3.92699),
    (-2.0 * PI, 2.0 * PI),
    (-1.692969, PI),
    (-2.0 * PI, 2.0 * PI),
];

const CURRENT: [(f64, f64); DOF] = [
    (-2.0 * PI, 2.0 * PI),
    (-2.042035, 2.024581),
    (-2.0 * PI, 2.0 * PI),
    (-0.10472, 3.92699),
    (-2.0 * PI, 2.0 * PI),
    (-1.692969, PI),
    (-2.0 * PI, 2.0 * PI),
];

impl JointTable {
    /// The table an arm with this serial number enforces, as the official SDK picks it: digits
    /// [2:6] read as a number in 1305..=8499 mean the current table; anything else (including a
    /// serial number too short or not numeric there) the legacy one.
    pub fn for_serial(serial: &str) -> JointTable {
        let digits = serial.get(2..6).and_then(|d| d.parse::<u32>().ok());
        match digits {
            Some(n) if (1305..=8499).contains(&n) => JointTable::Xarm7Current,
            _ => JointTable::Xarm7Legacy,
        }
    }

    /// (lower, upper) in radians, joint 1 first.
    pub const fn limits(self) -> [(f64, f64); DOF] {
        match self {
            JointTable::Xarm7Current => CURRENT,
            JointTable::Xarm7Legacy => LEGACY,
        }
    }

    /// The tighter of two tables: what an arm enforcing `other` allows and the lab's `self` too.
    /// The current table lies inside the legacy one on every joint (tested), so the tighter one
    /// is their intersection.
    pub fn tighter(self, other: JointTable) -> JointTable {
        if self == JointTable::Xarm7Current || other == JointTable::Xarm7Current {
            JointTable::Xarm7Current
        } else {
            JointTable::Xarm7Legacy
        }
    }

    /// The name used in lab configurations and messages.
    pub fn name(self) -> &'static str {
        match self {
            JointTable::Xarm7Current => "xarm7-current",
            JointTable::Xarm7Legacy => "xarm7-legacy",
        }
    }
}

impl fmt::Display for JointTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a table name was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("joint table {0:?}: expected xarm7-current or xarm7-legacy")]
pub struct UnknownTable(pub String);

impl FromStr for JointTable {
    type Err = UnknownTable;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ALL.into_iter().find(|t| t.name() == s).ok_or_else(|| UnknownTable(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serial_digits_pick_the_table() {
        assert_eq!(JointTable::for_serial("XI1305000000"), JointTable::Xarm7Current);
        assert_eq!(JointTable::for_serial("XI8499000000"), JointTable::Xarm7Current);
        assert_eq!(JointTable::for_serial("XI1304000000"), JointTable::Xarm7Legacy);
        assert_eq!(JointTable::for_serial("XI8500000000"), JointTable::Xarm7Legacy);
        assert_eq!(JointTable::for_serial("XI12"), JointTable::Xarm7Legacy);
        assert_eq!(JointTable::for_serial(""), JointTable::Xarm7Legacy);
        assert_eq!(JointTable::for_serial("XIab05000000"), JointTable::Xarm7Legacy);
    }

    #[test]
    fn the_current_table_is_inside_the_legacy_one() {
        for (c, l) in JointTable::Xarm7Current.limits().iter().zip(JointTable::Xarm7Legacy.limits())
        {
            assert!(c.0 >= l.0 && c.1 <= l.1, "{c:?} not inside {l:?}");
        }
        assert_eq!(JointTable::Xarm7Current.limits()[3].0, -0.10472);
    }

    #[test]
    fn the_tighter_table_is_the_current_one_whenever_either_is() {
        use JointTable::*;
        assert_eq!(Xarm7Legacy.tighter(Xarm7Legacy), Xarm7Legacy);
        assert_eq!(Xarm7Legacy.tighter(Xarm7Current), Xarm7Current);
        assert_eq!(Xarm7Current.tighter(Xarm7Legacy), Xarm7Current);
        assert_eq!(Xarm7Current.tighter(Xarm7Current), Xarm7Current);
    }

    #[test]
    fn the_tables_are_the_sdks() {
        // x_config.py, XARM7_X4 and XARM7_X4_1305: J2 and J4 differ, J6 is shared.
        let (c, l) = (JointTable::Xarm7Current.limits(), JointTable::Xarm7Legacy.limits());
        assert_eq!((c[1], c[3]), ((-2.042035, 2.024581), (-0.10472, 3.92699)));
        assert_eq!((l[1], l[3]), ((-2.059488, 2.094395), (-0.191986, 3.92699)));
        assert_eq!((c[5], l[5]), ((-1.692969, PI), (-1.692969, PI)));
    }

    #[test]
    fn names_round_trip() {
        for t in ALL {
            assert_eq!(t.name().parse::<JointTable>(), Ok(t));
        }
        assert!("xarm7".parse::<JointTable>().is_err());
    }
}
