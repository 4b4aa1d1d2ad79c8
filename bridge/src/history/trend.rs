//! The calibration trend pages (`probebridge history --html FILE`, and `/trend` of the
//! gateway's web face): per machine, each ISO 230-7 error cycle 451 identified and
//! each rotary axis's dispersion over the runs, as SVG charts an engineer reads without
//! taking numbers off an axis:
//! - values in µm (position errors, dispersion) or arcsec (orientation and zero
//!   errors), the y-range fitted to the data, ticks at round values;
//! - two series: before optimisation (the kinematics in use, red) and after (what the
//!   cycle identified, green), as the measuring protocol draws them;
//! - the tolerance (maxModification about the kinematics in use: the largest
//!   correction written without confirmation) drawn where it falls, else an arrow
//!   saying how far outside the view it is;
//! - a dated time axis; the latest value and its change since the previous run beside
//!   each chart; a run whose identified value changed by more than `[history]
//!   alarm_um` / `alarm_arcsec` ringed;
//! - a summary table at the top, the errors that moved most first.
//!
//! Several machines (a fleet on PostgreSQL): an index page and one page per machine.
//! Every stored string is escaped, in text and attributes; element ids are numbers, no
//! stored text. No script, no external resource.

use super::time::parse_utc;
use super::RunRow;
use std::collections::BTreeMap;
use std::fmt::Write;

/// Default alarm: a change of the identified position error between two runs, µm.
pub const DEFAULT_ALARM_UM: f64 = 5.0;
/// Default alarm: a change of an identified orientation error, arcsec.
pub const DEFAULT_ALARM_ARCSEC: f64 = 10.0;

/// A change between two consecutive runs larger than this is marked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alarm {
    pub um: f64,
    pub arcsec: f64,
}

impl Default for Alarm {
    fn default() -> Self {
        Self {
            um: DEFAULT_ALARM_UM,
            arcsec: DEFAULT_ALARM_ARCSEC,
        }
    }
}

/// Where a page takes its style sheet from: inline (a file carried away) or a fixed
/// URL of the web face (its Content-Security-Policy allows no inline style).
#[derive(Clone, Copy, Debug)]
pub enum Style<'a> {
    Inline,
    Linked(&'a str),
}

/// The style sheet of the trend and status pages.
pub const CSS: &str = "body{font-family:sans-serif;margin:1em;color:#222}\
h1{font-size:22px}h2{font-size:18px;margin-top:1.2em}\
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}\
th{background:#eee}td.l,th.l{text-align:left}tr.alarm td{background:#fde2e0}tr.out td{background:#fff1c2}\
.headline{font-size:17px;padding:0.4em 0.6em;border-left:5px solid #888;background:#f4f4f4}\
.headline.alarm{border-color:#d10000;background:#fde2e0}\
.chart{display:flex;align-items:flex-start;gap:1em;margin:0.6em 0}\
.stats{font-size:14px;min-width:17em;line-height:1.5}.stats .value{font-size:20px;font-weight:bold}\
.ok{color:#1e7a3e}.bad{color:#b00000;font-weight:bold}\
svg text{font-size:11px;fill:#333}svg .title{font-size:14px;font-weight:bold}\
.frame{fill:none;stroke:#888}.grid{stroke:#e6e6e6}.zero{stroke:#999}\
.line{fill:none;stroke-width:2}.line.before{stroke:#c0392b;stroke-dasharray:5 3}.line.after{stroke:#1e8449}\
.pt.before{fill:#c0392b}.pt.after{fill:#1e8449}\
.tol{fill:none;stroke:#e67e22;stroke-width:1.5;stroke-dasharray:7 4}svg .arrow{fill:#c25e00;font-weight:bold;paint-order:stroke;stroke:#fff;stroke-width:3px}\
.alarm-ring{fill:none;stroke:#d10000;stroke-width:2.5}svg .alarm-label{fill:#d10000;font-weight:bold;paint-order:stroke;stroke:#fff;stroke-width:3px}\
.swatch{display:inline-block;width:2em;height:0;border-top:3px solid;vertical-align:middle;margin-right:0.3em}\
.swatch.before{border-color:#c0392b;border-top-style:dashed}.swatch.after{border-color:#1e8449}\
.swatch.tol{border-color:#e67e22;border-top-style:dashed}\
.status td{text-align:left}nav a{margin-right:1em}";

