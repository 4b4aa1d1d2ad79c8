//! The layout rules of the workspace's code, checked from its sources:
//!
//! - No module of a crate imports another in a circle. For each member of the
//!   workspace, builds the import graph of its `src/` from the sources: one node per
//!   file (a module), one edge per `use crate::...`, `use super::...`, `use child::...`
//!   or inline `crate::a::b` / `super::b` path to another file, resolved to the deepest
//!   module that exists. Declaring a child (`mod child;`), comments and the
//!   `#[cfg(test)]` module are not imports. A binary's `main.rs` uses its library by
//!   name and declares no module of its own (checked).
//! - No production file (a `src/` file up to its `#[cfg(test)]` module) is over
//!   [`MAX_LINES`] lines, except the ones being split ([`BEING_SPLIT`]).
//! - The protocol cores ([`IO_FREE_CORES`]: CANopen, CiA 402, the real-time loop, the
//!   PLC handshake, the gateway's measurement rules) do no I/O: neither they nor any module of their crate they use
//!   (through the same import graph) reads a clock, starts a thread or opens a file, a
//!   socket or a process ([`IO_WORDS`]). Time is their argument, frames their input
//!   and output; the drivers around them do the rest.
//! - The gateway's faces reach the machine only through the measurement service: no
//!   module of a face uses the machine thread's ([`MACHINE_SIDE`]), and the OPC UA and
//!   web faces use none of the PLC face's ([`PLC_FACE`]).
//!
//! Rerun with `cargo test -p probebridge-tests --test module_graph`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The most lines of production code a file may hold: past it, a file is about more
/// than one concept.
const MAX_LINES: usize = 600;

/// Files over [`MAX_LINES`] that are being split into folders of one concept per file
/// (issue 24). Once a split is merged its entry goes: a listed file that is short
/// enough (or gone) fails the check, so the list only shrinks.
const BEING_SPLIT: &[&str] = &[];

/// The cores that do no I/O: (workspace member, module path). A module counts with
/// its submodules.
const IO_FREE_CORES: &[(&str, &str)] = &[
    ("hal", "crate::canopen"),
    ("hal", "crate::cia402"),
    ("hal", "crate::master::rt_loop"),
    ("bridge", "crate::serve::handshake"),
    ("bridge", "crate::serve::measurement"),
];

/// The gateway's faces other than the PLC's, and the PLC face's own modules: a face
/// reaches the machine only through the measurement service (`crate::serve::service`),
/// never another face's modules or the machine thread's.
const FACES_BESIDE_THE_PLC: &[&str] = &["crate::serve::opcua", "crate::serve::web_face"];
const PLC_FACE: &[&str] = &[
    "crate::serve::plc_registers",
    "crate::serve::modbus_face",
    "crate::serve::handshake",
    "crate::serve::register_map",
    "crate::serve::ownership",
];
/// What runs the machine: only the service's owner (`crate::serve`) and the machine
/// thread itself use these.
const MACHINE_SIDE: &[&str] = &[
    "crate::serve::machine_thread",
    "crate::serve::machine_link",
    "crate::serve::prepare",
    "crate::session",
];

/// What I/O looks like in Rust source: reading a clock, a thread, a file, a socket, a
/// process, the async runtime, the CAN socket crate, a system call.
const IO_WORDS: &[&str] = &[
    "Instant::now",
    "SystemTime::now",
    "monotonic_ns",
    "std::thread",
    "thread::spawn",
    "thread::sleep",
    "std::fs",
    "File::",
    "OpenOptions",
    "std::net",
    "TcpStream",
    "TcpListener",
    "UdpSocket",
    "std::process",
    "Command::new",
    "tokio",
    "socketcan",
    "libc::",
    "nix::",
];

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate is a member of the workspace")
        .to_path_buf()
}

