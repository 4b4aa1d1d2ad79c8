//! One SVG chart of a series: y-axis at round values, dated time axis, both series,
//! the tolerance lines (or an arrow when they are outside the view), the alarm rings,
//! and the latest value beside it.

use super::series::{Point, Series, Verdict};
use super::style::escape;
use super::text::{date, num, plain, plain_u, signed, tick_label, tick_step};
use std::fmt::Write;

const W: f64 = 620.0;
const H: f64 = 230.0;
const LEFT: f64 = 72.0;
const RIGHT: f64 = 16.0;
const TOP: f64 = 30.0;
const BOTTOM: f64 = 50.0;
/// The smallest y span shown (µm or arcsec): noise of a tenth stays small.
const MIN_SPAN: f64 = 2.0;

/// The y view: fitted to the data, widened to a tolerance line only when it is near.
fn y_range(s: &Series) -> (f64, f64) {
    let vals = s.points.iter().flat_map(|p| {
        let u = p.u.unwrap_or(0.0);
        [p.before, p.after - u, p.after + u]
    });
    let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    let (mut lo, mut hi) = if hi - lo < MIN_SPAN {
        let mid = (hi + lo) / 2.0;
        (mid - MIN_SPAN / 2.0, mid + MIN_SPAN / 2.0)
    } else {
        (lo, hi)
    };
    let pad = 0.12 * (hi - lo);
    (lo, hi) = (lo - pad, hi + pad);
    let span = hi - lo;
    let up = s
        .points
        .iter()
        .filter_map(|p| p.tol.map(|t| p.before + t))
        .fold(f64::NEG_INFINITY, f64::max);
    let down = s
        .points
        .iter()
        .filter_map(|p| p.tol.map(|t| p.before - t))
        .fold(f64::INFINITY, f64::min);
    if up > hi && up - hi <= 0.5 * span {
        hi = up + 0.05 * span;
    }
    if down < lo && lo - down <= 0.5 * span {
        lo = down - 0.05 * span;
    }
    (lo, hi)
}

/// The x positions of the runs: by start time, or evenly when the stamps are not
/// readable or all the same.
fn x_positions(points: &[Point]) -> Vec<f64> {
    let pw = W - LEFT - RIGHT;
    let n = points.len();
    let times: Option<Vec<i64>> = points.iter().map(|p| p.t).collect();
    let frac: Vec<f64> = match times {
        Some(t) if n >= 2 && t[n - 1] > t[0] => t
            .iter()
            .map(|&x| (x - t[0]) as f64 / (t[n - 1] - t[0]) as f64)
            .collect(),
        _ if n >= 2 => (0..n).map(|i| i as f64 / (n - 1) as f64).collect(),
        _ => vec![0.5; n],
    };
    frac.iter().map(|f| LEFT + pw * (0.04 + 0.92 * f)).collect()
}

/// Labels of the time axis by the span the runs cover, and the axis title.
fn time_labels(points: &[Point]) -> (Vec<String>, String) {
    let times: Option<Vec<i64>> = points.iter().map(|p| p.t).collect();
    let Some(t) = times.filter(|t| !t.is_empty()) else {
        return (
            points.iter().map(|p| format!("run {}", p.run)).collect(),
            "run".into(),
        );
    };
    let span = t[t.len() - 1] - t[0];
    let first = &points[0].started;
    let (range, title): (std::ops::Range<usize>, String) = if span >= 2 * 86_400 {
        (5..10, format!("run start (UTC), {}", &first[..4]))
    } else if span >= 600 {
        (11..16, format!("run start (UTC) on {}", &first[..10]))
    } else {
        (11..19, format!("run start (UTC) on {}", &first[..10]))
    };
    (
        points
            .iter()
            .map(|p| p.started[range.clone()].to_string())
            .collect(),
        title,
    )
}

/// The view of one chart: the y-range and the x positions, in SVG coordinates.
struct View {
    lo: f64,
    hi: f64,
    xs: Vec<f64>,
}

