//! An independent computation of spec.md's cycle 451 formulas for the tests, written
//! with plain arrays (not with the cycles crate's model): its own kinematic chain
//! (the convention of `hal::config::KinematicsConfig`), the deviations `d_k`, the
//! statistics, the QS format check, and its own Gauss-Newton for the least-squares
//! optimum. It reads a 451 result as the JSON of `--json` gives it.

pub type V = [f64; 3];

pub fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn scale(a: V, k: f64) -> V {
    [a[0] * k, a[1] * k, a[2] * k]
}
pub fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn norm(a: V) -> f64 {
    dot(a, a).sqrt()
}

/// Rodrigues: `v` turned by `deg` about the unit vector `k`.
pub fn turn(k: V, deg: f64, v: V) -> V {
    let (s, c) = deg.to_radians().sin_cos();
    add(
        add(scale(v, c), scale(cross(k, v), s)),
        scale(k, dot(k, v) * (1.0 - c)),
    )
}

pub const X: V = [1.0, 0.0, 0.0];
pub const Y: V = [0.0, 1.0, 0.0];
pub const Z: V = [0.0, 0.0, 1.0];

/// (point on the line, direction, zero error) of a rotary axis from its errors by name.
pub fn joint(axis: char, pivot: V, e: &dyn Fn(&str) -> f64) -> (V, V, f64) {
    let n = |s: &str| e(&s.replace('k', &axis.to_string()));
    match axis {
        'A' => (
            add(pivot, [0.0, n("EY0k"), n("EZ0k")]),
            turn(Y, n("EB0k"), turn(Z, n("EC0k"), X)),
            n("EA0k"),
        ),
        'B' => (
            add(pivot, [n("EX0k"), 0.0, n("EZ0k")]),
            turn(Z, n("EC0k"), turn(X, n("EA0k"), Y)),
            n("EB0k"),
        ),
        _ => (
            add(pivot, [n("EX0k"), n("EY0k"), 0.0]),
            turn(X, n("EA0k"), turn(Y, n("EB0k"), Z)),
            n("EC0k"),
        ),
    }
}

pub struct Chain {
    /// (axis letter, pivot), bed outward / frame to tool.
    pub table: Vec<(char, V)>,
    pub head: Vec<(char, V)>,
}

pub fn chain_of(cfg: &hal::config::MachineConfig) -> Chain {
    let list = |v: &[hal::Axis]| {
        v.iter()
            .map(|a| (a.name().chars().next().unwrap(), cfg.kinematics.pivot[a]))
            .collect()
    };
    Chain {
        table: list(&cfg.kinematics.table),
        head: list(&cfg.kinematics.head),
    }
}

pub type Errors = std::collections::BTreeMap<String, f64>;

pub fn angle(a: &[f64; 3], axis: char) -> f64 {
    a[match axis {
        'A' => 0,
        'B' => 1,
        _ => 2,
    }]
}

/// The X/Y/Z axis positions at which the ball centre is at the table point `p`:
/// `T_table p - h`.
pub fn predict(ch: &Chain, e: &Errors, a: &[f64; 3], p: V) -> V {
    let get = |n: &str| e.get(n).copied().unwrap_or(0.0);
    let mut x = p;
    for (ax, pv) in ch.table.iter().rev() {
        let (q, d, z) = joint(*ax, *pv, &get);
        x = add(q, turn(d, angle(a, *ax) + z, sub(x, q)));
    }
    let mut h = [0.0; 3];
    for (ax, pv) in ch.head.iter().rev() {
        let (q, d, z) = joint(*ax, *pv, &get);
        h = add(q, turn(d, angle(a, *ax) + z, sub(h, q)));
    }
    sub(x, h)
}