/// The workspace's members, as the root `Cargo.toml` lists them.
fn members(root: &Path) -> Vec<String> {
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    let at = manifest
        .find("members")
        .expect("Cargo.toml lists its members");
    let list = &manifest[at..];
    let list = &list[list.find('[').unwrap() + 1..list.find(']').unwrap()];
    list.split(',')
        .map(|m| m.trim().trim_matches('"').to_string())
        .filter(|m| !m.is_empty())
        .collect()
}

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(dir, &mut files);
    files.sort();
    files
}

/// Module path (`crate::cycle451::plan`) of every library source file, and its text.
/// `main.rs` is the binary's root, not a module of the library.
fn modules(src: &Path) -> BTreeMap<String, String> {
    rust_files(src)
        .into_iter()
        .filter(|f| f.strip_prefix(src).unwrap() != Path::new("main.rs"))
        .map(|f| {
            let rel = f.strip_prefix(src).unwrap().with_extension("");
            let mut parts: Vec<String> = rel
                .iter()
                .map(|s| s.to_string_lossy().into_owned())
                .collect();
            if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
                parts.pop();
            }
            let name = std::iter::once("crate".to_string())
                .chain(parts)
                .collect::<Vec<_>>()
                .join("::");
            (name, std::fs::read_to_string(&f).unwrap())
        })
        .collect()
}

/// The production part of a file: its lines up to the `#[cfg(test)]` that opens its
/// test module (a `#[cfg(test)]` helper item before it is production code).
fn production(text: &str) -> Vec<&str> {
    let lines: Vec<&str> = text.lines().collect();
    let end = (0..lines.len())
        .find(|&i| {
            lines[i].trim_start().starts_with("#[cfg(test)]")
                && lines[i + 1..]
                    .iter()
                    .map(|l| l.trim_start())
                    .find(|l| !l.is_empty() && !l.starts_with("#["))
                    .is_some_and(|l| l.split_whitespace().take(2).any(|w| w == "mod"))
        })
        .unwrap_or(lines.len());
    lines[..end].to_vec()
}

