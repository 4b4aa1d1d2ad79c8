use nalgebra::Vector3;
use probebridge_cycles::{fit_sphere, FitError};

/// splitmix64: seeded, reproducible, no dependency.
struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Points on a cap (polar angle up to `max_polar` deg), as cycle 451 probes a sphere.
fn cap_points(
    c: Vector3<f64>,
    r: f64,
    n: usize,
    max_polar: f64,
    rng: &mut Rng,
) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|_| {
            let theta = rng.uniform() * max_polar.to_radians();
            let phi = rng.uniform() * std::f64::consts::TAU;
            c + r * Vector3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            )
        })
        .collect()
}

#[test]
fn exact_points_are_recovered() {
    let mut rng = Rng(451);
    for _ in 0..50 {
        let c = Vector3::new(
            rng.uniform() * 800.0 - 400.0,
            rng.uniform() * 600.0 - 300.0,
            rng.uniform() * 400.0,
        );
        let r = 5.0 + rng.uniform() * 20.0;
        let pts = cap_points(c, r, 5 + (rng.next_u64() % 10) as usize, 100.0, &mut rng);
        let fit = fit_sphere(&pts).unwrap();
        assert!((fit.centre - c).norm() < 1e-9, "{:?} vs {c:?}", fit.centre);
        assert!((fit.radius - r).abs() < 1e-9);
        assert!(fit.rms < 1e-9 && fit.max_residual < 1e-9);
    }
}

#[test]
fn minimal_four_points_and_pole_plus_equator() {
    let c = Vector3::new(10.0, -20.0, 30.0);
    let r = 12.5;
    // The 451 pattern: the pole and Q423 = 3 points around the equator.
    let mut pts = vec![c + Vector3::new(0.0, 0.0, r)];
    for k in 0..3 {
        let a = (k as f64 * 120.0).to_radians();
        pts.push(c + r * Vector3::new(a.cos(), a.sin(), 0.0));
    }
    let fit = fit_sphere(&pts).unwrap();
    assert!((fit.centre - c).norm() < 1e-9 && (fit.radius - r).abs() < 1e-9);
}

#[test]
fn noisy_points_fit_within_expectation() {
    let mut rng = Rng(0x5EED);
    let sigma = 0.001;
    let (c, r) = (Vector3::new(100.0, 50.0, -20.0), 12.5);
    for _ in 0..20 {
        let mut pts = cap_points(c, r, 40, 90.0, &mut rng);
        for p in &mut pts {
            let u = (*p - c).normalize();
            *p += u * sigma * rng.normal();
        }
        let fit = fit_sphere(&pts).unwrap();
        // 40 points on a half sphere: centre and radius to a few sigma / sqrt(n).
        assert!(
            (fit.centre - c).norm() < 5.0 * sigma,
            "{}",
            (fit.centre - c).norm()
        );
        assert!((fit.radius - r).abs() < 5.0 * sigma);
        assert!(
            fit.rms > 0.5 * sigma && fit.rms < 1.5 * sigma,
            "rms {}",
            fit.rms
        );
        assert!(fit.max_residual >= fit.rms);
    }
}

#[test]
fn errors_say_why() {
    let p = |x, y, z| Vector3::new(x, y, z);
    assert_eq!(
        fit_sphere(&[p(0.0, 0.0, 0.0), p(1.0, 0.0, 0.0), p(0.0, 1.0, 0.0)]),
        Err(FitError::TooFewPoints(3))
    );
    let coplanar = [
        p(0.0, 0.0, 5.0),
        p(1.0, 0.0, 5.0),
        p(0.0, 1.0, 5.0),
        p(1.0, 1.0, 5.0),
        p(3.0, 2.0, 5.0),
    ];
    let e = fit_sphere(&coplanar).unwrap_err();
    assert!(matches!(e, FitError::Degenerate(_)), "{e}");
    assert!(e.to_string().contains("coplanar"), "{e}");
    let same = [p(1.0, 1.0, 1.0); 5];
    assert!(matches!(fit_sphere(&same), Err(FitError::Degenerate(_))));
    let nan = [
        p(0.0, 0.0, 0.0),
        p(1.0, 0.0, 0.0),
        p(0.0, 1.0, 0.0),
        p(0.0, 0.0, f64::NAN),
    ];
    assert_eq!(fit_sphere(&nan), Err(FitError::NotFinite(3)));
}
