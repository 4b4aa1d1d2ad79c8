//! Numbers and dates as the pages print them.

use super::super::time::parse_utc;

/// 1, 2 or 5 times a power of ten, about a fifth of the span.
pub(super) fn tick_step(span: f64) -> f64 {
    let raw = span / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    p * if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A tick label with as many decimals as the step needs; never "-0".
pub(super) fn tick_label(v: f64, step: f64) -> String {
    let d = (-step.log10().floor()).clamp(0.0, 4.0) as usize;
    let s = format!("{v:.d$}");
    if s.trim_start_matches('-')
        .bytes()
        .all(|c| c == b'0' || c == b'.')
    {
        "0".into()
    } else {
        s
    }
}

/// A value in its unit with a sign, to a resolution that suits it (0.1 µm, 0.1 arcsec).
pub(super) fn signed(v: f64) -> String {
    let s = format!("{v:+.1}");
    if s == "-0.0" || s == "+0.0" {
        "0.0".into()
    } else {
        s
    }
}

pub(super) fn plain(v: f64) -> String {
    format!("{v:.1}")
}

/// A standard uncertainty: two significant figures, at least 0.01 (µm or arcsec).
pub(super) fn plain_u(v: f64) -> String {
    if v >= 10.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// A configured number as typed (5, 2.5).
pub(super) fn num(v: f64) -> String {
    format!("{v}")
}

/// `2026-11-25T08:00:00Z` -> `2026-11-25 08:00`.
pub(super) fn date(stamp: &str) -> String {
    if parse_utc(stamp).is_some() {
        format!("{} {}", &stamp[..10], &stamp[11..16])
    } else {
        stamp.to_string()
    }
}