/// The production code of a file without comments.
fn code(text: &str) -> String {
    let mut out = String::new();
    for line in production(text) {
        let line = line.split("//").next().unwrap_or("");
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// Expands `a::{b, c::{d, e as f}}` into `a::b`, `a::c::d`, `a::c::e~f` (`~` marks
/// the name a path is bound to under `as`).
fn expand(tree: &str) -> Vec<String> {
    let tree = tree.split_whitespace().collect::<Vec<_>>().join(" ");
    let tree: String = tree
        .replace(" as ", "~")
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    let Some(open) = tree.find('{') else {
        return vec![tree];
    };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.len() - 1];
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts
        .into_iter()
        .filter(|p| !p.is_empty())
        .flat_map(|p| expand(&format!("{prefix}{p}")))
        .collect()
}

/// A `use` path, and whether its statement passes the name on (`pub use`,
/// `pub(crate) use`): a re-export, as a parent's `mod.rs` does for its children.
struct Use {
    path: String,
    re_export: bool,
}

/// The expanded `use` trees of a module's code, and the code without its re-exports.
fn uses(code: &str) -> (Vec<Use>, String) {
    let mut out = Vec::new();
    let mut rest = code;
    let mut own = String::new();
    while let Some(i) = rest.find("use ") {
        let before = rest[..i].chars().last();
        let after = &rest[i + 4..];
        let end = after.find(';').unwrap_or(after.len());
        if before.is_none_or(|c| !(c.is_alphanumeric() || c == '_')) {
            let line = rest[..i].rsplit('\n').next().unwrap_or_default();
            let re_export = line.trim_start().starts_with("pub");
            out.extend(
                expand(&after[..end])
                    .into_iter()
                    .map(|path| Use { path, re_export }),
            );
            if re_export {
                own.push_str(&rest[..i - line.len()]);
            } else {
                own.push_str(&rest[..i + 4 + end]);
            }
            rest = &after[end..];
        } else {
            own.push_str(&rest[..i + 4]);
            rest = after;
        }
    }
    own.push_str(rest);
    (out, own)
}

/// The name a `use` path binds: its last segment, or its `as` name.
fn bound_name(path: &str) -> &str {
    match path.split_once('~') {
        Some((_, alias)) => alias,
        None => path.rsplit("::").next().unwrap_or_default(),
    }
}

/// Whether `code` has `name` as a whole word.
fn names_word(code: &str, name: &str) -> bool {
    let word = |c: char| c.is_alphanumeric() || c == '_';
    !name.is_empty()
        && code.match_indices(name).any(|(i, _)| {
            !code[..i].chars().next_back().is_some_and(word)
                && !code[i + name.len()..].chars().next().is_some_and(word)
        })
}

/// Paths a module's own code names: its `use` trees and inline `crate::`/`super::`
/// paths. A re-export passes a name on and is not the module's own use of it unless its
/// code names it too: it is no edge (a parent's `pub use child::X` over children that
/// use the parent's items is no circle), and paths through it lead to the module that
/// defines the name ([`bindings`]).
fn paths(code: &str) -> Vec<String> {
    let (uses, own) = uses(code);
    let mut out: Vec<String> = uses
        .into_iter()
        .filter(|u| !u.re_export || names_word(&own, bound_name(&u.path)))
        .map(|u| u.path.split('~').next().unwrap_or_default().to_string())
        .collect();
    out.extend(inline_paths(&own));
    out
}

/// The `crate::`/`super::` paths in `code`, each whole: `super::super::time::f` is
/// one path, not also `super::time::f` (a module of the parent's that may not exist).
fn inline_paths(code: &str) -> Vec<String> {
    let path_char = |c: char| c.is_alphanumeric() || c == '_' || c == ':';
    let mut out = Vec::new();
    for start in ["crate::", "super::"] {
        let mut from = 0;
        while let Some(i) = code[from..].find(start) {
            let at = from + i;
            let path: String = code[at..].chars().take_while(|&c| path_char(c)).collect();
            // Inside a longer path (`a::crate::`, `super::super::`): counted with it.
            let inside = code[..at].chars().next_back().is_some_and(path_char);
            from = at + path.len().max(start.len());
            // `super::{a, b}` is a `use` tree, counted above.
            if !inside && !path.ends_with("::") {
                out.push(path);
            }
        }
    }
    out
}

/// The names each module binds with `use` (also private ones, which its children
/// see), and the module each name's path points into. A path through such a name
/// (`crate::MachineError` when the root has `pub use machine::MachineError`) leads to
/// the module that defines it, not to the one that passes it on.
type Bindings = BTreeMap<String, BTreeMap<String, String>>;

fn bindings(mods: &BTreeMap<String, String>, known: &BTreeSet<String>) -> Bindings {
    let none = Bindings::new();
    mods.iter()
        .map(|(m, text)| {
            let names = uses(&code(text))
                .0
                .into_iter()
                .filter_map(|u| {
                    let (path, alias) = match u.path.split_once('~') {
                        Some((p, a)) => (p.to_string(), Some(a.to_string())),
                        None => (u.path.clone(), None),
                    };
                    let last = path.rsplit("::").next().unwrap_or_default();
                    let name = match (alias, last) {
                        (Some(a), _) => a,
                        (None, "*") => return None,
                        (None, "self") => path.rsplit("::").nth(1)?.to_string(),
                        (None, l) => l.to_string(),
                    };
                    let target = resolve(m, &path, known, &none)?;
                    Some((name, target))
                })
                .collect();
            (m.clone(), names)
        })
        .collect()
}

/// The module a path in module `m` points into: the deepest existing module, or the
/// module a name bound there by `use` points into.
fn resolve(m: &str, path: &str, known: &BTreeSet<String>, bound: &Bindings) -> Option<String> {
    let mut segs: Vec<&str> = path.split("::").collect();
    let mut base: Vec<&str> = m.split("::").collect();
    let absolute = match segs.first().copied() {
        Some("crate") => {
            segs.remove(0);
            vec!["crate"]
        }
        Some("super") => {
            while segs.first() == Some(&"super") {
                segs.remove(0);
                base.pop();
            }
            base
        }
        Some("self") => {
            segs.remove(0);
            base
        }
        // `use child::X` in a module with that child.
        Some(first) if known.contains(&format!("{m}::{first}")) => base,
        _ => return None,
    };
    let mut best = absolute.join("::");
    let mut cur = absolute.clone();
    for s in segs {
        cur.push(s);
        let name = cur.join("::");
        if known.contains(&name) {
            best = name;
            continue;
        }
        // A name `best` binds with `use`, followed (a few steps at most) to its module.
        for _ in 0..8 {
            match bound.get(&best).and_then(|b| b.get(s)) {
                Some(target) if *target != best => best = target.clone(),
                _ => break,
            }
        }
        break;
    }
    Some(best)
}

fn graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mods = modules(src);
    let known: BTreeSet<String> = mods.keys().cloned().collect();
    let bound = bindings(&mods, &known);
    mods.iter()
        .map(|(m, text)| {
            let targets = paths(&code(text))
                .iter()
                .filter_map(|p| resolve(m, p, &known, &bound))
                .filter(|t| t != m)
                .collect();
            (m.clone(), targets)
        })
        .collect()
}

