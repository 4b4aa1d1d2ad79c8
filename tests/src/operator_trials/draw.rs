//! What a generated operator types and does: a [`Case`] of named numbers (genes), each
//! with the nominal value a careful operator would use, and a seeded draw of them over
//! the ranges issue 34 names. Every gene is an `f64` (choices are small whole numbers)
//! so that shrinking and printing work on all of them alike.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

macro_rules! genes {
    ($($name:ident = $nominal:expr, $doc:literal;)*) => {
        /// One generated operator: what the program says and how the machine and the
        /// probe really are.
        #[derive(Clone, Debug)]
        pub struct Case {
            $(#[doc = $doc] pub $name: f64,)*
        }

        impl Case {
            /// Every gene at its nominal value (cycle 451 on table-ac, in the world
            /// machine, the probe centred and ideal).
            pub fn nominal() -> Self {
                Case { $($name: $nominal,)* }
            }

            /// The genes' names, in order.
            pub const NAMES: &'static [&'static str] = &[$(stringify!($name),)*];

            /// Gene `i`, by its place in [`Self::NAMES`].
            pub fn get(&self, i: usize) -> f64 {
                [$(self.$name,)*][i]
            }

            /// Gene `i`, by its place in [`Self::NAMES`].
            pub fn set(&mut self, i: usize, v: f64) {
                let mut k = 0;
                $(if k == i { self.$name = v; return; } k += 1;)*
                let _ = k;
                panic!("no gene {i}");
            }
        }
    };
}

/// Two cases are the same when every gene is (NaN, "not given", equals NaN).
impl PartialEq for Case {
    fn eq(&self, other: &Self) -> bool {
        (0..Self::NAMES.len()).all(|i| {
            let (a, b) = (self.get(i), other.get(i));
            a == b || (a.is_nan() && b.is_nan())
        })
    }
}

genes! {
    machine = 0.0, "0 table-ac, 1 head-b-table-c, 2 horizontal-x-head-b-table-c, 3 horizontal-y-table-ac";
    cycle = 451.0, "451, 460, 431 or 444";
    backend = 0.0, "0 the world machine (no bus), 1 CANopen in-process lockstep, 2 Modbus TCP loopback";
    inch = 0.0, "1: the program is written in inch";
    flow = 0.0, "0 plain, 1 subprogram after M30, 2 subprogram before its call, 3 section repeat, 4 jumps and a loop before the cycle";
    off = 0.0, "start off the sphere centre in the working plane, fraction of the documented reach";
    off_dir = 0.0, "direction of that offset from the main axis, deg";
    rise = 0.0, "start height above SET_UP + Q320 over the pole, fraction of DIST (1 = the documented top)";
    q407_err = 0.0, "Q407 typed = true radius x (1 + q407_err)";
    q408 = 0.0, "Q408 (451), mm";
    q320 = 0.0, "Q320, mm";
    q253 = 750.0, "Q253 (451), mm/min; -1 FMAX, -2 FAUTO, -3 PREDEF";
    q260 = f64::NAN, "Q260 (431, 444) in cycle coordinates; NaN: 20 mm over the highest start";
    mode = 2.0, "Q406 (451)";
    q431 = 1.0, "Q431 (451)";
    preset_err = 0.0, "Q431 = 0/2: the preset row off the sphere centre, fraction of the 451 reach";
    preset_dir = 0.0, "direction of that error in the working plane, deg";
    preset_up = 0.0, "its component along the tool axis, mm";
    rot1 = 0.0, "first rotary (table) axis left at this angle before the cycle, deg";
    rot2 = 0.0, "C left at this angle before the cycle, deg";
    axes = 1.0, "451 measures: 0 the first rotary axis, 1 C, 2 both";
    points = 4.0, "Q423";
    q432 = 0.0, "Q432 backlash range (451), deg";
    q301 = 1.0, "Q301 (460)";
    q455 = 0.0, "Q455 (460): directions per ring of the 3D calibration";
    pretravel = 0.0, "lateral pre-travel, mm";
    axial = f64::NAN, "axial pre-travel, mm; NaN: as the lateral";
    lobing = 0.0, "amplitude of the three lobes, mm (at most the pre-travel)";
    phase = 0.0, "first lobe's azimuth, deg";
    off1 = 0.0, "ball centre off the spindle axis along the main axis, mm";
    off2 = 0.0, "ball centre off the spindle axis along the minor axis, mm";
    len_err = 0.0, "stylus length error, mm";
    stale_r = 0.0, "probe table R minus the effective radius, mm";
    noise = 0.0, "trigger noise, 1 sigma, mm";
    tilt1 = 0.0, "431: the face turned about the main axis, deg";
    tilt2 = 0.0, "431: the face turned about the minor axis, deg";
    h1 = 0.0, "431: point 1's nominal height minus the face's, mm";
    h2 = 0.0, "431: point 2's nominal height minus the face's, mm";
    h3 = 0.0, "431: point 3's nominal height minus the face's, mm";
    az = 0.0, "444: azimuth of the point on the sphere, deg";
    el = 90.0, "444: elevation of the point on the sphere, deg";
    surf = 0.0, "444: the real surface minus the nominal along the normal, mm";
    calibrate = 0.0, "431/444: 1 = cycle 460 with the drawn Q455 first, in the same program";
    seed = 1.0, "the simulator's noise seed";
}

