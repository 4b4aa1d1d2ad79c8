//! Parameter tables of the measuring cycles: every Q parameter a cycle takes, its
//! input range as the seeds give it, which keywords it accepts and its default.
//!
//! Defaults (for parameters a program may leave out) are the values of the seeds'
//! example blocks, or the neutral value ("no clearance", "no protocol", "never stop");
//! coordinates, normals, safe heights and modes have no default: guessing them could
//! drive the probe into the part.

use std::fmt;

/// What a number means, for the inch conversion (results are always mm).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// mm (inch programs: inch, times 25.4).
    Length,
    /// mm/min (inch programs: 1/10 inch/min as the TNC programs feeds, times 2.54).
    Feed,
    /// Degrees.
    Angle,
    /// Dimensionless: modes, counts, normal vector components.
    None,
}

impl Unit {
    /// Factor from the program's inch value to mm.
    pub fn inch_factor(self) -> f64 {
        match self {
            Unit::Length => 25.4,
            Unit::Feed => 2.54,
            Unit::Angle | Unit::None => 1.0,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A number in `min..=max`; `integer` ones take whole numbers only (modes, counts).
    Number {
        min: f64,
        max: f64,
        integer: bool,
        unit: Unit,
    },
    /// A `QS` string of at most `max_len` characters.
    Text { max_len: usize },
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Default {
    /// The program must give it.
    Required,
    Number(f64),
    Text(&'static str),
}

/// Keywords a number parameter may take instead of a value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, std::default::Default)]
pub struct Keywords {
    pub predef: bool,
    pub fmax: bool,
    pub fauto: bool,
}

const NONE: Keywords = Keywords {
    predef: false,
    fmax: false,
    fauto: false,
};
const PREDEF: Keywords = Keywords {
    predef: true,
    fmax: false,
    fauto: false,
};
const FEED_KEYWORDS: Keywords = Keywords {
    predef: true,
    fmax: true,
    fauto: true,
};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpec {
    /// "Q263" or "QS400".
    pub name: &'static str,
    /// English dialog text (the comment TNC writes after the value).
    pub title: &'static str,
    pub kind: Kind,
    pub keywords: Keywords,
    pub default: Default,
}

impl ParamSpec {
    /// The allowed input as a message fragment: `-99999.9999..99999.9999 or PREDEF`.
    pub fn allowed(&self) -> String {
        match self.kind {
            Kind::Text { max_len } => format!("a string of at most {max_len} characters"),
            Kind::Number {
                min, max, integer, ..
            } => {
                let mut s = format!("{min}..{max}");
                if integer {
                    s.push_str(" (whole numbers)");
                }
                let k = self.keywords;
                let words: Vec<&str> = [(k.predef, "PREDEF"), (k.fmax, "FMAX"), (k.fauto, "FAUTO")]
                    .into_iter()
                    .filter_map(|(on, w)| on.then_some(w))
                    .collect();
                if !words.is_empty() {
                    s.push_str(" or ");
                    s.push_str(&words.join(", "));
                }
                s
            }
        }
    }

    pub fn is_required(&self) -> bool {
        matches!(self.default, Default::Required)
    }
}

/// All parameters of one cycle, in the order the TNC writes them.
#[derive(Debug)]
pub struct CycleTable {
    pub number: u16,
    pub name: &'static str,
    pub params: &'static [ParamSpec],
}

impl CycleTable {
    pub fn param(&self, name: &str) -> Option<&'static ParamSpec> {
        self.params.iter().find(|p| p.name == name)
    }

    pub fn names(&self) -> Vec<&'static str> {
        self.params.iter().map(|p| p.name).collect()
    }
}

impl fmt::Display for CycleTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cycle {} {}", self.number, self.name)
    }
}

const COORD: f64 = 99999.9999;

const fn coord(name: &'static str, title: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        title,
        kind: Kind::Number {
            min: -COORD,
            max: COORD,
            integer: false,
            unit: Unit::Length,
        },
        keywords: NONE,
        default: Default::Required,
    }
}

const fn num(
    name: &'static str,
    title: &'static str,
    (min, max): (f64, f64),
    unit: Unit,
    keywords: Keywords,
    default: Default,
) -> ParamSpec {
    ParamSpec {
        name,
        title,
        kind: Kind::Number {
            min,
            max,
            integer: false,
            unit,
        },
        keywords,
        default,
    }
}

