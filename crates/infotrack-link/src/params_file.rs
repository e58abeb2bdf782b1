//! Parameter files as field operators have them: QGroundControl `.params` and Mission
//! Planner `.parm` / `.param`; and how a parameter value travels in PARAM_VALUE/PARAM_SET.

use std::path::{Path, PathBuf};

use thiserror::Error;

use super::modes::Flavor;

/// Why a parameter file could not be read.
#[derive(Debug, Error)]
pub enum ParamFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {message}")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// MAV_PARAM_TYPE.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamType {
    /// 1.
    Uint8,
    /// 2.
    Int8,
    /// 3.
    Uint16,
    /// 4.
    Int16,
    /// 5.
    Uint32,
    /// 6.
    Int32,
    /// 9.
    Real32,
}

impl ParamType {
    /// From the MAV_PARAM_TYPE number.
    pub fn from_mav(n: u8) -> Option<Self> {
        Some(match n {
            1 => Self::Uint8,
            2 => Self::Int8,
            3 => Self::Uint16,
            4 => Self::Int16,
            5 => Self::Uint32,
            6 => Self::Int32,
            9 => Self::Real32,
            _ => return None,
        })
    }

    /// The MAV_PARAM_TYPE number.
    pub fn to_mav(self) -> u8 {
        match self {
            Self::Uint8 => 1,
            Self::Int8 => 2,
            Self::Uint16 => 3,
            Self::Int16 => 4,
            Self::Uint32 => 5,
            Self::Int32 => 6,
            Self::Real32 => 9,
        }
    }

    /// Whether the type holds integers.
    pub fn is_integer(self) -> bool {
        self != Self::Real32
    }

    /// Whether `v` fits the type exactly.
    pub fn accepts(self, v: f64) -> bool {
        let int_in = |lo: f64, hi: f64| v.fract() == 0.0 && v >= lo && v <= hi;
        match self {
            // Finite as f64 is not enough: 1e308 or 3.5e38 become infinite as the f32 on the
            // wire.
            Self::Real32 => v.is_finite() && (v as f32).is_finite(),
            Self::Uint8 => int_in(0.0, u8::MAX as f64),
            Self::Int8 => int_in(i8::MIN as f64, i8::MAX as f64),
            Self::Uint16 => int_in(0.0, u16::MAX as f64),
            Self::Int16 => int_in(i16::MIN as f64, i16::MAX as f64),
            Self::Uint32 => int_in(0.0, u32::MAX as f64),
            Self::Int32 => int_in(i32::MIN as f64, i32::MAX as f64),
        }
    }
}

/// The float that carries `value` of type `ty` in PARAM_VALUE / PARAM_SET on `flavor`.
///
/// PX4 encodes bytewise: an integer travels as its raw 4 bytes inside the float field
/// (1 arrives as 1.4e-45). ArduPilot casts: an integer travels as the float of its value.
pub fn encode_wire(flavor: Flavor, ty: ParamType, value: f64) -> f32 {
    match (flavor, ty) {
        (_, ParamType::Real32) | (Flavor::ArduPilot, _) => value as f32,
        (Flavor::Px4, ParamType::Uint32) => f32::from_bits(value as u32),
        (Flavor::Px4, _) => f32::from_bits(value as i32 as u32),
    }
}

/// The value a PARAM_VALUE float of type `ty` carries on `flavor`.
pub fn decode_wire(flavor: Flavor, ty: ParamType, wire: f32) -> f64 {
    match (flavor, ty) {
        (_, ParamType::Real32) | (Flavor::ArduPilot, _) => wire as f64,
        (Flavor::Px4, ParamType::Uint32) => wire.to_bits() as f64,
        (Flavor::Px4, ParamType::Uint8) => (wire.to_bits() & 0xff) as f64,
        (Flavor::Px4, ParamType::Int8) => (wire.to_bits() as u8 as i8) as f64,
        (Flavor::Px4, ParamType::Uint16) => (wire.to_bits() & 0xffff) as f64,
        (Flavor::Px4, ParamType::Int16) => (wire.to_bits() as u16 as i16) as f64,
        (Flavor::Px4, ParamType::Int32) => (wire.to_bits() as i32) as f64,
    }
}

/// One parameter from a file.
#[derive(Debug, Clone, PartialEq)]
pub struct FileParam {
    /// Name (at most 16 characters).
    pub name: String,
    /// Value.
    pub value: f64,
    /// Type, when the file says (QGC files do; Mission Planner files do not).
    pub ty: Option<ParamType>,
    /// Line it came from.
    pub line: usize,
}

/// Which file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamFormat {
    /// QGroundControl `.params`.
    Qgc,
    /// Mission Planner `.parm` / `.param`.
    MissionPlanner,
}