/// The machines drawn, with their scenario and tool axis.
pub const MACHINES: [&str; 4] = [
    "table-ac",
    "head-b-table-c",
    "horizontal-x-head-b-table-c",
    "horizontal-y-table-ac",
];

pub const CYCLES: [u16; 4] = [451, 460, 431, 444];

/// The largest coordinate, height or feed a cycle parameter takes (params.rs).
const COORD: f64 = 99_999.999_9;

/// The bus draws: `share` of the cases in hundredths go over CANopen and as many over
/// Modbus (each a tenth of the world machine's speed or less).
pub struct Shares {
    pub can: f64,
    pub modbus: f64,
}

fn pick<T: Copy>(rng: &mut SmallRng, items: &[T]) -> T {
    items[rng.random_range(0..items.len())]
}

/// `nominal` with probability `p_nominal`, else uniform in `lo..hi`.
fn maybe(rng: &mut SmallRng, p_nominal: f64, nominal: f64, lo: f64, hi: f64) -> f64 {
    if rng.random_bool(p_nominal) {
        nominal
    } else {
        rng.random_range(lo..hi)
    }
}

/// Round to `d` decimals (what an operator types; also keeps printed cases exact).
fn round(v: f64, d: i32) -> f64 {
    let f = 10f64.powi(d);
    (v * f).round() / f
}

