//! The pages' style sheet and head, and the escaping of every stored string.

use std::fmt::Write;

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
.status td{text-align:left}nav a{margin-right:1em}\
.ebar{fill:none;stroke:#1e8449;stroke-width:1.2}.moved{fill:none;stroke:#6c3483;stroke-width:2}\
.stats .moved{color:#6c3483;font-weight:bold}.swatch.ebar{border-color:#1e8449;border-top-width:1px;width:0.6em}\
.swatch.moved{border:2px solid #6c3483;width:0.7em;height:0.7em;vertical-align:middle}";

pub(super) fn head(html: &mut String, title: &str, style: Style) {
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
