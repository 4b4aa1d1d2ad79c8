//! candump's log format (`candump -L`, read back by `canplayer`), for recording CAN
//! traffic and replaying it in tests:
//!
//! ```text
//! (1700000000.123456) vcan0 181#0102030405060708
//! (1700000000.123999) vcan0 705#R1
//! ```
//!
//! Only classic 11-bit frames: that is all CANopen uses.

use super::CanFrame;

/// Where and why a log line does not parse. Columns count characters from 1.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}column {column}: {reason}", line.map(|l| format!("line {l}, ")).unwrap_or_default())]
pub struct CandumpError {
    /// 1-based line number (set by [`parse_log`]).
    pub line: Option<usize>,
    pub column: usize,
    pub reason: String,
}

fn err(column: usize, reason: impl Into<String>) -> CandumpError {
    CandumpError {
        line: None,
        column,
        reason: reason.into(),
    }
}

/// One log line, without the newline. The timestamp is printed in microseconds, as
/// candump does.
pub fn format_line(timestamp_ns: u64, iface: &str, frame: &CanFrame) -> String {
    let mut s = String::with_capacity(48);
    let _ = write_line(&mut s, timestamp_ns, iface, frame);
    s
}

/// [`format_line`] into any `fmt::Write`, without allocating (the recorder formats
/// into a stack buffer from the real-time thread).
pub fn write_line(
    w: &mut impl core::fmt::Write,
    timestamp_ns: u64,
    iface: &str,
    frame: &CanFrame,
) -> core::fmt::Result {
    let secs = timestamp_ns / 1_000_000_000;
    let micros = (timestamp_ns % 1_000_000_000) / 1_000;
    write!(w, "({secs}.{micros:06}) {iface} {:03X}#", frame.cob_id())?;
    if frame.is_rtr() {
        w.write_char('R')?;
        let dlc = embedded_can::Frame::dlc(frame);
        if dlc > 0 {
            write!(w, "{dlc}")?;
        }
    } else {
        for b in frame.data() {
            write!(w, "{b:02X}")?;
        }
    }
    Ok(())
}

/// Timestamp (ns), interface and frame of one log line.
pub fn parse_line(line: &str) -> Result<(u64, String, CanFrame), CandumpError> {
    let mut fields = Fields { line, pos: 0 };
    let (col, ts) = fields.next().ok_or_else(|| err(1, "empty line"))?;
    let timestamp_ns = parse_timestamp(ts, col)?;
    let (col, iface) = fields
        .next()
        .ok_or_else(|| err(line.len() + 1, "missing interface name"))?;
    if iface.starts_with('(') || iface.contains('#') {
        return Err(err(
            col,
            format!("expected an interface name, found {iface:?}"),
        ));
    }
    let (col, frame) = fields
        .next()
        .ok_or_else(|| err(line.len() + 1, "missing frame (ID#DATA)"))?;
    let frame = parse_frame(frame, col)?;
    // Newer can-utils append a direction flag (R = received, T = transmitted).
    if let Some((col, flag)) = fields.next() {
        if flag != "R" && flag != "T" {
            return Err(err(col, format!("unexpected {flag:?} after the frame")));
        }
        if let Some((col, extra)) = fields.next() {
            return Err(err(col, format!("unexpected {extra:?} after the frame")));
        }
    }
    Ok((timestamp_ns, iface.to_string(), frame))
}

/// All frames of a log; blank lines and lines starting with `#` are skipped.
pub fn parse_log(text: &str) -> Result<Vec<(u64, String, CanFrame)>, CandumpError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        out.push(parse_line(line).map_err(|mut e| {
            e.line = Some(i + 1);
            e
        })?);
    }
    Ok(out)
}

/// Whitespace-separated fields with their 1-based start column.
struct Fields<'a> {
    line: &'a str,
    pos: usize,
}

