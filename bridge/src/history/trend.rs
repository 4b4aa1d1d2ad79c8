//! The trend page of `probebridge history --html FILE`: for every ISO 230-7 error of
//! cycle 451 and every rotary axis's dispersion, the values over the runs as an SVG
//! line chart, with the machine's maxModification as a band about zero (a drift that
//! leaves the band is a correction cycle 451 would not write without confirmation).
//! One self-contained HTML file: no script, no external resource.

use super::RunRow;
use std::collections::BTreeMap;
use std::fmt::Write;

const W: f64 = 640.0;
const H: f64 = 200.0;
const PAD: f64 = 40.0;

/// A series: (run start, value) per run, in order.
type Series = Vec<(String, f64)>;

pub fn trend_html(runs: &[RunRow]) -> String {
    let mut errors: BTreeMap<String, Series> = BTreeMap::new();
    let mut dispersion: BTreeMap<String, Series> = BTreeMap::new();
    let mut band: Option<f64> = None;
    for r in runs.iter().filter(|r| r.status == "done") {
        for e in &r.iso_errors {
            errors
                .entry(e.name.clone())
                .or_default()
                .push((r.started.clone(), e.after));
        }
        for d in &r.dispersion {
            dispersion
                .entry(d.axis.clone())
                .or_default()
                .push((r.started.clone(), d.before));
        }
        if !r.iso_errors.is_empty() {
            band = band.or(r.max_modification);
        }
    }
    let mut html = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>probebridge: calibration trend</title><style>\
         body{font-family:sans-serif;margin:1em}figure{display:inline-block;margin:0.5em}\
         .band{fill:#d8f0d8}.line{fill:none;stroke:#1f5fa8;stroke-width:2}\
         .pt{fill:#1f5fa8}.axis{stroke:#888}text{font-size:11px}</style></head><body>\n",
    );
    let machines: std::collections::BTreeSet<&str> =
        runs.iter().map(|r| r.machine.as_str()).collect();
    let _ = writeln!(
        html,
        "<h1>Calibration trend</h1><p>{} run(s) of cycle 451 on {}; band: maxModification {}</p>",
        runs.iter().filter(|r| !r.iso_errors.is_empty()).count(),
        escape(&machines.into_iter().collect::<Vec<_>>().join(", ")),
        band.map_or("not recorded".into(), |b| format!("&#177;{b}")),
    );
    html.push_str("<h2>ISO 230-7 errors identified by cycle 451</h2>\n");
    for (name, s) in &errors {
        chart(&mut html, name, s, band);
    }
    html.push_str("<h2>Dispersion per axis (before optimisation)</h2>\n");
    for (axis, s) in &dispersion {
        chart(&mut html, &format!("dispersion {axis}"), s, None);
    }
    html.push_str("</body></html>\n");
    html
}

fn chart(html: &mut String, title: &str, s: &Series, band: Option<f64>) {
    // The scale follows the data (a drift of microns stays visible), with zero in view;
    // the band is clipped to it.
    let b = band.unwrap_or(0.0);
    let lo = s.iter().map(|p| p.1).fold(0.0, f64::min);
    let hi = s.iter().map(|p| p.1).fold(0.0, f64::max);
    let span = if hi - lo > 1e-9 { hi - lo } else { 1e-3 };
    let (lo, hi) = (lo - 0.1 * span, hi + 0.1 * span);
    let clip = |v: f64| v.clamp(lo, hi);
    let y = |v: f64| PAD + (H - 2.0 * PAD) * (hi - v) / (hi - lo);
    let n = s.len().max(2) - 1;
    let x = |i: usize| PAD + (W - 2.0 * PAD) * i as f64 / n as f64;
    let id = title.replace(' ', "-");
    let _ = write!(
        html,
        "<figure><svg id=\"{id}\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{H}\" viewBox=\"0 0 {W} {H}\">\
         <text x=\"{PAD}\" y=\"16\">{}</text>",
        escape(title)
    );
    if band.is_some() {
        let _ = write!(
            html,
            "<rect class=\"band\" x=\"{PAD}\" y=\"{:.2}\" width=\"{:.2}\" height=\"{:.2}\"/>",
            y(clip(b)),
            W - 2.0 * PAD,
            y(clip(-b)) - y(clip(b))
        );
    }
    let _ = write!(
        html,
        "<line class=\"axis\" x1=\"{PAD}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\"/>\
         <text x=\"2\" y=\"{:.2}\">{hi:.4}</text><text x=\"2\" y=\"{:.2}\">{lo:.4}</text>",
        y(0.0),
        W - PAD,
        y(0.0),
        PAD,
        H - PAD
    );
    let points: Vec<String> = s
        .iter()
        .enumerate()
        .map(|(i, p)| format!("{:.2},{:.2}", x(i), y(p.1)))
        .collect();
    let _ = write!(
        html,
        "<polyline class=\"line\" points=\"{}\"/>",
        points.join(" ")
    );
    for (i, (t, v)) in s.iter().enumerate() {
        let _ = write!(
            html,
            "<circle class=\"pt\" cx=\"{:.2}\" cy=\"{:.2}\" r=\"3\"><title>{} {v:+.6}</title></circle>",
            x(i),
            y(*v),
            escape(t)
        );
    }
    if let (Some(first), Some(last)) = (s.first(), s.last()) {
        let _ = write!(
            html,
            "<text x=\"{PAD}\" y=\"{:.2}\">{}</text><text x=\"{:.2}\" y=\"{:.2}\" text-anchor=\"end\">{}</text>",
            H - 8.0,
            escape(&first.0),
            W - PAD,
            H - 8.0,
            escape(&last.0)
        );
    }
    html.push_str("</svg></figure>\n");
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::{DispersionRow, IsoErrorRow};

    #[test]
    fn one_chart_per_error_and_axis_with_a_point_per_run() {
        let runs: Vec<RunRow> = (0..5)
            .map(|i| RunRow {
                id: i,
                started: format!("2026-11-2{i}T08:00:00Z"),
                finished: None,
                machine: "table-ac".into(),
                source: "serve".into(),
                request_seq: Some(i as u16),
                program_number: Some(451),
                program: "451.h".into(),
                status: "done".into(),
                message: None,
                protocols: vec![],
                results: vec![],
                iso_errors: ["EX0C", "EY0C"]
                    .iter()
                    .map(|n| IsoErrorRow {
                        block: 11,
                        name: (*n).into(),
                        before: 0.01 * i as f64,
                        after: 0.0,
                    })
                    .collect(),
                max_modification: Some(0.03),
                parameters: vec![],
                dispersion: vec![DispersionRow {
                    block: 11,
                    axis: "C".into(),
                    before: 0.001 * i as f64,
                    after: 0.0,
                }],
            })
            .collect();
        let html = trend_html(&runs);
        assert_eq!(html.matches("<svg").count(), 3);
        assert_eq!(html.matches("<circle").count(), 15);
        assert_eq!(html.matches("class=\"band\"").count(), 2);
        assert!(html.contains("id=\"EX0C\"") && html.contains("id=\"dispersion-C\""));
    }
}