const fn int(
    name: &'static str,
    title: &'static str,
    (min, max): (f64, f64),
    default: Default,
) -> ParamSpec {
    ParamSpec {
        name,
        title,
        kind: Kind::Number {
            min,
            max,
            integer: true,
            unit: Unit::None,
        },
        keywords: NONE,
        default,
    }
}

const SETUP_CLEARANCE: ParamSpec = num(
    "Q320",
    "SET-UP CLEARANCE",
    (0.0, COORD),
    Unit::Length,
    PREDEF,
    Default::Number(0.0),
);
const CLEARANCE_HEIGHT: ParamSpec = num(
    "Q260",
    "CLEARANCE HEIGHT",
    (-COORD, COORD),
    Unit::Length,
    PREDEF,
    Default::Required,
);

pub static CYCLE_431: CycleTable = CycleTable {
    number: 431,
    name: "MEASURE PLANE",
    params: &[
        coord("Q263", "1ST POINT 1ST AXIS"),
        coord("Q264", "1ST POINT 2ND AXIS"),
        coord("Q294", "1ST POINT 3RD AXIS"),
        coord("Q265", "2ND POINT 1ST AXIS"),
        coord("Q266", "2ND POINT 2ND AXIS"),
        coord("Q295", "2ND POINT 3RD AXIS"),
        coord("Q296", "3RD POINT 1ST AXIS"),
        coord("Q297", "3RD POINT 2ND AXIS"),
        coord("Q298", "3RD POINT 3RD AXIS"),
        SETUP_CLEARANCE,
        CLEARANCE_HEIGHT,
        int("Q281", "MEASURING LOG", (0.0, 2.0), Default::Number(0.0)),
    ],
};

const fn normal(name: &'static str, title: &'static str) -> ParamSpec {
    num(
        name,
        title,
        (-10.0, 10.0),
        Unit::None,
        NONE,
        Default::Required,
    )
}

pub static CYCLE_444: CycleTable = CycleTable {
    number: 444,
    name: "PROBING 3D",
    params: &[
        coord("Q263", "1ST POINT 1ST AXIS"),
        coord("Q264", "1ST POINT 2ND AXIS"),
        coord("Q294", "1ST POINT 3RD AXIS"),
        normal("Q581", "SURFACE NORMAL MAIN AXIS"),
        normal("Q582", "SURFACE NORMAL MINOR AXIS"),
        normal("Q583", "SURFACE NORMAL TOOL AXIS"),
        SETUP_CLEARANCE,
        CLEARANCE_HEIGHT,
        ParamSpec {
            name: "QS400",
            title: "TOLERANCE",
            kind: Kind::Text { max_len: 255 },
            keywords: NONE,
            // No tolerance: Q183 = -1.
            default: Default::Text(" "),
        },
        int("Q309", "ERROR REACTION", (0.0, 2.0), Default::Number(0.0)),
    ],
};

const ANGLE: f64 = 359.9999;

const fn angle(name: &'static str, title: &'static str, range: (f64, f64)) -> ParamSpec {
    num(name, title, range, Unit::Angle, NONE, Default::Number(0.0))
}