const W: f64 = 620.0;
const H: f64 = 230.0;
const LEFT: f64 = 72.0;
const RIGHT: f64 = 16.0;
const TOP: f64 = 30.0;
const BOTTOM: f64 = 50.0;
/// The smallest y span shown (µm or arcsec): noise of a tenth stays small.
const MIN_SPAN: f64 = 2.0;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Unit {
    Um,
    Arcsec,
}

impl Unit {
    /// ISO 230-7: `E` + the error's direction + `0` + the axis; X/Y/Z are positions
    /// (mm), A/B/C orientations (deg).
    fn of_error(name: &str) -> Self {
        match name.as_bytes().get(1) {
            Some(b'X' | b'Y' | b'Z') => Unit::Um,
            _ => Unit::Arcsec,
        }
    }
    /// From the stored unit (mm, deg).
    fn scale(self) -> f64 {
        match self {
            Unit::Um => 1000.0,
            Unit::Arcsec => 3600.0,
        }
    }
    fn label(self) -> &'static str {
        match self {
            Unit::Um => "µm",
            Unit::Arcsec => "arcsec",
        }
    }
    fn threshold(self, a: &Alarm) -> f64 {
        match self {
            Unit::Um => a.um,
            Unit::Arcsec => a.arcsec,
        }
    }
}

/// One run's values of one series, in the series' unit.
#[derive(Clone, Debug)]
struct Point {
    run: i64,
    started: String,
    t: Option<i64>,
    before: f64,
    after: f64,
    /// maxModification in the series' unit (errors only).
    tol: Option<f64>,
}

#[derive(Clone, Debug)]
struct Series {
    title: String,
    unit: Unit,
    points: Vec<Point>,
}

/// What a series says about its runs.
#[derive(Clone, Debug)]
struct Verdict {
    /// Change of the identified value since the previous run.
    change: Option<f64>,
    /// Since the first run shown.
    drift: f64,
    /// Indices of the runs whose change exceeds the alarm.
    alarms: Vec<usize>,
    /// The latest correction (after - before) within maxModification.
    in_tolerance: Option<bool>,
    threshold: f64,
}

impl Series {
    fn verdict(&self, alarm: &Alarm) -> Verdict {
        let threshold = self.unit.threshold(alarm);
        let p = &self.points;
        let alarms = (1..p.len())
            .filter(|&i| (p[i].after - p[i - 1].after).abs() > threshold)
            .collect();
        let last = p.last();
        Verdict {
            change: (p.len() >= 2).then(|| p[p.len() - 1].after - p[p.len() - 2].after),
            drift: match (p.first(), last) {
                (Some(a), Some(b)) => b.after - a.after,
                _ => 0.0,
            },
            alarms,
            in_tolerance: last.and_then(|l| l.tol.map(|t| (l.after - l.before).abs() <= t)),
            threshold,
        }
    }

    /// How strongly it moved, in alarms: the order of the summary.
    fn weight(&self, v: &Verdict) -> f64 {
        v.drift.abs().max(v.change.unwrap_or(0.0).abs()) / v.threshold.max(1e-12)
    }
}

/// The machines of the history with a completed run, in order: the index's pages.
pub fn machines(runs: &[RunRow]) -> Vec<String> {
    let set: std::collections::BTreeSet<&str> = runs
        .iter()
        .filter(|r| r.status == "done")
        .map(|r| r.machine.as_str())
        .collect();
    set.into_iter().map(str::to_string).collect()
}