pub fn table_point(ch: &Chain, e: &Errors, a: &[f64; 3], xyz: V) -> V {
    let get = |n: &str| e.get(n).copied().unwrap_or(0.0);
    let mut h = [0.0; 3];
    for (ax, pv) in ch.head.iter().rev() {
        let (q, d, z) = joint(*ax, *pv, &get);
        h = add(q, turn(d, angle(a, *ax) + z, sub(h, q)));
    }
    let mut x = add(xyz, h);
    for (ax, pv) in ch.table.iter() {
        let (q, d, z) = joint(*ax, *pv, &get);
        x = add(q, turn(d, -(angle(a, *ax) + z), sub(x, q)));
    }
    x
}

/// One measured axis as the JSON result gives it: (angles, centre) per position,
/// reference first.
pub struct Measured {
    pub axis: char,
    pub positions: Vec<([f64; 3], V)>,
}

pub fn measured(c: &serde_json::Value) -> Vec<Measured> {
    c["kinematics"]["axes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| Measured {
            axis: a["axis"].as_str().unwrap().chars().next().unwrap(),
            positions: a["positions"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| {
                    let g = |n: &str| p["angles"][n].as_f64().unwrap_or(0.0);
                    let c = &p["centre"];
                    (
                        [g("A"), g("B"), g("C")],
                        [
                            c[0].as_f64().unwrap(),
                            c[1].as_f64().unwrap(),
                            c[2].as_f64().unwrap(),
                        ],
                    )
                })
                .collect(),
        })
        .collect()
}

/// spec.md: d_k = c_measured(k) - c_predicted(k), the prediction from the model and
/// the centre measured at the 0 deg reference.
pub fn spec_deviations(ch: &Chain, e: &Errors, m: &Measured) -> Vec<V> {
    let (a0, c0) = m.positions[0];
    let p = table_point(ch, e, &a0, c0);
    m.positions
        .iter()
        .map(|(a, c)| sub(*c, predict(ch, e, a, p)))
        .collect()
}

/// (dispersion sqrt(sum |d|^2 / m), max |d|); with one position besides the reference
/// the dispersion is that position's spatial error |d_1| (spec.md, the seeds).
pub fn spec_statistics(d: &[V]) -> (f64, f64) {
    let sum: f64 = d.iter().map(|v| dot(*v, *v)).sum();
    let max = d.iter().map(|v| norm(*v)).fold(0.0, f64::max);
    if d.len() == 2 {
        return (norm(d[1]), max);
    }
    ((sum / d.len() as f64).sqrt(), max)
}

pub fn spec_objective(ch: &Chain, e: &Errors, ms: &[Measured]) -> f64 {
    ms.iter()
        .flat_map(|m| spec_deviations(ch, e, m))
        .map(|d| dot(d, d))
        .sum()
}

pub fn errors_of(v: &serde_json::Value) -> Errors {
    v.as_object()
        .unwrap()
        .iter()
        .map(|(k, x)| (k.clone(), x.as_f64().unwrap()))
        .collect()
}

/// The QS string order of spec.md.
pub fn qs_names(axis: char) -> [String; 4] {
    let names = match axis {
        'A' => ["EY0", "EZ0", "EB0", "EC0"],
        'B' => ["EZ0", "EX0", "EC0", "EA0"],
        _ => ["EX0", "EY0", "EA0", "EB0"],
    };
    names.map(|n| format!("{n}{axis}"))
}