impl ParamFormat {
    /// From the file extension.
    pub fn from_path(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()? {
            "params" => Some(Self::Qgc),
            "parm" | "param" => Some(Self::MissionPlanner),
            _ => None,
        }
    }
}

/// Text from the file as it goes into a message: at most 40 characters (a 1 MB line is not
/// echoed whole).
fn cut(text: &str) -> String {
    const MAX: usize = 40;
    match text.char_indices().nth(MAX) {
        Some((i, _)) => format!("{}... ({} bytes)", &text[..i], text.len()),
        None => text.to_string(),
    }
}

fn check_name(path: &Path, line: usize, name: &str) -> Result<(), ParamFileError> {
    let ok = !name.is_empty()
        && name.len() <= 16
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if ok {
        Ok(())
    } else {
        Err(ParamFileError::Line {
            path: path.to_path_buf(),
            line,
            message: format!(
                "`{}` is not a parameter name (1-16 characters of A-Z, 0-9, _)",
                cut(name)
            ),
        })
    }
}

/// A parameter file longer than this is refused: ArduCopter has ~1,400 parameters, PX4
/// ~1,500, and a file names each once.
pub const MAX_LINES: usize = 20_000;
/// A parameter file larger than this is refused, bytes.
pub const MAX_BYTES: u64 = 2 << 20;

/// Reads a parameter file; the format follows from the extension.
pub fn read(path: &Path) -> Result<Vec<FileParam>, ParamFileError> {
    let text = infotrack_files::read_text(path, MAX_BYTES).map_err(|e| match e {
        infotrack_files::BoundedReadError::Io(source) => ParamFileError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => ParamFileError::Line {
            path: path.to_path_buf(),
            line: 0,
            message: other.to_string(),
        },
    })?;
    let format = ParamFormat::from_path(path).ok_or_else(|| ParamFileError::Line {
        path: path.to_path_buf(),
        line: 0,
        message: "unknown parameter file type (expected .params, .parm or .param)".into(),
    })?;
    parse(&text, format, path)
}

/// Parses parameter-file text; `origin` names the file in errors.
pub fn parse(
    text: &str,
    format: ParamFormat,
    origin: &Path,
) -> Result<Vec<FileParam>, ParamFileError> {
    // Editors on Windows write a byte-order mark and CRLF line ends (`lines` drops the CR).
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut out: Vec<FileParam> = Vec::new();
    // Name -> first line: the duplicate check is a lookup, not a scan of every earlier line.
    let mut seen: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for (i, raw) in text.lines().enumerate() {
        if i >= MAX_LINES {
            return Err(ParamFileError::Line {
                path: origin.to_path_buf(),
                line: i + 1,
                message: format!(
                    "more than {MAX_LINES} lines: no autopilot has that many parameters (the wrong file?)"
                ),
            });
        }
        let line = i + 1;
        let err = |message: String| ParamFileError::Line {
            path: origin.to_path_buf(),
            line,
            message,
        };
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let (name, value, ty) = match format {
            ParamFormat::Qgc => qgc_fields(content, &err)?,
            ParamFormat::MissionPlanner => mission_planner_fields(content, &err)?,
        };
        check_name(origin, line, &name)?;
        let value = checked_value(&name, &value, ty, &err)?;
        if let Some(first) = seen.insert(name.clone(), line) {
            return Err(err(format!("{name} is set again (first on line {first})")));
        }
        out.push(FileParam {
            name,
            value,
            ty,
            line,
        });
    }
    if out.is_empty() {
        return Err(ParamFileError::Line {
            path: origin.to_path_buf(),
            line: 0,
            message: "no parameters in the file (only blank lines and comments): nothing to check or apply".into(),
        });
    }
    Ok(out)
}

/// One line's fields, as parsed: name, value text, type (QGC files give one).
type Fields = (String, String, Option<ParamType>);

/// A QGroundControl line: `vehicle-id component-id NAME VALUE TYPE`, tab-separated.
fn qgc_fields(
    content: &str,
    err: &impl Fn(String) -> ParamFileError,
) -> Result<Fields, ParamFileError> {
    let fields: Vec<&str> = content.split('\t').map(str::trim).collect();
    if fields.len() != 5 {
        return Err(err(format!(
            "expected 5 tab-separated fields `vehicle-id component-id NAME VALUE TYPE`, found {}",
            fields.len()
        )));
    }
    for (k, what) in [(0, "vehicle id"), (1, "component id")] {
        fields[k]
            .parse::<u8>()
            .map_err(|_| err(format!("{what} `{}` is not a number 0-255", cut(fields[k]))))?;
    }
    let ty_n: u8 = fields[4].parse().map_err(|_| {
        err(format!(
            "type `{}` is not a MAV_PARAM_TYPE number",
            cut(fields[4])
        ))
    })?;
    let ty = ParamType::from_mav(ty_n).ok_or_else(|| {
        err(format!(
            "type {ty_n} is not a MAV_PARAM_TYPE this link supports"
        ))
    })?;
    Ok((fields[2].to_string(), fields[3].to_string(), Some(ty)))
}

