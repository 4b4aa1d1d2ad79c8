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

mod alarm;
mod chart;
mod page;
mod series;
mod style;
mod text;

pub use alarm::{Alarm, DEFAULT_ALARM_ARCSEC, DEFAULT_ALARM_UM};
pub use page::{index_page, machine_page};
pub use series::machines;
pub use style::{escape, Style, CSS};

use super::RunRow;
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

#[cfg(test)]
mod tests {
    use super::text::{tick_label, tick_step};
    use super::*;
    use crate::history::{DispersionRow, IsoErrorRow, RunStatus};

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
                status: RunStatus::Done,
                message: None,
                protocols: vec![],
                results: vec![],
                iso_errors: vec![
                    IsoErrorRow {
                        block: 11,
                        name: "EX0C".into(),
                        before: 0.0,
                        after: ex0c(i),
                        u: None,
                    },
                    IsoErrorRow {
                        block: 11,
                        name: "EB0C".into(),
                        before: 0.0,
                        after: 0.0001,
                        u: None,
                    },
                ],
                max_modification: Some(0.03),
                machine_time_s: Some(400.0 + i as f64),
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
        // How long the runs kept the machine: the latest (404 s) and the range.
        assert!(
            html.contains("Machine time of the latest run: <b>404.0 s</b> (5 run(s) with a machine time: 400.0 .. 404.0 s)"),
            "{html}"
        );
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

    #[test]
    fn error_bars_and_a_change_beyond_two_combined_uncertainties() {
        // EX0C 10, 10.5, 13 µm with u = 0.5 µm: 0.5 µm is noise (2 u_c = 1.41 µm),
        // 2.5 µm is a change, below the 5 µm alarm.
        let values = [0.010, 0.0105, 0.013];
        let mut r = runs("table-ac", 3, |i| values[i]);
        for run in &mut r {
            run.iso_errors[0].u = Some(0.0005);
        }
        let html = trend_html(&r);
        assert_eq!(html.matches("class=\"ebar\"").count(), 3, "{html}");
        assert!(
            html.contains("+10.0 ± 0.50 µm (standard uncertainty, k = 1)"),
            "{html}"
        );
        assert_eq!(
            html.matches("class=\"moved\" data-run").count(),
            1,
            "{html}"
        );
        assert!(html.contains("class=\"moved\" data-run=\"3\""));
        assert!(html.contains("more than 2 combined standard uncertainties (2 u_c = 1.4 µm)"));
        assert_eq!(html.matches("class=\"alarm-ring\"").count(), 0);
        assert!(
            html.contains("+13.0 &#177; 0.50"),
            "the summary's latest value with u"
        );
        // Without uncertainties (runs recorded before them): no bars, no marks.
        let html = trend_html(&runs("table-ac", 3, |i| values[i]));
        assert!(!html.contains("class=\"ebar\"") && !html.contains("class=\"moved\" data-run"));
    }
}