/// Draws case `index` of the run seeded `seed` (the same pair always gives the same
/// case, whatever else runs).
pub fn draw(seed: u64, index: u64, shares: &Shares) -> Case {
    let mut rng = SmallRng::seed_from_u64(seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut c = Case::nominal();
    c.cycle = f64::from(pick(&mut rng, &CYCLES));
    c.machine = f64::from(rng.random_range(0u8..4));
    let bus: f64 = rng.random();
    c.backend = if bus < shares.can {
        1.0
    } else if bus < shares.can + shares.modbus {
        2.0
    } else {
        0.0
    };
    // The simulated PLC drives table-ac's axes: Modbus cases run there.
    if c.backend == 2.0 {
        c.machine = 0.0;
    }
    c.inch = f64::from(u8::from(rng.random_bool(0.2)));
    c.flow = maybe(&mut rng, 0.5, 0.0, 1.0, 5.0).floor();
    c.off = round(maybe(&mut rng, 0.2, 0.0, 0.0, 1.5), 3);
    c.off_dir = round(rng.random_range(0.0..360.0), 1);
    // Lower than SET_UP + Q320 over the pole (the docs allow it) a quarter of the time.
    c.rise = round(
        match rng.random_range(0..20) {
            0..=5 => 0.0,
            6..=10 => rng.random_range(-1.0..0.0),
            _ => rng.random_range(0.0..1.5),
        },
        3,
    );
    // Within maxDevCalBall (0.1 mm of 12.5: 0.8 %) as often as up to 30 % off.
    c.q407_err = round(
        match rng.random_range(0..10) {
            0..=5 => 0.0,
            6..=7 => rng.random_range(-0.008..0.008),
            _ => rng.random_range(-0.3..0.3),
        },
        4,
    );
    c.q320 = round(
        match rng.random_range(0..10) {
            0..=4 => 0.0,
            5..=7 => rng.random_range(0.0..5.0),
            8 => rng.random_range(0.0..50.0),
            _ => rng.random_range(0.0..COORD),
        },
        3,
    );
    // The tool axis's end of travel over the sphere centre (Q408 counts from the
    // preset, the sphere centre after Q431 = 1/3), per machine.
    let top = [320.0, 440.0, 360.0, 330.0][c.machine as usize];
    c.q408 = round(
        match rng.random_range(0..20) {
            0..=10 => 0.0,
            11..=14 => rng.random_range(0.0..500.0),
            15..=17 => top + rng.random_range(-15.0..5.0),
            _ => rng.random_range(0.0..COORD),
        },
        3,
    );
    c.q253 = round(
        match rng.random_range(0..20) {
            0..=11 => 750.0,
            12..=13 => rng.random_range(0.0..20_000.0),
            14 => rng.random_range(0.0..COORD),
            15 => -1.0,
            16 => -2.0,
            _ => -3.0,
        },
        1,
    );
    c.q260 = match rng.random_range(0..10) {
        0..=6 => f64::NAN,
        7..=8 => round(rng.random_range(-50.0..200.0), 2),
        _ => round(rng.random_range(-COORD..COORD), 2),
    };
    c.mode = f64::from(pick(&mut rng, &[0u8, 1, 2, 2, 2, 3]));
    c.q431 = f64::from(rng.random_range(0u8..4));
    c.preset_err = round(maybe(&mut rng, 0.3, 0.0, 0.0, 1.5), 3);
    c.preset_dir = round(rng.random_range(0.0..360.0), 1);
    c.preset_up = round(maybe(&mut rng, 0.5, 0.0, -5.0, 5.0), 2);
    c.rot1 = round(maybe(&mut rng, 0.6, 0.0, -90.0, 90.0), 1);
    c.rot2 = round(maybe(&mut rng, 0.6, 0.0, -180.0, 360.0), 1);
    c.axes = f64::from(rng.random_range(0u8..3));
    c.points = f64::from(rng.random_range(3u8..9));
    c.q432 = round(maybe(&mut rng, 0.8, 0.0, -3.0, 3.0), 2);
    c.q301 = f64::from(rng.random_range(0u8..2));
    c.q455 = maybe(&mut rng, 0.5, 0.0, 3.0, 13.0).floor();
    c.pretravel = round(maybe(&mut rng, 0.4, 0.0, 0.0, 0.015), 6);
    c.axial = if rng.random_bool(0.5) {
        f64::NAN
    } else {
        round(rng.random_range(0.0..0.015), 6)
    };
    c.lobing = round(rng.random_range(0.0..=0.005f64.min(c.pretravel)), 6);
    c.phase = round(rng.random_range(0.0..360.0), 1);
    c.off1 = round(maybe(&mut rng, 0.4, 0.0, -0.01, 0.01), 6);
    c.off2 = round(maybe(&mut rng, 0.4, 0.0, -0.01, 0.01), 6);
    c.len_err = round(maybe(&mut rng, 0.4, 0.0, -0.01, 0.01), 6);
    c.stale_r = round(
        match rng.random_range(0..10) {
            0..=4 => 0.0,
            5..=7 => rng.random_range(-0.05..0.05),
            _ => rng.random_range(-2.0..2.0),
        },
        4,
    );
    c.noise = round(maybe(&mut rng, 0.5, 0.0, 0.0, 0.001), 6);
    c.tilt1 = round(maybe(&mut rng, 0.3, 0.0, -15.0, 15.0), 2);
    c.tilt2 = round(maybe(&mut rng, 0.3, 0.0, -15.0, 15.0), 2);
    for h in [&mut c.h1, &mut c.h2, &mut c.h3] {
        *h = round(maybe(&mut rng, 0.5, 0.0, -3.0, 3.0), 3);
    }
    c.az = round(rng.random_range(0.0..360.0), 1);
    c.el = round(maybe(&mut rng, 0.2, 90.0, -30.0, 90.0), 1);
    c.surf = round(maybe(&mut rng, 0.3, 0.0, -3.0, 3.0), 3);
    c.calibrate = f64::from(u8::from(rng.random_bool(0.25)));
    c.seed = f64::from(rng.random_range(1u32..100_000));
    c
}