/// The circles of the graph (strongly connected components of two or more modules).
fn circles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let reach = |from: &str| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.to_string()];
        while let Some(n) = stack.pop() {
            for t in g.get(&n).into_iter().flatten() {
                if seen.insert(t.clone()) {
                    stack.push(t.clone());
                }
            }
        }
        seen
    };
    let reachable: BTreeMap<&String, BTreeSet<String>> = g.keys().map(|m| (m, reach(m))).collect();
    let mut done = BTreeSet::new();
    let mut out = Vec::new();
    for m in g.keys() {
        if done.contains(m) || !reachable[m].contains(m) {
            continue;
        }
        let component: Vec<String> = g
            .keys()
            .filter(|n| reachable[m].contains(*n) && reachable[*n].contains(m))
            .cloned()
            .collect();
        done.extend(component.iter().cloned());
        out.push(component);
    }
    out
}

#[test]
fn no_module_imports_another_in_a_circle() {
    let root = workspace_root();
    let crates = members(&root);
    assert!(crates.len() >= 6, "the members were found: {crates:?}");
    let mut found = Vec::new();
    for member in &crates {
        let src = root.join(member).join("src");
        let main = src.join("main.rs");
        if let Ok(text) = std::fs::read_to_string(&main) {
            let declares = code(&text)
                .lines()
                .any(|l| l.trim_start().starts_with("mod ") || l.contains(" mod "));
            assert!(
                !declares,
                "{}: a binary root that declares modules of its own is not checked; \
                 put them in the library",
                main.display()
            );
        }
        let g = graph(&src);
        assert!(g.len() > 1, "{member}: the sources were found: {g:?}");
        for c in circles(&g) {
            found.push(format!("  {member}: {}", c.join(", ")));
        }
    }
    assert!(
        found.is_empty(),
        "modules that import each other in a circle:\n{}",
        found.join("\n")
    );
}

/// The modules `core` (a module path, with its submodules) and every module it uses,
/// through the import graph `g`.
fn closure(g: &BTreeMap<String, BTreeSet<String>>, core: &str) -> BTreeSet<String> {
    let mut seen: BTreeSet<String> = g.keys().filter(|m| within(m, core)).cloned().collect();
    let mut stack: Vec<String> = seen.iter().cloned().collect();
    while let Some(m) = stack.pop() {
        for t in g.get(&m).into_iter().flatten() {
            if seen.insert(t.clone()) {
                stack.push(t.clone());
            }
        }
    }
    seen
}

/// The [`IO_WORDS`] in `code`, each where it starts a word (`std::fs` and its `fs::`
/// inside a path both count; `offs::` does not).
fn io_words(code: &str) -> Vec<&'static str> {
    let word = |c: char| c.is_alphanumeric() || c == '_';
    IO_WORDS
        .iter()
        .copied()
        .filter(|w| {
            code.match_indices(w)
                .any(|(i, _)| !code[..i].chars().next_back().is_some_and(word))
        })
        .collect()
}