impl View {
    fn y(&self, val: f64) -> f64 {
        TOP + (H - TOP - BOTTOM) * (self.hi - val) / (self.hi - self.lo)
    }
}

pub(super) fn chart(html: &mut String, idx: usize, s: &Series, v: &Verdict) {
    let (lo, hi) = y_range(s);
    let view = View {
        lo,
        hi,
        xs: x_positions(&s.points),
    };
    let _ = write!(
        html,
        "<figure class=\"chart\" id=\"chart-{idx}\"><svg class=\"trend\" data-series=\"{idx}\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{H}\" viewBox=\"0 0 {W} {H}\">\
         <text class=\"title\" x=\"{LEFT}\" y=\"18\">{}</text>",
        escape(&s.title)
    );
    y_axis(html, s, &view);
    time_axis(html, s, &view);
    plot(html, s, v, &view);
    tolerance_arrows(html, s, &view);
    html.push_str("</svg>");
    stats(html, s, v);
    html.push_str("</figure>\n");
}

/// Grid and labels at round values; the unit in the axis title.
fn y_axis(html: &mut String, s: &Series, view: &View) {
    let pw = W - LEFT - RIGHT;
    let ph = H - TOP - BOTTOM;
    let step = tick_step(view.hi - view.lo);
    let mut t = (view.lo / step).ceil() * step;
    while t <= view.hi + 1e-9 * step {
        let y = view.y(t);
        let _ = write!(
            html,
            "<line class=\"{}\" x1=\"{LEFT}\" x2=\"{:.1}\" y1=\"{y:.1}\" y2=\"{y:.1}\"/><text class=\"ytick\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            if t.abs() < 1e-9 * step { "zero" } else { "grid" },
            LEFT + pw,
            LEFT - 5.0,
            y + 4.0,
            tick_label(t, step)
        );
        t += step;
    }
    let _ = write!(
        html,
        "<text class=\"yunit\" transform=\"translate(14 {:.1}) rotate(-90)\" text-anchor=\"middle\">{} ({})</text>",
        TOP + ph / 2.0,
        escape(&s.title),
        s.unit.label()
    );
}

/// A tick per run, labels where they do not overlap (the last always), the frame.
fn time_axis(html: &mut String, s: &Series, view: &View) {
    let pw = W - LEFT - RIGHT;
    let ph = H - TOP - BOTTOM;
    let (labels, title) = time_labels(&s.points);
    let xs = &view.xs;
    let mut last_label = f64::NEG_INFINITY;
    let n = xs.len();
    for (i, (x, label)) in xs.iter().zip(&labels).enumerate() {
        let _ = write!(
            html,
            "<line class=\"grid\" x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{TOP}\" y2=\"{:.1}\"/>",
            TOP + ph
        );
        let room = i + 1 == n || (x - last_label >= 70.0 && xs[n - 1] - x >= 70.0);
        if room {
            let _ = write!(
                html,
                "<text class=\"xtick\" x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                TOP + ph + 15.0,
                escape(label)
            );
            last_label = *x;
        }
    }
    let _ = write!(
        html,
        "<text class=\"xunit\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text><rect class=\"frame\" x=\"{LEFT}\" y=\"{TOP}\" width=\"{pw}\" height=\"{ph}\"/>",
        LEFT + pw / 2.0,
        H - 10.0,
        escape(&title)
    );
}