pub static CYCLE_451: CycleTable = CycleTable {
    number: 451,
    name: "MEASURE KINEMATICS",
    params: &[
        int("Q406", "MODE", (0.0, 3.0), Default::Required),
        num(
            "Q407",
            "SPHERE RADIUS",
            (0.0001, 99.9999),
            Unit::Length,
            NONE,
            Default::Required,
        ),
        SETUP_CLEARANCE,
        num(
            "Q408",
            "RETR. HEIGHT",
            (0.0, COORD),
            Unit::Length,
            NONE,
            Default::Number(0.0),
        ),
        num(
            "Q253",
            "F PRE-POSITIONING",
            (0.0, COORD),
            Unit::Feed,
            FEED_KEYWORDS,
            Default::Number(750.0),
        ),
        angle("Q380", "REFERENCE ANGLE", (0.0, 360.0)),
        angle("Q411", "START ANGLE A AXIS", (-ANGLE, ANGLE)),
        angle("Q412", "END ANGLE A AXIS", (-ANGLE, ANGLE)),
        angle("Q413", "INCID. ANGLE A AXIS", (-ANGLE, ANGLE)),
        int(
            "Q414",
            "MEAS. POINTS A AXIS",
            (0.0, 12.0),
            Default::Number(0.0),
        ),
        angle("Q415", "START ANGLE B AXIS", (-ANGLE, ANGLE)),
        angle("Q416", "END ANGLE B AXIS", (-ANGLE, ANGLE)),
        angle("Q417", "INCID. ANGLE B AXIS", (-359.999, 360.0)),
        int(
            "Q418",
            "MEAS. POINTS B AXIS",
            (0.0, 12.0),
            Default::Number(0.0),
        ),
        angle("Q419", "START ANGLE C AXIS", (-ANGLE, ANGLE)),
        angle("Q420", "END ANGLE C AXIS", (-ANGLE, ANGLE)),
        angle("Q421", "INCID. ANGLE C AXIS", (-ANGLE, ANGLE)),
        int(
            "Q422",
            "MEAS. POINTS C AXIS",
            (0.0, 12.0),
            Default::Number(0.0),
        ),
        int(
            "Q423",
            "NO. OF PROBE POINTS",
            (3.0, 8.0),
            Default::Number(4.0),
        ),
        int("Q431", "PRESET", (0.0, 3.0), Default::Number(0.0)),
        angle("Q432", "BACKLASH, ANG. RANGE", (-3.0, 3.0)),
    ],
};

pub static CYCLE_450: CycleTable = CycleTable {
    number: 450,
    name: "SAVE KINEMATICS",
    params: &[
        int("Q410", "MODE", (0.0, 3.0), Default::Required),
        int(
            "Q409",
            "MEMORY DESIGNATION",
            (0.0, 99_999_999.0),
            Default::Required,
        ),
    ],
};

/// Most directions per ring of cycle 460's 3D calibration.
pub const MAX_POINTS_3D: f64 = 30.0;

pub static CYCLE_460: CycleTable = CycleTable {
    number: 460,
    name: "CALIBRATION OF TS ON A SPHERE",
    params: &[
        num(
            "Q407",
            "RADIUS OF CALIB. SPHERE",
            (0.0001, 99.9999),
            Unit::Length,
            NONE,
            Default::Required,
        ),
        SETUP_CLEARANCE,
        ParamSpec {
            name: "Q301",
            title: "MOVE TO CLEARANCE",
            kind: Kind::Number {
                min: 0.0,
                max: 1.0,
                integer: true,
                unit: Unit::None,
            },
            keywords: PREDEF,
            default: Default::Number(1.0),
        },
        int(
            "Q423",
            "NO. OF PROBE POINTS",
            (3.0, 8.0),
            Default::Number(8.0),
        ),
        angle("Q380", "REFERENCE ANGLE", (0.0, 360.0)),
        int("Q433", "CALIBRATE LENGTH", (0.0, 1.0), Default::Number(0.0)),
        num(
            "Q434",
            "DATUM FOR LENGTH",
            (-COORD, COORD),
            Unit::Length,
            NONE,
            Default::Number(0.0),
        ),
        int(
            "Q455",
            "NO. OF POINTS IN 3D CAL.",
            (0.0, MAX_POINTS_3D),
            Default::Number(0.0),
        ),
    ],
};

/// Cycles this crate knows, by number.
pub static TABLES: [&CycleTable; 5] = [&CYCLE_431, &CYCLE_444, &CYCLE_450, &CYCLE_451, &CYCLE_460];

pub fn table(cycle: u16) -> Option<&'static CycleTable> {
    TABLES.iter().copied().find(|t| t.number == cycle)
}

/// The parameter a cycle takes as `PREDEF` under `name` ("Q320"), from any table.
pub fn predef_spec(name: &str) -> Option<&'static ParamSpec> {
    TABLES
        .iter()
        .flat_map(|t| t.params.iter())
        .find(|p| p.name == name && p.keywords.predef)
}

/// Every parameter some cycle takes as `PREDEF`, sorted, for messages.
pub fn predef_names() -> Vec<&'static str> {
    let mut names: Vec<&str> = TABLES
        .iter()
        .flat_map(|t| t.params.iter())
        .filter(|p| p.keywords.predef)
        .map(|p| p.name)
        .collect();
    names.sort_unstable();
    names.dedup();
    names
}

/// "431, 444, 450, 451, 460" for messages.
pub fn known_cycles() -> String {
    TABLES
        .iter()
        .map(|t| t.number.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}