/// Q141..Q146 and QS144..QS146 of a 451 result against spec.md's formulas computed here.
pub fn check_results_against_spec(c: &serde_json::Value, cfg: &hal::config::MachineConfig) {
    let ch = chain_of(cfg);
    let k = &c["kinematics"];
    let before = errors_of(&k["errors_before"]);
    let after = errors_of(&k["errors_after"]);
    let ms = measured(c);
    for (i, axis) in ['A', 'B', 'C'].into_iter().enumerate() {
        let q = |n: usize| c["q"][format!("Q{n}")].as_f64().unwrap();
        let qs = c["qs"][format!("QS{}", 144 + i)].as_str().unwrap();
        assert_eq!(qs.len(), 43, "{qs:?}");
        let fields: Vec<f64> = (0..4)
            .map(|f| {
                assert!(f == 3 || &qs[11 * f + 10..11 * f + 11] == " ", "{qs:?}");
                qs[11 * f..11 * f + 10].trim().parse().unwrap()
            })
            .collect();
        match ms.iter().find(|m| m.axis == axis) {
            None => {
                assert_eq!((q(141 + i), q(144 + i)), (-1.0, -1.0), "{axis}");
                assert!(fields.iter().all(|f| *f == -1.0), "{axis}: {qs:?}");
            }
            Some(m) => {
                let (disp_b, max_b) = spec_statistics(&spec_deviations(&ch, &before, m));
                let (disp_a, max_a) = spec_statistics(&spec_deviations(&ch, &after, m));
                assert!(
                    (q(141 + i) - disp_b).abs() < 1e-9,
                    "Q{}: {} vs {disp_b}",
                    141 + i,
                    q(141 + i)
                );
                assert!(
                    (q(144 + i) - disp_a).abs() < 1e-9,
                    "Q{}: {} vs {disp_a}",
                    144 + i,
                    q(144 + i)
                );
                let ax = k["axes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|a| a["axis"] == axis.to_string())
                    .unwrap();
                assert!((ax["max_before"].as_f64().unwrap() - max_b).abs() < 1e-9);
                assert!((ax["max_after"].as_f64().unwrap() - max_a).abs() < 1e-9);
                for (f, name) in fields.iter().zip(qs_names(axis)) {
                    let v = after[&name];
                    assert!((f - v).abs() <= 5e-8 + 1e-12, "{name}: QS {f} vs {v}");
                }
            }
        }
    }
}

/// Gauss-Newton over `free` (numeric Jacobian, normal equations by Gaussian
/// elimination): the least-squares optimum of spec.md's objective.
pub fn independent_optimum(ch: &Chain, ms: &[Measured], free: &[String]) -> (Errors, f64) {
    let mut e: Errors = free.iter().map(|n| (n.clone(), 0.0)).collect();
    let residuals = |e: &Errors| -> Vec<f64> {
        ms.iter()
            .flat_map(|m| spec_deviations(ch, e, m))
            .flat_map(|d| d.into_iter())
            .collect()
    };
    for _ in 0..30 {
        let r = residuals(&e);
        let n = free.len();
        let h = 1e-5;
        let cols: Vec<Vec<f64>> = free
            .iter()
            .map(|name| {
                let mut p = e.clone();
                *p.get_mut(name).unwrap() += h;
                let mut q = e.clone();
                *q.get_mut(name).unwrap() -= h;
                let (rp, rq) = (residuals(&p), residuals(&q));
                rp.iter()
                    .zip(rq)
                    .map(|(a, b)| (a - b) / (2.0 * h))
                    .collect()
            })
            .collect();
        let mut a = vec![vec![0.0; n + 1]; n];
        for i in 0..n {
            for j in 0..n {
                a[i][j] = cols[i].iter().zip(&cols[j]).map(|(x, y)| x * y).sum();
            }
            a[i][n] = -cols[i].iter().zip(&r).map(|(x, y)| x * y).sum::<f64>();
        }
        for c in 0..n {
            let piv = (c..n)
                .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
                .unwrap();
            a.swap(c, piv);
            let pivot = a[c].clone();
            for (row, line) in a.iter_mut().enumerate() {
                if row != c {
                    let f = line[c] / pivot[c];
                    for (x, p) in line[c..].iter_mut().zip(&pivot[c..]) {
                        *x -= f * p;
                    }
                }
            }
        }
        let mut step = 0.0f64;
        for (i, name) in free.iter().enumerate() {
            let d = a[i][n] / a[i][i];
            *e.get_mut(name).unwrap() += d;
            step = step.max(d.abs());
        }
        if step < 1e-13 {
            break;
        }
    }
    let f = spec_objective(ch, &e, ms);
    (e, f)
}