/// The tolerance lines, both series and the alarm rings, clipped to the plot area.
fn plot(html: &mut String, s: &Series, v: &Verdict, view: &View) {
    let u = s.unit.label();
    let pw = W - LEFT - RIGHT;
    let ph = H - TOP - BOTTOM;
    let xs = &view.xs;
    let _ = write!(
        html,
        "<svg x=\"{LEFT}\" y=\"{TOP}\" width=\"{pw}\" height=\"{ph}\" viewBox=\"{LEFT} {TOP} {pw} {ph}\">"
    );
    let line = |f: &dyn Fn(&Point) -> Option<f64>| -> String {
        s.points
            .iter()
            .zip(xs)
            .filter_map(|(p, x)| f(p).map(|val| format!("{x:.1},{:.1}", view.y(val))))
            .collect::<Vec<_>>()
            .join(" ")
    };
    if s.points.iter().any(|p| p.tol.is_some()) {
        for sign in [1.0, -1.0] {
            let mut pts = line(&|p| p.tol.map(|t| p.before + sign * t));
            // One run: its tolerance across the plot.
            if let (1, Some(t)) = (s.points.len(), s.points[0].tol) {
                let y = view.y(s.points[0].before + sign * t);
                pts = format!("{LEFT},{y:.1} {},{y:.1}", LEFT + pw);
            }
            let _ = write!(html, "<polyline class=\"tol\" points=\"{pts}\"/>");
        }
    }
    let before = line(&|p| Some(p.before));
    let after = line(&|p| Some(p.after));
    let _ = write!(
        html,
        "<polyline class=\"line before\" points=\"{before}\"/><polyline class=\"line after\" points=\"{after}\"/>"
    );
    for (p, x) in s.points.iter().zip(xs) {
        for (class, val) in [("before", p.before), ("after", p.after)] {
            let _ = write!(
                html,
                "<circle class=\"pt {class}\" data-run=\"{}\" cx=\"{x:.1}\" cy=\"{:.1}\" r=\"3.5\"><title>{} {class} optimisation: {} {u}</title></circle>",
                p.run,
                view.y(val),
                escape(&p.started),
                signed(val)
            );
        }
    }
    error_bars(html, s, view);
    moved_marks(html, s, v, view);
    for &i in &v.alarms {
        let (p, x) = (&s.points[i], xs[i]);
        let change = signed(p.after - s.points[i - 1].after);
        let y = view.y(p.after);
        // Near the right edge the label ends left of the ring, so it stays in view.
        let (lx, anchor) = if x > LEFT + pw - 50.0 {
            (x - 12.0, "end")
        } else {
            (x, "middle")
        };
        let _ = write!(
            html,
            "<circle class=\"alarm-ring\" data-run=\"{}\" cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"9\"><title>alarm: changed by {change} {u} since the previous run</title></circle>\
             <text class=\"alarm-label\" x=\"{lx:.1}\" y=\"{:.1}\" text-anchor=\"{anchor}\">{change} {u}</text>",
            p.run,
            (y - 13.0).max(TOP + 11.0),
        );
    }
    html.push_str("</svg>");
}

/// `after ± u` (k = 1) of every run that has a u, with caps.
fn error_bars(html: &mut String, s: &Series, view: &View) {
    let unit = s.unit.label();
    for (p, x) in s.points.iter().zip(&view.xs) {
        let Some(u) = p.u else { continue };
        let (top, bottom) = (view.y(p.after + u), view.y(p.after - u));
        let _ = write!(
            html,
            "<path class=\"ebar\" data-run=\"{}\" d=\"M{x:.1},{top:.1}V{bottom:.1}M{:.1},{top:.1}h8M{:.1},{bottom:.1}h8\"><title>{} ± {} {unit} (standard uncertainty, k = 1)</title></path>",
            p.run,
            x - 4.0,
            x - 4.0,
            signed(p.after),
            plain_u(u),
        );
    }
}

/// A square around each run whose change since the previous run exceeds 2 combined
/// standard uncertainties: a change of the machine, not noise of the measurement.
fn moved_marks(html: &mut String, s: &Series, v: &Verdict, view: &View) {
    let unit = s.unit.label();
    for &i in &v.moved {
        let (p, x) = (&s.points[i], view.xs[i]);
        let y = view.y(p.after);
        let change = p.after - s.points[i - 1].after;
        let uc = s.change_u(i).unwrap_or(0.0);
        let _ = write!(
            html,
            "<rect class=\"moved\" data-run=\"{}\" x=\"{:.1}\" y=\"{:.1}\" width=\"14\" height=\"14\"><title>changed by {} {unit} since the previous run, more than 2 combined standard uncertainties (2 u_c = {} {unit})</title></rect>",
            p.run,
            x - 7.0,
            y - 7.0,
            signed(change),
            plain_u(2.0 * uc),
        );
    }
}

