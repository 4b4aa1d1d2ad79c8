//! The pages: the index of several machines, and a machine's page with its headline,
//! summary table and charts.

use super::super::RunRow;
use super::alarm::Alarm;
use super::chart::chart;
use super::series::{collect, done_runs, machines, Series, SeriesKind, Verdict};
use super::style::{escape, head, Style};
use super::text::{date, num, plain, plain_u, signed};
use std::fmt::Write;

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
    machine_time(&mut html, runs, machine);
    summary(&mut html, &rows);
    html.push_str("<p><span class=\"swatch before\"></span>before optimisation (kinematics in use) <span class=\"swatch after\"></span>after optimisation (identified by cycle 451) <span class=\"swatch tol\"></span>tolerance (maxModification) <span class=\"swatch ebar\"></span>&#177; standard uncertainty (k = 1) <span class=\"swatch moved\"></span>changed by more than 2 combined standard uncertainties since the previous run</p>\n");
    let (errs, disp): (Vec<_>, Vec<_>) = rows
        .iter()
        .partition(|(_, s, _)| s.kind == SeriesKind::Error);
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

/// How long the 451 runs kept the machine: the latest, and the range of the runs shown.
fn machine_time(html: &mut String, runs: &[RunRow], machine: &str) {
    let times: Vec<f64> = done_runs(runs, machine)
        .filter(|r| !r.iso_errors.is_empty())
        .filter_map(|r| r.machine_time_s)
        .collect();
    let Some(latest) = times.last() else {
        return;
    };
    let (lo, hi) = times
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), t| {
            (l.min(*t), h.max(*t))
        });
    let _ = writeln!(
        html,
        "<p id=\"machine-time\">Machine time of the latest run: <b>{latest:.1} s</b> ({} run(s) with a machine time: {lo:.1} .. {hi:.1} s).</p>",
        times.len()
    );
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
        if v.moved.last().is_some_and(|&a| a + 1 == s.points.len()) {
            state.push(
                "<span class=\"moved\">changed by more than 2 combined uncertainties</span>".into(),
            );
        }
        if state.is_empty() {
            state.push("ok".into());
        }
        let _ = writeln!(
            html,
            "<tr{class} data-series=\"{i}\"><td class=\"l\"><a href=\"#chart-{i}\">{}</a></td><td>{} {u}</td><td>{}</td><td>{} {u}</td><td>{tol}</td><td class=\"l\">{}</td></tr>",
            escape(&s.title),
            with_u(last.after, last.u),
            v.change.map_or("first run".into(), |c| format!("{} {u}", signed(c))),
            signed(v.drift),
            state.join(", "),
        );
    }
    html.push_str("</table>\n");
}

/// A value with its standard uncertainty when recorded (`+12.0 &#177; 0.45`).
fn with_u(v: f64, u: Option<f64>) -> String {
    match u {
        Some(u) => format!("{} &#177; {}", signed(v), plain_u(u)),
        None => signed(v),
    }
}