/// The page for the whole history with the default alarm, inline style: the machine's
/// page if it holds one machine, else the index (linking `trend-N.html`).
pub fn trend_html(runs: &[RunRow]) -> String {
    let pages = trend_pages(runs, &Alarm::default(), "trend");
    pages.into_iter().next().map(|p| p.1).unwrap_or_default()
}

/// The files of `history --html STEM.html`: `(file name, page)`; the first is
/// `STEM.html` (the machine's page, or the index of several machines, each on
/// `STEM-N.html`).
pub fn trend_pages(runs: &[RunRow], alarm: &Alarm, stem: &str) -> Vec<(String, String)> {
    let names = machines(runs);
    if names.len() <= 1 {
        let name = names.first().map_or("", String::as_str);
        return vec![(
            format!("{stem}.html"),
            machine_page(runs, name, alarm, Style::Inline, None),
        )];
    }
    let href = |i: usize| format!("{stem}-{}.html", i + 1);
    let index_href = format!("{stem}.html");
    let mut pages = vec![(
        index_href.clone(),
        index_page(runs, alarm, Style::Inline, &href),
    )];
    for (i, m) in names.iter().enumerate() {
        pages.push((
            href(i),
            machine_page(runs, m, alarm, Style::Inline, Some(&index_href)),
        ));
    }
    pages
}

fn head(html: &mut String, title: &str, style: Style) {
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>",
        escape(title)
    );
    match style {
        Style::Inline => {
            let _ = write!(html, "<style>{CSS}</style>");
        }
        Style::Linked(href) => {
            let _ = write!(html, "<link rel=\"stylesheet\" href=\"{}\">", escape(href));
        }
    }
    html.push_str("</head><body>\n");
}

/// The index of several machines: per machine its runs, latest run, the errors out
/// of tolerance and the alarms of its latest run; `href(i)` links machine `i` of
/// [`machines`].
pub fn index_page(
    runs: &[RunRow],
    alarm: &Alarm,
    style: Style,
    href: &dyn Fn(usize) -> String,
) -> String {
    let mut html = String::new();
    head(
        &mut html,
        "probebridge: calibration trend, all machines",
        style,
    );
    html.push_str("<h1>Calibration trend: all machines</h1>\n<table class=\"index\"><tr><th class=\"l\">machine</th><th>runs of cycle 451</th><th class=\"l\">latest run</th><th class=\"l\">outside maxModification</th><th class=\"l\">alarms in the latest run</th><th class=\"l\">largest drift</th></tr>\n");
    for (i, m) in machines(runs).iter().enumerate() {
        let series = collect(runs, m);
        let done: Vec<&RunRow> = done_runs(runs, m).collect();
        let latest = done.last().map_or("", |r| r.started.as_str());
        let mut out = Vec::new();
        let mut alarms = Vec::new();
        let mut largest: Option<(f64, String)> = None;
        for s in &series {
            let v = s.verdict(alarm);
            if v.in_tolerance == Some(false) {
                out.push(s.title.clone());
            }
            if v.alarms.last().is_some_and(|&a| a + 1 == s.points.len()) {
                alarms.push(s.title.clone());
            }
            let w = s.weight(&v);
            if largest.as_ref().is_none_or(|(lw, _)| w > *lw) {
                largest = Some((
                    w,
                    format!("{} {} {}", s.title, signed(v.drift), s.unit.label()),
                ));
            }
        }
        let row_class = if !alarms.is_empty() {
            " class=\"alarm\""
        } else if !out.is_empty() {
            " class=\"out\""
        } else {
            ""
        };
        let _ = writeln!(
            html,
            "<tr{row_class}><td class=\"l\"><a href=\"{}\">{}</a></td><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
            escape(&href(i)),
            escape(m),
            done.iter().filter(|r| !r.iso_errors.is_empty()).count(),
            escape(latest),
            if out.is_empty() { "none".into() } else { escape(&out.join(", ")) },
            if alarms.is_empty() { "none".into() } else { escape(&alarms.join(", ")) },
            largest.map_or(String::new(), |l| escape(&l.1)),
        );
    }
    html.push_str("</table>\n</body></html>\n");
    html
}

