//! The command lines of the pages' fenced shell blocks: split into words as the shell
//! does, the ones that run probebridge found, their arguments parsed with the CLI.

use super::markdown::{lines, Line};
use crate::Cli;
use clap::Parser;

/// Splits a shell line into words (quotes and backslashes as the shell reads them);
/// stops at a comment or an operator (`|`, `>`, `<`, `;`, `&`), since what follows is
/// another command.
pub(super) fn shell_words(line: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('\'') => break,
                        Some(x) => word.push(x),
                        None => return Err("unclosed ' quote".into()),
                    }
                }
            }
            '"' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('"') => break,
                        Some('\\') => match chars.next() {
                            Some(x @ ('"' | '\\' | '$' | '`')) => word.push(x),
                            Some(x) => {
                                word.push('\\');
                                word.push(x);
                            }
                            None => return Err("unclosed \" quote".into()),
                        },
                        Some(x) => word.push(x),
                        None => return Err("unclosed \" quote".into()),
                    }
                }
            }
            '\\' => {
                in_word = true;
                if let Some(x) = chars.next() {
                    word.push(x);
                }
            }
            '#' if !in_word => break,
            '|' | '>' | '<' | ';' | '&' => {
                // `2>&1`: the digits name a file descriptor, not an argument
                if in_word && !word.is_empty() && word.chars().all(|d| d.is_ascii_digit()) {
                    in_word = false;
                }
                break;
            }
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            c => {
                in_word = true;
                word.push(c);
            }
        }
    }
    if in_word {
        words.push(word);
    }
    Ok(words)
}

/// The arguments after the program name, if the words run probebridge.
pub(super) fn probebridge_args(words: &[String]) -> Option<Vec<String>> {
    let first = words.first()?;
    if first == "probebridge" || first.ends_with("/probebridge") {
        return Some(words[1..].to_vec());
    }
    let cargo_run = first == "cargo"
        && words.get(1).is_some_and(|w| w == "run")
        && words.windows(2).any(|w| {
            matches!(w[0].as_str(), "-p" | "--package" | "--bin") && w[1] == "probebridge"
        });
    if cargo_run {
        let dashes = words.iter().position(|w| w == "--")?;
        return Some(words[dashes + 1..].to_vec());
    }
    None
}

/// The command lines of a page's fenced shell blocks: (line number, the line as
/// written with `\` continuations joined). A block with `$ ` prompts shows commands only
/// on those lines (the rest is their output).
pub(super) fn fenced_commands(text: &str) -> Vec<(usize, String)> {
    let mut blocks: Vec<(&str, Vec<(usize, &str)>)> = Vec::new();
    let mut last = 0;
    for line in lines(text) {
        let Line::Fenced(n, info, l) = line else {
            continue;
        };
        if n != last + 1 || blocks.is_empty() {
            blocks.push((info, Vec::new()));
        }
        last = n;
        blocks.last_mut().expect("pushed").1.push((n, l));
    }
    let mut out = Vec::new();
    for (info, block) in blocks {
        let lang = info.split_whitespace().next().unwrap_or("");
        if !matches!(lang, "" | "sh" | "shell" | "bash" | "console" | "text") {
            continue;
        }
        let prompts = block.iter().any(|(_, l)| l.trim_start().starts_with("$ "));
        let mut pending: Option<(usize, String)> = None;
        for (n, l) in block {
            let l = l.trim();
            let (start, mut joined) = match pending.take() {
                Some((start, so_far)) => (start, so_far),
                None if prompts => match l.strip_prefix("$ ") {
                    Some(_) => (n, String::new()),
                    None => continue,
                },
                None => (n, String::new()),
            };
            let l = if joined.is_empty() {
                l.strip_prefix("$ ").unwrap_or(l)
            } else {
                l
            };
            match l.strip_suffix('\\') {
                Some(head) => {
                    joined.push_str(head.trim_end());
                    joined.push(' ');
                    pending = Some((start, joined));
                }
                None => {
                    joined.push_str(l);
                    out.push((start, joined));
                }
            }
        }
        if let Some(p) = pending {
            out.push(p);
        }
    }
    out
}

/// Whether `args` parse with the CLI (`--help`/`--version` count as parsing); else
/// clap's error.
pub(super) fn parses(args: &[String]) -> Result<(), String> {
    let argv = std::iter::once("probebridge".to_string()).chain(args.iter().cloned());
    match Cli::try_parse_from(argv) {
        Ok(_) => Ok(()),
        Err(e)
            if matches!(
                e.kind(),
                clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
            ) =>
        {
            Ok(())
        }
        Err(e) => Err(e.to_string().lines().next().unwrap_or("").to_string()),
    }
}
