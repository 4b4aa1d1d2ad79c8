//! Measuring positions of cycle 451 (spec.md, "Cycle 451"; seeds 000/004, "Positioning
//! direction" and "Machines with Hirth-coupled axes").
//!
//! Axis with start S, end E, n points: step = (E - S) / (n - 1) (n = 1: S alone),
//! position i = S + i * step. With a Hirth grid g every position is rounded to the
//! nearest multiple of g. A position equal to 0 deg is dropped: the reference
//! measurement at 0 deg is always made first. n = 0: the axis is not measured.

/// Angles closer than this to 0 count as 0, deg.
const ZERO: f64 = 1e-9;

/// `x` rounded to the nearest multiple of the Hirth grid `g` (none when `g <= 0`), and
/// to 1e-9 deg so that `S + i * step` prints as the seeds write it.
pub fn on_grid(x: f64, g: f64) -> f64 {
    let x = if g > 0.0 { (x / g).round() * g } else { x };
    let r = (x * 1e9).round() / 1e9;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

/// The positions of one axis before dropping 0 (seed examples: +90/-90/4 gives 90, 30,
/// -30, -90; -30/+90/4 with a 3 deg grid gives -30, 9, 51, 90).
pub fn raw_positions(start: f64, end: f64, n: u32, hirth: f64) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![on_grid(start, hirth)],
        _ => {
            let step = (end - start) / f64::from(n - 1);
            (0..n)
                .map(|i| on_grid(start + f64::from(i) * step, hirth))
                .collect()
        }
    }
}

/// The measuring positions of one axis after the 0 deg reference: [`raw_positions`]
/// without those equal to 0.
pub fn measuring_positions(start: f64, end: f64, n: u32, hirth: f64) -> Vec<f64> {
    raw_positions(start, end, n, hirth)
        .into_iter()
        .filter(|a| a.abs() > ZERO)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_examples() {
        assert_eq!(
            measuring_positions(90.0, -90.0, 4, 0.0),
            vec![90.0, 30.0, -30.0, -90.0]
        );
        assert_eq!(
            measuring_positions(90.0, 270.0, 4, 0.0),
            vec![90.0, 150.0, 210.0, 270.0]
        );
        assert_eq!(
            measuring_positions(-30.0, 90.0, 4, 3.0),
            vec![-30.0, 9.0, 51.0, 90.0]
        );
    }

    #[test]
    fn zero_is_dropped_and_single_points_are_the_start() {
        assert_eq!(measuring_positions(-90.0, 90.0, 3, 0.0), vec![-90.0, 90.0]);
        assert_eq!(measuring_positions(45.0, 90.0, 1, 0.0), vec![45.0]);
        assert!(measuring_positions(0.0, 90.0, 1, 0.0).is_empty());
        assert!(measuring_positions(10.0, 90.0, 0, 0.0).is_empty());
        // 1 deg rounds to 0 on a 5 deg grid and is dropped.
        assert_eq!(measuring_positions(1.0, 91.0, 2, 5.0), vec![90.0]);
    }
}