fn done_runs<'a>(runs: &'a [RunRow], machine: &'a str) -> impl Iterator<Item = &'a RunRow> {
    runs.iter()
        .filter(move |r| r.status == "done" && r.machine == machine)
}

/// The errors (by ISO name) and dispersions (by axis) of `machine`'s completed runs.
fn collect(runs: &[RunRow], machine: &str) -> Vec<Series> {
    let mut errors: BTreeMap<&str, Vec<Point>> = BTreeMap::new();
    let mut dispersion: BTreeMap<&str, Vec<Point>> = BTreeMap::new();
    for r in done_runs(runs, machine) {
        let point = |unit: Unit, before: f64, after: f64, tol: Option<f64>| Point {
            run: r.id,
            started: r.started.clone(),
            t: parse_utc(&r.started),
            before: before * unit.scale(),
            after: after * unit.scale(),
            tol: tol.map(|t| t * unit.scale()),
        };
        for e in &r.iso_errors {
            let u = Unit::of_error(&e.name);
            errors.entry(&e.name).or_default().push(point(
                u,
                e.before,
                e.after,
                r.max_modification,
            ));
        }
        for d in &r.dispersion {
            // Dispersion is a length (mm).
            dispersion
                .entry(&d.axis)
                .or_default()
                .push(point(Unit::Um, d.before, d.after, None));
        }
    }
    let errors = errors.into_iter().map(|(name, points)| Series {
        title: name.to_string(),
        unit: Unit::of_error(name),
        points,
    });
    let dispersion = dispersion.into_iter().map(|(axis, points)| Series {
        title: format!("dispersion {axis}"),
        unit: Unit::Um,
        points,
    });
    errors.chain(dispersion).collect()
}

/// The page of one machine; `index`: the link back to the index of several machines.
pub fn machine_page(
    runs: &[RunRow],
    machine: &str,
    alarm: &Alarm,
    style: Style,
    index: Option<&str>,
) -> String {
    let mut html = String::new();
    head(
        &mut html,
        &format!("probebridge: calibration trend of {machine}"),
        style,
    );
    if let Some(href) = index {
        let _ = writeln!(
            html,
            "<nav><a href=\"{}\">all machines</a></nav>",
            escape(href)
        );
    }
    let series = collect(runs, machine);
    let n451 = done_runs(runs, machine)
        .filter(|r| !r.iso_errors.is_empty())
        .count();
    let _ = writeln!(
        html,
        "<h1>Calibration trend: {}</h1>\n<p>{n451} completed run(s) of cycle 451. Alarm: a change between two runs of more than {} µm (position, dispersion) or {} arcsec (orientation). Tolerance: maxModification about the kinematics in use, the largest correction cycle 451 writes without confirmation.</p>",
        escape(machine),
        num(alarm.um),
        num(alarm.arcsec),
    );
    if series.is_empty() {
        html.push_str(
            "<p class=\"headline\">No completed cycle 451 run recorded.</p>\n</body></html>\n",
        );
        return html;
    }
    let mut rows: Vec<(usize, &Series, Verdict)> = series
        .iter()
        .enumerate()
        .map(|(i, s)| (i, s, s.verdict(alarm)))
        .collect();
    // The summary lists the errors that moved most (in alarms) first; stable otherwise.
    rows.sort_by(|a, b| b.1.weight(&b.2).total_cmp(&a.1.weight(&a.2)));
    headline(&mut html, &rows);
    summary(&mut html, &rows);
    html.push_str("<p><span class=\"swatch before\"></span>before optimisation (kinematics in use) <span class=\"swatch after\"></span>after optimisation (identified by cycle 451) <span class=\"swatch tol\"></span>tolerance (maxModification)</p>\n");
    let (errs, disp): (Vec<_>, Vec<_>) = rows
        .iter()
        .partition(|(_, s, _)| !s.title.starts_with("dispersion "));
    if !errs.is_empty() {
        html.push_str("<h2>ISO 230-7 errors identified by cycle 451</h2>\n");
        for (i, s, v) in errs {
            chart(&mut html, *i, s, v);
        }
    }
    if !disp.is_empty() {
        html.push_str("<h2>Dispersion per rotary axis</h2>\n");
        for (i, s, v) in disp {
            chart(&mut html, *i, s, v);
        }
    }
    html.push_str("</body></html>\n");
    html
}

