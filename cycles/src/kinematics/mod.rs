//! Cycle 451's kinematics: the control's model of the machine ([`model`]), the
//! measuring positions ([`positions`]), the ISO 230-7 identification
//! ([`identification`]), the estimator it runs in ([`estimator`]) and the QS result
//! format ([`qs_string`]).

pub mod codec;
pub mod error_uncertainty;
pub mod estimator;
pub mod identification;
pub mod model;
pub mod positions;

pub use estimator::{Estimator, EstimatorError, LocalEstimator};
pub use identification::{
    identify, AxisMeasurement, IdentificationError, IdentificationInput, IdentificationResult,
    MeasuredPosition, Mode,
};
pub use model::{ChainSpec, ErrorPart, ErrorSet, KinematicModel};

/// Width of one QS144..QS146 field.
pub const QS_FIELD: usize = 10;

/// One QS field: exactly 10 characters, the sign included, as many decimals as fit
/// (seed: `0.01234567`, `-0.0123456`). Rounded, never `-0.0…`; beyond ±999999999 the
/// value is clamped.
pub fn qs_field(v: f64) -> String {
    let v = if v.is_finite() {
        v.clamp(-999_999_999.0, 999_999_999.0)
    } else {
        0.0
    };
    for decimals in (0..=8usize).rev() {
        let mut s = format!("{v:.decimals$}");
        if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
            // A negative value that rounds to zero prints as zero, with all decimals.
            return "0.00000000".to_string();
        }
        if s.len() <= QS_FIELD {
            if s.ends_with('.') {
                s.pop();
            }
            return format!("{s:>QS_FIELD$}");
        }
    }
    format!("{:>QS_FIELD$}", format!("{v:.0}"))
}

/// QS144/QS145/QS146: four fields separated by one space (field i starts at 11 * i).
pub fn qs_string(values: [f64; 4]) -> String {
    values.map(qs_field).join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_qs_example_field_for_field() {
        let s = qs_string([0.01234567, -0.0123456, 0.00123456, -0.0012345]);
        assert_eq!(s, "0.01234567 -0.0123456 0.00123456 -0.0012345");
        for i in 0..4 {
            let field = &s[11 * i..11 * i + 10];
            let v: f64 = field.trim().parse().unwrap();
            assert!((v - [0.01234567, -0.0123456, 0.00123456, -0.0012345][i]).abs() < 1e-12);
        }
    }

    #[test]
    fn fields_are_always_ten_wide() {
        for v in [
            0.0,
            -1.0,
            1.0,
            -1e-12,
            12.345678912,
            -123.45,
            99999.5,
            -0.000000004,
            1e12,
        ] {
            let f = qs_field(v);
            assert_eq!(f.len(), 10, "{v}: {f:?}");
            assert!(!f.contains("-0.0000000") || v < -5e-8, "{v}: {f:?}");
        }
        assert_eq!(qs_field(-1.0), "-1.0000000");
        assert_eq!(qs_field(0.0), "0.00000000");
        assert_eq!(qs_field(-4e-8), "0.00000000");
        assert_eq!(qs_field(4e-8), "0.00000004");
        assert_eq!(qs_field(-123.45), "-123.45000");
    }
}