/// Tolerance lines wholly outside the view: an arrow with the distance.
fn tolerance_arrows(html: &mut String, s: &Series, view: &View) {
    let u = s.unit.label();
    let right = W - RIGHT - 4.0;
    let up = s
        .points
        .iter()
        .filter_map(|p| p.tol.map(|t| p.before + t))
        .fold(f64::INFINITY, f64::min);
    let down = s
        .points
        .iter()
        .filter_map(|p| p.tol.map(|t| p.before - t))
        .fold(f64::NEG_INFINITY, f64::max);
    let Some(tol) = s.points.last().and_then(|p| p.tol) else {
        return;
    };
    if up.is_finite() && up > view.hi {
        let _ = write!(
            html,
            "<text class=\"arrow\" x=\"{right:.1}\" y=\"{:.1}\" text-anchor=\"end\">&#9650; tolerance +{} {u}: {} {u} above the view</text>",
            TOP + 12.0,
            plain(tol),
            plain(up - view.hi)
        );
    }
    if down.is_finite() && down < view.lo {
        let _ = write!(
            html,
            "<text class=\"arrow\" x=\"{right:.1}\" y=\"{:.1}\" text-anchor=\"end\">&#9660; tolerance &#8722;{} {u}: {} {u} below the view</text>",
            H - BOTTOM - 5.0,
            plain(tol),
            plain(view.lo - down)
        );
    }
}

/// Beside the chart: the latest value, its change since the previous run, the
/// tolerance.
fn stats(html: &mut String, s: &Series, v: &Verdict) {
    let u = s.unit.label();
    let Some(last) = s.points.last() else { return };
    let _ = write!(
        html,
        "<div class=\"stats\"><div>latest ({}):</div><div class=\"value latest\">{}{} {u}</div><div>before optimisation {} {u}</div>",
        escape(&date(&last.started)),
        signed(last.after),
        last.u.map_or_else(String::new, |x| format!(" &#177; {}", plain_u(x))),
        signed(last.before),
    );
    match (v.change, s.points.iter().rev().nth(1)) {
        (Some(c), Some(prev)) => {
            let alarm = c.abs() > v.threshold;
            let _ = write!(
                html,
                "<div>since the previous run ({}):</div><div class=\"value change{}\">{} {u}</div>",
                escape(&date(&prev.started)),
                if alarm { " bad" } else { "" },
                signed(c),
            );
            if alarm {
                let _ = write!(
                    html,
                    "<div class=\"bad\">alarm: more than {} {u}</div>",
                    num(v.threshold)
                );
            }
        }
        _ => html.push_str("<div>first run</div>"),
    }
    if let Some(uc) = s.change_u(s.points.len().saturating_sub(1)) {
        let moved = v.moved.last().is_some_and(|&i| i + 1 == s.points.len());
        let _ = write!(
            html,
            "<div class=\"{}\">{} (2 u_c = {} {u})</div>",
            if moved { "bad moved" } else { "ok" },
            if moved {
                "a change: more than 2 combined uncertainties"
            } else {
                "within 2 combined uncertainties: noise"
            },
            plain_u(2.0 * uc)
        );
    }
    if let (Some(t), Some(ok)) = (last.tol, v.in_tolerance) {
        let _ = write!(
            html,
            "<div class=\"{}\">{} (correction {} of &#177;{} {u})</div>",
            if ok { "ok" } else { "bad" },
            if ok {
                "in tolerance"
            } else {
                "OUT OF TOLERANCE"
            },
            signed(last.after - last.before),
            plain(t)
        );
    }
    html.push_str("</div>");
}