impl<'a> Iterator for Fields<'a> {
    type Item = (usize, &'a str);
    fn next(&mut self) -> Option<Self::Item> {
        let rest = &self.line[self.pos..];
        let start = self.pos + (rest.len() - rest.trim_start().len());
        let rest = &self.line[start..];
        if rest.is_empty() {
            self.pos = self.line.len();
            return None;
        }
        let len = rest.find(char::is_whitespace).unwrap_or(rest.len());
        self.pos = start + len;
        Some((self.line[..start].chars().count() + 1, &rest[..len]))
    }
}

fn parse_timestamp(s: &str, col: usize) -> Result<u64, CandumpError> {
    let inner = s
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| err(col, format!("expected (seconds.fraction), found {s:?}")))?;
    let (secs, frac) = inner
        .split_once('.')
        .ok_or_else(|| err(col + 1, "timestamp has no '.'"))?;
    let all_digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
    if !all_digits(secs) {
        return Err(err(col + 1, format!("seconds {secs:?} are not a number")));
    }
    let frac_col = col + 2 + secs.len();
    if !all_digits(frac) || frac.len() > 9 {
        return Err(err(
            frac_col,
            format!("fraction {frac:?} is not 1 to 9 digits"),
        ));
    }
    let secs: u64 = secs
        .parse()
        .map_err(|_| err(col + 1, "seconds out of range"))?;
    let mut ns: u64 = frac.parse().map_err(|_| err(frac_col, "bad fraction"))?;
    for _ in frac.len()..9 {
        ns *= 10;
    }
    secs.checked_mul(1_000_000_000)
        .and_then(|v| v.checked_add(ns))
        .ok_or_else(|| err(col + 1, "timestamp out of range"))
}

fn parse_frame(s: &str, col: usize) -> Result<CanFrame, CandumpError> {
    let (id, data) = s
        .split_once('#')
        .ok_or_else(|| err(col, format!("expected ID#DATA, found {s:?}")))?;
    if data.starts_with('#') {
        return Err(err(
            col + id.len() + 1,
            "CAN FD frames (##) are not supported",
        ));
    }
    match id.len() {
        3 => {}
        8 => return Err(err(col, "29-bit identifiers are not CANopen frames")),
        _ => return Err(err(col, format!("identifier {id:?} is not 3 hex digits"))),
    }
    let cob = u16::from_str_radix(id, 16)
        .ok()
        .filter(|&v| v <= 0x7FF)
        .ok_or_else(|| err(col, format!("identifier {id:?} is not 11-bit hex")))?;
    let data_col = col + id.len() + 1;
    if let Some(dlc) = data.strip_prefix('R') {
        let dlc = match dlc {
            "" => 0,
            d => d
                .parse::<u8>()
                .ok()
                .filter(|&v| v <= 8)
                .ok_or_else(|| err(data_col + 1, format!("remote DLC {d:?} is not 0..=8")))?,
        };
        return CanFrame::remote(cob, dlc).ok_or_else(|| err(col, "invalid remote frame"));
    }
    let mut bytes = [0u8; 8];
    let mut n = 0;
    let mut digits = data.char_indices().filter(|&(_, c)| c != '.');
    while let Some((i, hi)) = digits.next() {
        let Some((j, lo)) = digits.next() else {
            return Err(err(data_col + i, "odd number of hex digits"));
        };
        if n == 8 {
            return Err(err(data_col + i, "more than 8 data bytes"));
        }
        let nib = |k: usize, c: char| {
            c.to_digit(16)
                .ok_or_else(|| err(data_col + k, format!("{c:?} is not a hex digit")))
        };
        bytes[n] = (nib(i, hi)? << 4 | nib(j, lo)?) as u8;
        n += 1;
    }
    CanFrame::new(cob, &bytes[..n]).ok_or_else(|| err(col, "invalid frame"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let f = CanFrame::new(0x181, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        let line = format_line(1_700_000_000_123_456_000, "vcan0", &f);
        assert_eq!(line, "(1700000000.123456) vcan0 181#0102030405060708");
        assert_eq!(
            parse_line(&line).unwrap(),
            (1_700_000_000_123_456_000, "vcan0".to_string(), f)
        );
        let (_, _, r) = parse_line("(1.5) can0 123#R4").unwrap();
        assert_eq!(r, CanFrame::remote(0x123, 4).unwrap());
        assert_eq!(format_line(0, "can0", &r), "(0.000000) can0 123#R4");
        let (t, _, e) = parse_line("(1.5) can0 080# T").unwrap();
        assert_eq!((t, e), (1_500_000_000, CanFrame::new(0x80, &[]).unwrap()));
        let (_, _, d) = parse_line("(1.0) can0 181#01.02").unwrap();
        assert_eq!(d.data(), &[1, 2]);

        let e = parse_line("(1.0) can0 181#0G").unwrap_err();
        assert_eq!(e.column, 17);
        let e = parse_line("(1.0) can0 12345678#00").unwrap_err();
        assert_eq!(e.column, 12);
        let e = parse_line("(1,0) can0 181#00").unwrap_err();
        assert_eq!(e.column, 2);
        let e = parse_log("(1.0) can0 181#00\n\n(2.0) can0 181#000").unwrap_err();
        assert_eq!(e.line, Some(3));
        assert!(e.to_string().starts_with("line 3, column 18:"), "{e}");
    }
}