/// One sentence: which error moved most, by how much since the previous run, and
/// whether it is in tolerance.
fn headline(html: &mut String, rows: &[(usize, &Series, Verdict)]) {
    let Some((_, s, v)) = rows.first() else {
        return;
    };
    let (Some(first), Some(last)) = (s.points.first(), s.points.last()) else {
        return;
    };
    let u = s.unit.label();
    let alarm = !v.alarms.is_empty();
    let _ = write!(
        html,
        "<p class=\"headline{}\" id=\"headline\"><b>{}</b> moved most: <b>{} {u}</b> over {} run(s) since {}",
        if alarm { " alarm" } else { "" },
        escape(&s.title),
        signed(v.drift),
        s.points.len(),
        escape(&date(&first.started)),
    );
    if let (Some(c), Some(prev)) = (v.change, s.points.iter().rev().nth(1)) {
        let _ = write!(
            html,
            ", <b>{} {u}</b> since the previous run ({})",
            signed(c),
            escape(&date(&prev.started))
        );
    }
    let _ = write!(html, "; latest {} {u}", signed(last.after));
    match v.in_tolerance {
        Some(true) => html.push_str(", <span class=\"ok\">in tolerance</span>"),
        Some(false) => html.push_str(", <span class=\"bad\">OUT OF TOLERANCE</span>"),
        None => {}
    }
    if alarm {
        html.push_str(", <span class=\"bad\">alarm</span>");
    }
    html.push_str(".</p>\n");
}

fn summary(html: &mut String, rows: &[(usize, &Series, Verdict)]) {
    html.push_str("<table class=\"summary\"><tr><th class=\"l\">error</th><th>latest (after optimisation)</th><th>change since the previous run</th><th>change over the runs shown</th><th>correction / tolerance</th><th class=\"l\">state</th></tr>\n");
    for (i, s, v) in rows {
        let u = s.unit.label();
        let Some(last) = s.points.last() else {
            continue;
        };
        let last_alarm = v.alarms.last().is_some_and(|&a| a + 1 == s.points.len());
        let class = if last_alarm {
            " class=\"alarm\""
        } else if v.in_tolerance == Some(false) {
            " class=\"out\""
        } else {
            ""
        };
        let tol = match last.tol {
            Some(t) => format!(
                "{} of &#177;{} {u}",
                signed(last.after - last.before),
                plain(t)
            ),
            None => "no tolerance".into(),
        };
        let mut state = Vec::new();
        match v.in_tolerance {
            Some(true) => state.push("<span class=\"ok\">in tolerance</span>".to_string()),
            Some(false) => state.push("<span class=\"bad\">out of tolerance</span>".into()),
            None => {}
        }
        if last_alarm {
            state.push(format!(
                "<span class=\"bad\">alarm: changed by more than {} {u}</span>",
                num(v.threshold)
            ));
        } else if !v.alarms.is_empty() {
            state.push(format!("alarm in {} earlier run(s)", v.alarms.len()));
        }
        if state.is_empty() {
            state.push("ok".into());
        }
        let _ = writeln!(
            html,
            "<tr{class} data-series=\"{i}\"><td class=\"l\"><a href=\"#chart-{i}\">{}</a></td><td>{} {u}</td><td>{}</td><td>{} {u}</td><td>{tol}</td><td class=\"l\">{}</td></tr>",
            escape(&s.title),
            signed(last.after),
            v.change.map_or("first run".into(), |c| format!("{} {u}", signed(c))),
            signed(v.drift),
            state.join(", "),
        );
    }
    html.push_str("</table>\n");
}