#[test]
fn the_protocol_cores_do_no_io() {
    let root = workspace_root();
    let mut found = Vec::new();
    for (member, core) in IO_FREE_CORES {
        let src = root.join(member).join("src");
        let mods = modules(&src);
        let g = graph(&src);
        let reached = closure(&g, core);
        assert!(
            reached.iter().any(|m| m == core),
            "{member}: the core {core} was found"
        );
        for m in &reached {
            let words = io_words(&code(&mods[m]));
            if !words.is_empty() {
                found.push(format!(
                    "  {member} {m} (from {core}): {}",
                    words.join(", ")
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "I/O in a protocol core, or in a module of its crate it uses (a clock read, \
         a thread, a file, a socket, a process): pass time and frames in as arguments, \
         and move the I/O to the driver around the core\n{}",
        found.join("\n")
    );
}

fn within(m: &str, root: &str) -> bool {
    m == root || m.starts_with(&format!("{root}::"))
}

/// Where a face's module uses one past the service: (module, what it uses).
fn faces_past_the_service(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    let faces: Vec<&str> = FACES_BESIDE_THE_PLC
        .iter()
        .chain(PLC_FACE)
        .copied()
        .collect();
    let mut found = Vec::new();
    for (m, targets) in g {
        let Some(face) = faces.iter().find(|f| within(m, f)) else {
            continue;
        };
        for t in targets {
            let machine = MACHINE_SIDE.iter().any(|x| within(t, x));
            let plc = FACES_BESIDE_THE_PLC.contains(face) && PLC_FACE.iter().any(|x| within(t, x));
            if machine || plc {
                found.push(format!("  {m} uses {t}"));
            }
        }
    }
    found
}

#[test]
fn the_faces_reach_the_machine_only_through_the_service() {
    let g = graph(&workspace_root().join("bridge").join("src"));
    for face in FACES_BESIDE_THE_PLC.iter().chain(PLC_FACE) {
        assert!(
            g.keys().any(|m| within(m, face)),
            "the face {face} was found"
        );
    }
    let found = faces_past_the_service(&g);
    assert!(
        found.is_empty(),
        "a face reaches past the measurement service (crate::serve::service): into the \
         machine thread's modules, or (OPC UA, web) into the PLC face's\n{}",
        found.join("\n")
    );
}

#[test]
fn the_face_check_sees_a_face_past_the_service() {
    let edge = |from: &str, to: &[&str]| {
        (
            from.to_string(),
            to.iter().map(|t| t.to_string()).collect::<BTreeSet<_>>(),
        )
    };
    let g: BTreeMap<String, BTreeSet<String>> = [
        edge(
            "crate::serve::opcua::values",
            &["crate::serve::service", "crate::serve::register_map"],
        ),
        edge("crate::serve::web_face", &["crate::serve::machine_thread"]),
        // The PLC face may use its own modules, not the machine thread's.
        edge(
            "crate::serve::plc_registers",
            &["crate::serve::handshake", "crate::serve::prepare"],
        ),
        edge("crate::serve::service", &["crate::serve::measurement"]),
    ]
    .into_iter()
    .collect();
    assert_eq!(
        faces_past_the_service(&g),
        [
            "  crate::serve::opcua::values uses crate::serve::register_map",
            "  crate::serve::plc_registers uses crate::serve::prepare",
            "  crate::serve::web_face uses crate::serve::machine_thread",
        ]
    );
}

#[test]
fn the_io_check_sees_io_in_what_a_core_uses() {
    let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    let mut g = BTreeMap::new();
    g.insert("crate::core".to_string(), set(&["crate::helper"]));
    g.insert("crate::core::part".to_string(), set(&[]));
    g.insert("crate::helper".to_string(), set(&["crate::deep"]));
    g.insert("crate::deep".to_string(), set(&[]));
    g.insert("crate::other".to_string(), set(&["crate::core"]));
    assert_eq!(
        closure(&g, "crate::core"),
        set(&[
            "crate::core",
            "crate::core::part",
            "crate::helper",
            "crate::deep"
        ])
    );
    assert_eq!(
        io_words("let t = std::time::Instant::now();\nlet f = std::fs::read(p);"),
        vec!["Instant::now", "std::fs"]
    );
    assert_eq!(
        io_words("let t: Instant = at; let offs::x = 1;"),
        Vec::<&str>::new()
    );
    assert_eq!(
        io_words("use tokio::net::TcpStream;"),
        vec!["TcpStream", "tokio"]
    );
}

#[test]
fn no_production_file_is_over_600_lines() {
    let root = workspace_root();
    let mut long = Vec::new();
    let mut still_listed = Vec::new();
    for member in members(&root) {
        for f in rust_files(&root.join(&member).join("src")) {
            let rel = f
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            let n = production(&std::fs::read_to_string(&f).unwrap()).len();
            if n > MAX_LINES && !BEING_SPLIT.contains(&rel.as_str()) {
                long.push(format!("  {rel}: {n} lines"));
            }
        }
    }
    for rel in BEING_SPLIT {
        let n = std::fs::read_to_string(root.join(rel)).map_or(0, |text| production(&text).len());
        if n <= MAX_LINES {
            still_listed.push(format!("  {rel}: {n} lines (0 = gone)"));
        }
    }
    assert!(
        long.is_empty(),
        "production files (before their #[cfg(test)] module) over {MAX_LINES} lines: \
         split each by concept into a folder of files\n{}",
        long.join("\n")
    );
    assert!(
        still_listed.is_empty(),
        "split already, remove from BEING_SPLIT:\n{}",
        still_listed.join("\n")
    );
}

#[test]
fn the_check_sees_a_circle() {
    let mut g = BTreeMap::new();
    let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    g.insert("crate::a".to_string(), set(&["crate::b"]));
    g.insert("crate::b".to_string(), set(&["crate::c"]));
    g.insert("crate::c".to_string(), set(&["crate::a"]));
    g.insert("crate::d".to_string(), set(&["crate::a"]));
    assert_eq!(
        circles(&g),
        vec![vec![
            "crate::a".to_string(),
            "crate::b".into(),
            "crate::c".into()
        ]]
    );
    let known = set(&["crate", "crate::k", "crate::k::m", "crate::k::n"]);
    let none = Bindings::new();
    assert_eq!(
        resolve("crate::k::m", "super::n::X", &known, &none).as_deref(),
        Some("crate::k::n")
    );
    assert_eq!(
        resolve("crate::k", "n::{X, Y}", &known, &none).as_deref(),
        Some("crate::k::n")
    );
    assert_eq!(
        inline_paths("f(super::super::time::parse(x), crate::k::m::f());"),
        vec!["crate::k::m::f", "super::super::time::parse"]
    );
    assert_eq!(
        expand("crate::{a, b::{c, d as e}}"),
        vec!["crate::a", "crate::b::c", "crate::b::d~e"]
    );
    // `crate::k` passes on `n`'s X (and, under another name, Y): a path through it
    // leads to `n`.
    let mut mods = BTreeMap::new();
    mods.insert(
        "crate::k".to_string(),
        "pub use n::{X, Y as Z};".to_string(),
    );
    mods.insert("crate::k::m".to_string(), String::new());
    mods.insert("crate::k::n".to_string(), String::new());
    let bound = bindings(&mods, &known);
    for path in ["super::X", "crate::k::Z"] {
        assert_eq!(
            resolve("crate::k::m", path, &known, &bound).as_deref(),
            Some("crate::k::n"),
            "{path}"
        );
    }
    assert_eq!(
        resolve("crate::k::m", "super::W", &known, &bound).as_deref(),
        Some("crate::k")
    );
}

#[test]
fn production_ends_at_the_test_module() {
    let text =
        "a\n#[cfg(test)]\nfn helper() {}\nb\n#[cfg(test)]\n#[allow(x)]\npub(crate) mod tests {\nc\n}\n";
    assert_eq!(
        production(text),
        vec!["a", "#[cfg(test)]", "fn helper() {}", "b"]
    );
    assert_eq!(production("a\nb\n"), vec!["a", "b"]);
}
