//! The mock's parameter table: the flavour's defaults for what a tracking companion and the
//! mock's own behaviour read, with the types and units the real firmware uses.

use infotrack_link::modes::Flavor;
use infotrack_link::params_file::ParamType;

/// One parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Name.
    pub name: String,
    /// Value (in the firmware's own units).
    pub value: f64,
    /// Type.
    pub ty: ParamType,
}

/// An ordered table; the index of a parameter is its position.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamTable {
    params: Vec<Param>,
}

fn p(name: &str, value: f64, ty: ParamType) -> Param {
    Param {
        name: name.to_string(),
        value,
        ty,
    }
}

impl ParamTable {
    /// The flavour's defaults.
    pub fn defaults(flavor: Flavor) -> Self {
        use ParamType::*;
        let params = match flavor {
            Flavor::Px4 => vec![
                p("_HASH_CHECK", 0.0, Int32),
                p("COM_OF_LOSS_T", 1.0, Real32),
                p("COM_OBL_RC_ACT", 0.0, Int32),
                p("COM_RCL_EXCEPT", 0.0, Int32),
                p("COM_DL_LOSS_T", 10.0, Int32),
                p("NAV_DLL_ACT", 0.0, Int32),
                p("MPC_XY_VEL_MAX", 12.0, Real32),
                p("MPC_XY_CRUISE", 5.0, Real32),
                p("MPC_ACC_HOR", 3.0, Real32),
                p("MPC_ACC_HOR_MAX", 5.0, Real32),
                p("MPC_Z_VEL_MAX_UP", 3.0, Real32),
                p("MPC_Z_VEL_MAX_DN", 1.5, Real32),
                p("MPC_TKO_SPEED", 1.5, Real32),
                p("MPC_TILTMAX_AIR", 45.0, Real32),
                p("MPC_YAWRAUTO_MAX", 45.0, Real32),
                p("MIS_TAKEOFF_ALT", 2.5, Real32),
                p("GF_ACTION", 1.0, Int32),
                p("GF_MAX_HOR_DIST", 0.0, Real32),
                p("GF_MAX_VER_DIST", 0.0, Real32),
                p("MAV_1_CONFIG", 0.0, Int32),
                p("MAV_1_MODE", 0.0, Int32),
                p("MAV_1_RATE", 0.0, Int32),
                p("SER_TEL2_BAUD", 57600.0, Int32),
            ],
            Flavor::ArduPilot => vec![
                p("FORMAT_VERSION", 120.0, Int16),
                p("WPNAV_SPEED", 1000.0, Real32),
                p("WPNAV_ACCEL", 250.0, Real32),
                p("WPNAV_SPEED_UP", 250.0, Real32),
                p("WPNAV_SPEED_DN", 150.0, Real32),
                p("ANGLE_MAX", 3000.0, Int16),
                p("ATC_SLEW_YAW", 6000.0, Real32),
                p("PILOT_SPEED_UP", 250.0, Int16),
                p("GUID_TIMEOUT", 3.0, Real32),
                p("FS_GCS_ENABLE", 0.0, Int8),
                p("FS_GCS_TIMEOUT", 5.0, Real32),
                p("MAV_GCS_SYSID", 255.0, Int16),
                p("FENCE_ENABLE", 0.0, Int8),
                p("FENCE_TYPE", 7.0, Int8),
                p("FENCE_ACTION", 1.0, Int8),
                p("FENCE_RADIUS", 300.0, Real32),
                p("FENCE_ALT_MAX", 100.0, Real32),
                p("RTL_ALT", 1500.0, Int32),
                p("LAND_SPEED", 50.0, Int16),
                p("SERIAL2_PROTOCOL", 2.0, Int8),
                p("SERIAL2_BAUD", 57.0, Int32),
                p("SR2_POSITION", 0.0, Int16),
                p("ARMING_CHECK", 1.0, Int32),
            ],
        };
        Self { params }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// Whether empty.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// By index.
    pub fn by_index(&self, i: usize) -> Option<&Param> {
        self.params.get(i)
    }

    /// Index and entry by name.
    pub fn by_name(&self, name: &str) -> Option<(usize, &Param)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }

    /// Value by name, or `default` if absent.
    pub fn get(&self, name: &str, default: f64) -> f64 {
        self.by_name(name).map(|(_, p)| p.value).unwrap_or(default)
    }

    /// Sets an existing parameter; false if there is none by that name or the value does not
    /// fit its type.
    pub fn set(&mut self, name: &str, value: f64) -> bool {
        match self.params.iter_mut().find(|p| p.name == name) {
            Some(p) if p.ty.accepts(value) => {
                p.value = value;
                true
            }
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_hold_the_documented_values() {
        let px4 = ParamTable::defaults(Flavor::Px4);
        assert_eq!(px4.by_index(0).unwrap().name, "_HASH_CHECK");
        assert_eq!(px4.get("COM_OF_LOSS_T", -1.0), 1.0);
        assert_eq!(px4.get("MPC_XY_VEL_MAX", -1.0), 12.0);
        let ap = ParamTable::defaults(Flavor::ArduPilot);
        assert_eq!(ap.get("WPNAV_SPEED", -1.0), 1000.0);
        assert_eq!(ap.get("MAV_GCS_SYSID", -1.0), 255.0);
    }

    #[test]
    fn set_checks_name_and_type() {
        let mut t = ParamTable::defaults(Flavor::ArduPilot);
        assert!(t.set("FS_GCS_ENABLE", 1.0));
        assert!(!t.set("FS_GCS_ENABLE", 1.5));
        assert!(!t.set("NO_SUCH_PARAM", 1.0));
        assert_eq!(t.get("FS_GCS_ENABLE", -1.0), 1.0);
    }
}