/// A Mission Planner line: `NAME,VALUE` (or `NAME VALUE`, `NAME=VALUE`).
fn mission_planner_fields(
    content: &str,
    err: &impl Fn(String) -> ParamFileError,
) -> Result<Fields, ParamFileError> {
    let fields: Vec<&str> = content
        .split([',', ' ', '\t', '='])
        .filter(|s| !s.is_empty())
        .collect();
    if fields.len() != 2 {
        return Err(err(format!(
            "expected `NAME,VALUE` (or NAME VALUE, NAME=VALUE), found {} fields",
            fields.len()
        )));
    }
    Ok((fields[0].to_string(), fields[1].to_string(), None))
}

/// The value of `name`: a finite number that fits its type, if the file gives one.
fn checked_value(
    name: &str,
    value: &str,
    ty: Option<ParamType>,
    err: &impl Fn(String) -> ParamFileError,
) -> Result<f64, ParamFileError> {
    let v: f64 = value
        .parse()
        .map_err(|_| err(format!("value `{}` of {name} is not a number", cut(value))))?;
    if !v.is_finite() {
        return Err(err(format!("value of {name} is not finite")));
    }
    if let Some(t) = ty {
        if !t.accepts(v) {
            return Err(err(format!("value {v} of {name} does not fit type {t:?}")));
        }
    }
    Ok(v)
}

/// Renders parameters as a QGroundControl `.params` file.
pub fn render_qgc(params: &[(String, f64, ParamType)], sysid: u8, compid: u8) -> String {
    let mut s = String::from(
        "# Onboard parameters for vehicle\n#\n# Vehicle-Id Component-Id Name Value Type\n",
    );
    for (name, value, ty) in params {
        let v = if ty.is_integer() {
            format!("{}", *value as i64)
        } else {
            format!("{:.9}", value)
        };
        s += &format!("{sysid}\t{compid}\t{name}\t{v}\t{}\n", ty.to_mav());
    }
    s
}

/// Renders parameters as a Mission Planner `.parm` file.
pub fn render_parm(params: &[(String, f64)]) -> String {
    let mut s = String::new();
    for (name, value) in params {
        s += &format!("{name},{value}\n");
    }
    s
}

/// The MAV_PARAM_TYPE of a ParamType.
pub fn mav_param_type_of(t: ParamType) -> mavlink::dialects::ardupilotmega::MavParamType {
    match t {
        ParamType::Uint8 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_UINT8,
        ParamType::Int8 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_INT8,
        ParamType::Uint16 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_UINT16,
        ParamType::Int16 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_INT16,
        ParamType::Uint32 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_UINT32,
        ParamType::Int32 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_INT32,
        ParamType::Real32 => mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_REAL32,
    }
}