/// The y view: fitted to the data, widened to a tolerance line only when it is near.
fn y_range(s: &Series) -> (f64, f64) {
    let vals = s.points.iter().flat_map(|p| [p.before, p.after]);
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

/// 1, 2 or 5 times a power of ten, about a fifth of the span.
fn tick_step(span: f64) -> f64 {
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
fn tick_label(v: f64, step: f64) -> String {
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
fn signed(v: f64) -> String {
    let s = format!("{v:+.1}");
    if s == "-0.0" || s == "+0.0" {
        "0.0".into()
    } else {
        s
    }
}

fn plain(v: f64) -> String {
    format!("{v:.1}")
}

/// A configured number as typed (5, 2.5).
fn num(v: f64) -> String {
    format!("{v}")
}

/// `2026-11-25T08:00:00Z` -> `2026-11-25 08:00`.
fn date(stamp: &str) -> String {
    if parse_utc(stamp).is_some() {
        format!("{} {}", &stamp[..10], &stamp[11..16])
    } else {
        stamp.to_string()
    }
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

fn chart(html: &mut String, idx: usize, s: &Series, v: &Verdict) {
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
        "<div class=\"stats\"><div>latest ({}):</div><div class=\"value latest\">{} {u}</div><div>before optimisation {} {u}</div>",
        escape(&date(&last.started)),
        signed(last.after),
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

/// Text and attribute values: every character that could end either is a reference.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if c.is_control() => {
                let _ = write!(out, "&#xFFFD;");
            }
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::{DispersionRow, IsoErrorRow};

    /// Runs a week apart; `ex0c(i)` the identified EX0C of run i (mm).
    fn runs(machine: &str, n: usize, ex0c: impl Fn(usize) -> f64) -> Vec<RunRow> {
        (0..n)
            .map(|i| RunRow {
                id: i as i64 + 1,
                started: super::super::time::format_utc(1_793_000_000 + 7 * 86_400 * i as u64),
                finished: None,
                machine: machine.into(),
                source: "serve".into(),
                request_seq: Some(i as u16),
                program_number: Some(451),
                program: "451.h".into(),
                status: "done".into(),
                message: None,
                protocols: vec![],
                results: vec![],
                iso_errors: vec![
                    IsoErrorRow {
                        block: 11,
                        name: "EX0C".into(),
                        before: 0.0,
                        after: ex0c(i),
                    },
                    IsoErrorRow {
                        block: 11,
                        name: "EB0C".into(),
                        before: 0.0,
                        after: 0.0001,
                    },
                ],
                max_modification: Some(0.03),
                parameters: vec![],
                dispersion: vec![DispersionRow {
                    block: 11,
                    axis: "C".into(),
                    before: 0.002,
                    after: 0.0005,
                }],
            })
            .collect()
    }

    #[test]
    fn charts_have_units_two_series_and_the_drift_first() {
        let html = trend_html(&runs("table-ac", 5, |i| 0.012 + 0.004 * i as f64));
        assert_eq!(html.matches("<svg class=\"trend\"").count(), 3);
        // Before and after: two points per run.
        assert_eq!(html.matches("class=\"pt before\"").count(), 15);
        assert_eq!(html.matches("class=\"pt after\"").count(), 15);
        assert!(html.contains("EX0C (µm)") && html.contains("EB0C (arcsec)"));
        // The drifting error heads the summary and the headline: +16 µm, +4 since
        // last week, within the 30 µm maxModification.
        let headline = &html[html.find("id=\"headline\"").unwrap()..];
        let headline = &headline[..headline.find("</p>").unwrap()];
        assert!(headline.contains("<b>EX0C</b>"), "{headline}");
        assert!(headline.contains("+16.0 µm") && headline.contains("+4.0 µm"));
        assert!(headline.contains("in tolerance"), "{headline}");
        let summary = &html[html.find("class=\"summary\"").unwrap()..];
        assert!(summary.find("EX0C").unwrap() < summary.find("EB0C").unwrap());
        // Dated time axis, a tick per run.
        assert_eq!(html.matches("class=\"xtick\"").count() % 3, 0);
        assert!(html.contains("run start (UTC), 2026"));
        assert!(!html.contains("-0.0") && !html.contains(">-0<"));
    }

    #[test]
    fn the_alarm_marks_exactly_the_run_that_crossed_the_threshold() {
        // Steps of 2 µm, then 8 µm between runs 3 and 4 (ids 4 and 5).
        let values = [0.010, 0.012, 0.014, 0.016, 0.024];
        let html = trend_html(&runs("table-ac", 5, |i| values[i]));
        assert_eq!(html.matches("class=\"alarm-ring\"").count(), 1, "{html}");
        assert!(html.contains("class=\"alarm-ring\" data-run=\"5\""));
        assert!(html.contains("<tr class=\"alarm\" data-series=\"1\">"));
    }

    #[test]
    fn tolerance_lines_far_away_become_an_arrow_with_the_distance() {
        let mut r = runs("table-ac", 3, |i| 0.001 * i as f64);
        for run in &mut r {
            run.max_modification = Some(0.5);
        }
        let html = trend_html(&r);
        // EX0C: data 0..2 µm, tolerance 500 µm: arrows, no line in view needed.
        assert!(html.contains("tolerance +500.0 µm"), "{html}");
        assert!(html.contains("above the view") && html.contains("below the view"));
    }

    #[test]
    fn ticks_are_round_and_never_minus_zero() {
        assert_eq!(tick_step(10.0), 2.0);
        assert_eq!(tick_step(0.9), 0.2);
        assert_eq!(tick_label(-0.00001, 0.2), "0");
        assert_eq!(tick_label(-0.4, 0.2), "-0.4");
        assert_eq!(tick_label(12.0, 5.0), "12");
    }

    #[test]
    fn stored_names_with_markup_stay_text_in_attributes_too() {
        let evil = "EX0C\" onload=\"alert(1)\"><script>alert(2)</script>";
        let mut r = runs("m\"><img src=x onerror=alert(3)>", 2, |_| 0.0);
        for run in &mut r {
            run.iso_errors[0].name = evil.into();
            run.dispersion[0].axis = "C' onmouseover='alert(4)".into();
            run.started = "2026-11-25\"><script>x</script>".into();
        }
        let html = trend_html(&r);
        for bad in ["<script", "onload=\"", "<img", "alert(3)>", "onmouseover='"] {
            assert!(!html.contains(bad), "{bad} in {html}");
        }
        assert!(html.contains("EX0C&quot; onload=&quot;alert(1)&quot;&gt;&lt;script&gt;"));
    }

    #[test]
    fn several_machines_get_an_index_and_a_page_each() {
        let mut r = runs("table-ac", 3, |i| 0.001 * i as f64);
        r.extend(runs("head-bc", 3, |_| 0.0));
        let pages = trend_pages(&r, &Alarm::default(), "trend");
        let names: Vec<&str> = pages.iter().map(|p| p.0.as_str()).collect();
        assert_eq!(names, ["trend.html", "trend-1.html", "trend-2.html"]);
        assert!(pages[0].1.contains("href=\"trend-1.html\">head-bc<"));
        assert!(pages[2].1.contains("Calibration trend: table-ac"));
        assert!(pages[2].1.contains("href=\"trend.html\">all machines"));
    }
}
