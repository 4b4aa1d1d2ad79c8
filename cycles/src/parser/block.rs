//! The block grammar: groups lines into blocks (`~` continues a block, a cycle's
//! parameter lines belong to it) and reports continuation errors at their lines.

use super::lexer::{is_cycle_head, is_param_line, iso_cycle_number, split_line, upper_words, Line};
use crate::diagnostic::Diagnostic;
use crate::params;

#[derive(Clone, Copy, Debug)]
pub(super) struct ParamLine<'a> {
    pub(super) no: usize,
    pub(super) code: &'a str,
    pub(super) comment: Option<&'a str>,
}

#[derive(Debug)]
pub(super) struct RawBlock<'a> {
    pub(super) head: Line<'a>,
    pub(super) body: Vec<ParamLine<'a>>,
    /// The last line read ended with `~`.
    pub(super) open: bool,
    pub(super) last_line: usize,
    /// The last line's comment (for the seed layout where the comment with its `~`
    /// stands on its own line after the value).
    pub(super) last_has_comment: bool,
    pub(super) is_cycle: bool,
}

/// Groups lines into blocks; reports continuation errors.
pub(super) fn group<'a>(text: &'a str, diags: &mut Vec<Diagnostic>) -> Vec<RawBlock<'a>> {
    let mut blocks: Vec<RawBlock> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = split_line(i + 1, raw);
        if line.is_blank() {
            continue;
        }
        if let Some(cur) = blocks.last_mut() {
            let comment_only = line.code.is_empty() && line.number.is_none();
            if cur.open && starts_block(&line) {
                // Continuation lines never carry a block number or a block keyword.
                diags.push(Diagnostic {
                    line: cur.last_line,
                    message: format!(
                        "the line ends with \"~\" but line {} starts a new block",
                        line.no
                    ),
                });
                cur.open = false;
            } else if cur.open || (comment_only && cur.is_cycle && !cur.last_has_comment) {
                if comment_only {
                    // A comment (and maybe the `~`) belonging to the line before.
                    if let Some(last) = cur.body.last_mut() {
                        last.comment = line.comment;
                    }
                    cur.last_has_comment = true;
                } else {
                    cur.body.push(ParamLine {
                        no: line.no,
                        code: line.code,
                        comment: line.comment,
                    });
                    cur.last_has_comment = line.comment.is_some();
                }
                cur.open = line.cont;
                cur.last_line = line.no;
                continue;
            }
            let name = line
                .code
                .split('=')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_uppercase();
            if line.number.is_none()
                && is_param_line(line.code)
                && cur.is_cycle
                && cycle_takes(cur.head.code, &name)
            {
                diags.push(Diagnostic {
                    line: cur.last_line,
                    message: format!(
                        "missing continuation \"~\": the block ends here but line {} continues it with {name}",
                        line.no
                    ),
                });
                // Keep the parameter in its block so that it is not also reported
                // missing.
                cur.body.push(ParamLine {
                    no: line.no,
                    code: line.code,
                    comment: line.comment,
                });
                cur.open = line.cont;
                cur.last_line = line.no;
                cur.last_has_comment = line.comment.is_some();
                continue;
            }
        }
        // `Q1 = 5` on its own is an assignment; `Q263=+0 Q264=+0` is a cycle's.
        if line.number.is_none()
            && is_param_line(line.code)
            && !matches!(crate::flow_block::parse_flow(line.code), Some(Ok(_)))
        {
            diags.push(Diagnostic {
                line: line.no,
                message: "parameter line outside a cycle block (expected a TCH PROBE or G4xx block before it, its lines ending with \"~\")".into(),
            });
            continue;
        }
        let is_cycle = is_cycle_head(line.code);
        blocks.push(RawBlock {
            head: line,
            body: Vec::new(),
            open: line.cont,
            last_line: line.no,
            last_has_comment: line.comment.is_some(),
            is_cycle,
        });
    }
    if let Some(last) = blocks.last() {
        if last.open {
            diags.push(Diagnostic {
                line: last.last_line,
                message: "the block continues with \"~\" but the program ends".into(),
            });
        }
    }
    blocks
}

/// A line that can only be the start of a block.
pub(super) fn starts_block(line: &Line) -> bool {
    let w = upper_words(line.code);
    let first_two = (w.first().map(String::as_str), w.get(1).map(String::as_str));
    line.number.is_some()
        || is_cycle_head(line.code)
        || matches!(
            first_two,
            (Some("TOOL"), Some("CALL")) | (Some("BEGIN" | "END"), Some("PGM"))
        )
}

/// Whether the cycle block starting with `head` takes parameter `name` (so that a
/// `Qn=` line after it without `~` is its forgotten continuation, not a formula).
pub(super) fn cycle_takes(head: &str, name: &str) -> bool {
    let w = upper_words(head);
    let number = match (w.first().map(String::as_str), w.get(1).map(String::as_str)) {
        (Some("TCH"), Some("PROBE")) | (Some("CYCL"), Some("DEF")) => {
            w.get(2).and_then(|n| n.parse::<u16>().ok())
        }
        (Some("G247"), _) => Some(247),
        _ => iso_cycle_number(head),
    };
    match number {
        Some(247) => name == "Q339",
        Some(n) => params::table(n).is_some_and(|t| t.param(name).is_some()),
        None => false,
    }
}