/// The ParamType of a MAV_PARAM_TYPE, if the link supports it.
pub fn param_type_of(t: mavlink::dialects::ardupilotmega::MavParamType) -> Option<ParamType> {
    Some(match t {
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_UINT8 => ParamType::Uint8,
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_INT8 => ParamType::Int8,
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_UINT16 => ParamType::Uint16,
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_INT16 => ParamType::Int16,
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_UINT32 => ParamType::Uint32,
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_INT32 => ParamType::Int32,
        mavlink::dialects::ardupilotmega::MavParamType::MAV_PARAM_TYPE_REAL32 => ParamType::Real32,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.params")
    }

    #[test]
    fn qgc_rows_and_comments() {
        let text =
            "# header\n1\t1\tCOM_OF_LOSS_T\t1.000000000\t9\n1\t1\tCOM_OBL_RC_ACT\t5\t6 # hold\n\n";
        let v = parse(text, ParamFormat::Qgc, p()).unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(v[1].name, "COM_OBL_RC_ACT");
        assert_eq!(v[1].value, 5.0);
        assert_eq!(v[1].ty, Some(ParamType::Int32));
        assert_eq!(v[1].line, 3);
    }

    #[test]
    fn malformed_lines_name_file_and_line() {
        for (text, needle) in [
            ("1\t1\tA\t1\n", "expected 5"),
            ("1\t1\tA\tx\t9\n", "not a number"),
            ("1\t1\tA\t1.5\t6\n", "does not fit"),
            ("1\t1\tA\t1\t7\n", "type 7"),
            (
                "1\t1\tTHIS_NAME_IS_TOO_LONG\t1\t9\n",
                "not a parameter name",
            ),
            ("1\t1\tA\t1\t9\n1\t1\tA\t2\t9\n", "set again"),
        ] {
            let e = parse(text, ParamFormat::Qgc, Path::new("f.params"))
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("f.params:"), "{e}");
            assert!(e.contains(needle), "{e}");
        }
        let e = parse(
            "OK,1\nBAD LINE HERE\n",
            ParamFormat::MissionPlanner,
            Path::new("g.parm"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("g.parm:2:"), "{e}");
    }

    /// The fault campaign's parameter-file rows: a BOM and CRLF are read, an empty file is
    /// an error, a 1 MB line is not echoed whole.
    #[test]
    fn bom_crlf_empty_files_and_long_lines() {
        let text = "\u{feff}1\t1\tCOM_OF_LOSS_T\t1.0\t9\r\n1\t1\tNAV_DLL_ACT\t2\t6\r\n";
        let v = parse(text, ParamFormat::Qgc, p()).unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!((v[0].name.as_str(), v[1].value), ("COM_OF_LOSS_T", 2.0));
        let v = parse(
            "\u{feff}WPNAV_SPEED,500\r\n",
            ParamFormat::MissionPlanner,
            p(),
        )
        .unwrap();
        assert_eq!(v[0].name, "WPNAV_SPEED");
        for empty in ["", "# only a comment\n\n", "\u{feff}"] {
            let e = parse(empty, ParamFormat::Qgc, Path::new("e.params"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("e.params") && e.contains("no parameters"), "{e}");
        }
        let long = format!("1\t1\tA\t{}\t9\n", "9x".repeat(500_000));
        let e = parse(&long, ParamFormat::Qgc, p()).unwrap_err().to_string();
        assert!(
            e.contains("not a number") && e.len() < 200,
            "{} bytes",
            e.len()
        );
    }

    #[test]
    fn mission_planner_separators() {
        let text = "# c\nWPNAV_SPEED,500\nFS_GCS_ENABLE 1\nGUID_TIMEOUT\t3\nFENCE_ENABLE=1 # on\n";
        let v = parse(text, ParamFormat::MissionPlanner, Path::new("x.parm")).unwrap();
        let names: Vec<&str> = v.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "WPNAV_SPEED",
                "FS_GCS_ENABLE",
                "GUID_TIMEOUT",
                "FENCE_ENABLE"
            ]
        );
        assert!(v.iter().all(|p| p.ty.is_none()));
    }

    #[test]
    fn render_and_parse_round_trip() {
        let params = vec![
            ("MPC_XY_VEL_MAX".to_string(), 3.5, ParamType::Real32),
            ("COM_OBL_RC_ACT".to_string(), 5.0, ParamType::Int32),
        ];
        let text = render_qgc(&params, 1, 1);
        let back = parse(&text, ParamFormat::Qgc, p()).unwrap();
        assert_eq!(back.len(), 2);
        assert!((back[0].value - 3.5).abs() < 1e-9);
        let parm = render_parm(&[("WPNAV_SPEED".into(), 500.0)]);
        let back = parse(&parm, ParamFormat::MissionPlanner, Path::new("a.parm")).unwrap();
        assert_eq!(back[0].value, 500.0);
    }

    #[test]
    fn px4_bytewise_and_ardupilot_cast_encodings() {
        // PX4: INT32 1 arrives as the float with bits 1 (1.4e-45).
        let w = encode_wire(Flavor::Px4, ParamType::Int32, 1.0);
        assert_eq!(w.to_bits(), 1);
        assert!(w > 0.0 && w < 1e-44);
        assert_eq!(decode_wire(Flavor::Px4, ParamType::Int32, w), 1.0);
        // Sending 4.0 as a plain float to an INT32 would store 1082130432.
        assert_eq!(
            decode_wire(Flavor::Px4, ParamType::Int32, 4.0f32),
            1_082_130_432.0
        );
        assert_eq!(
            decode_wire(
                Flavor::Px4,
                ParamType::Int32,
                encode_wire(Flavor::Px4, ParamType::Int32, -7.0)
            ),
            -7.0
        );
        assert_eq!(encode_wire(Flavor::Px4, ParamType::Real32, 1.5), 1.5);
        // ArduPilot: plain cast.
        assert_eq!(
            encode_wire(Flavor::ArduPilot, ParamType::Int16, 500.0),
            500.0
        );
        assert_eq!(decode_wire(Flavor::ArduPilot, ParamType::Int8, 3.0), 3.0);
    }
}
