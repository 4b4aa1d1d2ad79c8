//! `probebridge serve`'s OPC UA face on the simulator, played against by Python's
//! asyncua as the factory's MES (`tests/gateway/mes.py`, written from the gateway
//! page's address-space table) next to the pymodbus PLC (`tests/gateway/plc.py`):
//! browse by browse names, read identification and state, subscribe (the change
//! latencies, measured with the client's clock, are printed; only a generous bound is
//! asserted), StartProgram of a 431 as a user over Basic256Sha256 SignAndEncrypt with
//! the results of the PLC face and of the history, a 460's probe table row as the
//! PLC face's calibration block has it, refusals (anonymous, wrong password, the
//! PLC's run), an abort of a 451, a subscriber that never publishes,
//! the connection cap, asyncua's `uals`/`uaread`; the configuration's errors; the
//! face's death ending the service.
//!
//! Python with pymodbus and asyncua: `PROBEBRIDGE_PYTHON`, else
//! `/opt/probebridge-venv/bin/python` (`scripts/install-test-peers`). Skipped with a
//! line saying why where it is not there, never in CI.

#[allow(dead_code)] // run_program: the CLI tests'.
mod common;
#[path = "common/pymodbus_venv.rs"]
mod pymodbus_venv;

use common::*;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

const MAX_QUEUED: usize = 5;
const MAX_CONNECTIONS: usize = 4;

/// The venv's python, with asyncua (and pymodbus, for the PLC).
fn python() -> Option<PathBuf> {
    let py = pymodbus_venv::python()?;
    let ok = Command::new(&py)
        .args(["-c", "import asyncua"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{}: no asyncua in CI; scripts/install-test-peers should have installed it",
        py.display()
    );
    eprintln!(
        "SKIPPED: {} has no asyncua (run scripts/install-test-peers)",
        py.display()
    );
    None
}

/// A running `probebridge serve` with both faces; SIGTERM on drop.
struct Serve {
    child: Child,
    plc_port: u16,
    url: String,
    dir: PathBuf,
}

/// The machine of demo-sphere.toml (its `machine`, configs/machines/table-ac.toml).
const MACHINE: &str = "table-ac";

impl Serve {
    /// `opcua`: keys added to the `[opcua]` section; `envs` to the environment; with
    /// `users`, the users file with the MES's user.
    fn start(
        name: &str,
        scenario: &str,
        programs: &[(u16, &str)],
        opcua: &str,
        envs: &[(&str, &str)],
        users: bool,
    ) -> Self {
        let dir = tmpdir(&format!("opcua-{name}"));
        if users {
            write_users(&dir);
        }
        let folder = dir.join("programs");
        std::fs::create_dir_all(&folder).unwrap();
        for (n, p) in programs {
            std::fs::copy(
                configs().join("programs").join(p),
                folder.join(format!("{n}.h")),
            )
            .unwrap();
        }
        let config = dir.join("gateway.toml");
        std::fs::write(
            &config,
            format!(
                "[machine]\nscenario = {:?}\nservice = \"pbua-{name}-{}\"\nkinematics = {:?}\n\
                 [programs]\nfolder = \"programs\"\n[history]\nsqlite = {:?}\n{HISTORY_TIMEOUT}\
                 [plc]\nlisten = \"127.0.0.1:0\"\nheartbeat_timeout_ms = 0\n\
                 [opcua]\nlisten = \"opc.tcp://127.0.0.1:0\"\npki = \"pki\"\nusers = \"users\"\n\
                 manufacturer = \"ACME Werkzeugmaschinen\"\nmodel = \"RT-5\"\n\
                 serial_number = \"SN-0451\"\n{opcua}",
                configs().join("scenarios").join(scenario).to_str().unwrap(),
                std::process::id(),
                dir.join("kinematics.toml").to_str().unwrap(),
                dir.join("history.sqlite").to_str().unwrap(),
            ),
        )
        .unwrap();
        Self::spawn(dir, &config, envs)
    }

    fn spawn(dir: PathBuf, config: &Path, envs: &[(&str, &str)]) -> Self {
        let log = std::fs::File::create(dir.join("serve.log")).unwrap();
        let mut child = bin()
            .envs(envs.iter().copied())
            .args(["serve", "--config", config.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .unwrap();
        // Readiness: the lines the service says once each face is up.
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let (mut plc_port, mut url) = (None, None);
        while url.is_none() {
            let mut line = String::new();
            if out.read_line(&mut line).unwrap() == 0 {
                let _ = child.kill();
                let log = std::fs::read_to_string(dir.join("serve.log")).unwrap_or_default();
                panic!("serve did not come up:\n{log}");
            }
            if let Some(a) = line.trim().strip_prefix("probebridge serve: listening on ") {
                plc_port = Some(a.rsplit(':').next().unwrap().parse().unwrap());
            }
            if let Some(u) = line
                .trim()
                .strip_prefix("probebridge serve: OPC UA face on ")
            {
                url = Some(u.to_string());
            }
        }
        Self {
            child,
            plc_port: plc_port.unwrap(),
            url: url.unwrap(),
            dir,
        }
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("serve.log")).unwrap_or_default()
    }

    fn opcua_port(&self) -> u16 {
        self.url
            .trim_end_matches('/')
            .rsplit(':')
            .next()
            .unwrap()
            .parse()
            .unwrap()
    }

    /// mes.py COMMAND ARGS; its JSON (`ok`: it must succeed).
    fn mes(&self, py: &Path, machine: &str, args: &[&str]) -> serde_json::Value {
        let mut cmd = Command::new(py);
        cmd.arg(gateway_script("mes.py"))
            .arg(&self.url)
            .arg(machine)
            .arg(&self.dir)
            .arg(self.dir.join("pki/own/cert.der"))
            .args(args);
        python_peer(cmd, &format!("MES {args:?}"), || self.log())
    }

    /// plc.py COMMAND ARGS against the PLC face; its JSON.
    fn plc(&self, py: &Path, args: &[&str]) -> serde_json::Value {
        let mut cmd = Command::new(py);
        cmd.arg(gateway_script("plc.py"))
            .args(["127.0.0.1", &self.plc_port.to_string()])
            .args(args);
        python_peer(cmd, &format!("PLC {args:?}"), || self.log())
    }

    /// asyncua's own command-line tool `tool` (in the venv's bin/) with `args`.
    fn ua_tool(&self, py: &Path, tool: &str, args: &[&str]) -> String {
        let out = Command::new(py.with_file_name(tool))
            .args(["-u", &self.url])
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{tool} {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn stop(&mut self) -> std::process::ExitStatus {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        self.child.wait().unwrap()
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.stop();
        }
    }
}

/// The users file with the MES's user, made by `probebridge opcua-user`.
fn write_users(dir: &Path) {
    let mut child = bin()
        .args(["opcua-user", "mes"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(b"measure 431!\n")
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let line = String::from_utf8(out.stdout).unwrap();
    assert!(
        line.starts_with("mes:$argon2id$") && !line.contains("measure"),
        "{line}"
    );
    let f = dir.join("users");
    std::fs::write(&f, line).unwrap();
    std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
}

fn history(dir: &Path) -> Vec<serde_json::Value> {
    let out = run(bin()
        .args([
            "history",
            "--db",
            dir.join("history.sqlite").to_str().unwrap(),
            "--json",
        ])
        .args(["--since", "2000-01-01"]));
    assert!(out.status.success());
    serde_json::from_slice::<serde_json::Value>(&out.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

/// Trusts the MES's certificate the way the docs say: its first secured connection is
/// refused and leaves the certificate in pki/rejected/; moved to pki/trusted/ it is
/// taken.
fn trust_the_mes(serve: &Serve, py: &Path, machine: &str) {
    let first = serve.mes(py, machine, &["connect"]);
    assert_eq!(first["connected"], false, "{first}");
    let rejected: Vec<PathBuf> = std::fs::read_dir(serve.dir.join("pki/rejected"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(rejected.len(), 1, "{rejected:?}");
    let name = rejected[0].file_name().unwrap();
    std::fs::rename(&rejected[0], serve.dir.join("pki/trusted").join(name)).unwrap();
    let again = serve.mes(py, machine, &["connect"]);
    assert_eq!(again["connected"], true, "{again}\n{}", serve.log());
}

#[test]
fn the_mes_browses_subscribes_and_runs_a_431_as_the_plc_does() {
    let Some(py) = python() else { return };
    let machine = MACHINE;
    let mut serve = Serve::start(
        "mes",
        "tilted-plane.toml",
        &[(431, "431-plane.h")],
        &format!(
            "security = [\"none\", \"basic256sha256-sign-encrypt\"]\nmay_start = true\n\
             max_queued_notifications = {MAX_QUEUED}\nmax_connections = {MAX_CONNECTIONS}\n\
             max_sessions = {MAX_CONNECTIONS}\nmanufacturer_uri = \"{MANUFACTURER_URI}\"\n"
        ),
        &[],
        true,
    );
    // The certificate is made on first start, in the PKI folder; its key is private.
    let key = serve.dir.join("pki/private/private.pem");
    assert!(serve.dir.join("pki/own/cert.der").is_file());
    assert_eq!(key.metadata().unwrap().permissions().mode() & 0o777, 0o600);

    browse_and_tools(&serve, &py);
    let idle = companion_types(&serve, &py);
    assert_eq!(
        idle["MachineTool:Monitoring/MachineTool:MachineTool/Machinery:MachineryOperationMode/CurrentState"],
        "None",
        "no operation mode known outside a run"
    );
    assert_eq!(
        idle["MachineTool:Monitoring/MachineTool:MachineTool/MachineTool:OperationMode"],
        serde_json::Value::Null
    );
    trust_the_mes(&serve, &py, machine);
    let r = serve.mes(&py, machine, &["refusals", "431"]);
    assert_eq!(r["anonymous"], "BadUserAccessDenied", "{r}");
    assert_ne!(r["wrong_password"], "logged in", "{r}");
    assert_eq!(r["state"], "idle", "nothing started: {r}");
    failed_logins_are_throttled(&serve, &py);

    the_431_as_the_plc(&serve, &py);
    // After the MES's 431: the program's state machine says it ended, by its state's
    // node and number.
    let ended = companion_types(&serve, &py);
    let program = "MachineTool:Production/MachineTool:ActiveProgram";
    for (path, want) in [
        ("MachineTool:Name", serde_json::json!("431.h")),
        ("NumberInList", serde_json::json!(0)),
        ("MachineTool:State/CurrentState", serde_json::json!("Ended")),
        (
            "MachineTool:State/CurrentState/Number",
            serde_json::json!(2),
        ),
        ("PB:Number", serde_json::json!(431)),
    ] {
        assert_eq!(ended[&format!("{program}/{path}")], want, "{path}");
    }
    assert_eq!(
        ended["MachineTool:Monitoring/MachineTool:MachineTool/Machinery:MachineryItemState/CurrentState"],
        "NotExecuting"
    );
    stalled_and_capped(&serve, &py);
    let status = serve.stop();
    assert_eq!(status.code(), Some(0), "{}", serve.log());
    let _ = std::fs::remove_dir_all(&serve.dir);
}

const MANUFACTURER_URI: &str = "https://machines.acme.example";

/// The machine against OPC 40501-1's types (tests/gateway/companion.py, from the
/// NodeSet files): found under Machinery's Machines by its type definition, every
/// Mandatory component there with its browse name, type definition and data type, the
/// namespace URIs in the namespace array, each state machine's CurrentState naming its
/// state; and docs/opcua.md's table is the server's. Returns each node's value by its
/// path below the machine.
fn companion_types(serve: &Serve, py: &Path) -> serde_json::Map<String, serde_json::Value> {
    let mut cmd = Command::new(py);
    cmd.arg(gateway_script("companion.py"))
        .arg(&serve.url)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../third_party/opcua-nodesets"));
    let c = python_peer(cmd, "companion.py", || serve.log());
    assert_eq!(c["failures"], serde_json::json!([]), "{}", c["failures"]);
    assert_eq!(
        c["machines"],
        serde_json::json!([{"name": format!("PB:{MACHINE}"), "node_id": "ns=8;s=Machine",
                            "type": "MachineTool:MachineToolType"}]),
        "{}",
        c["namespaces"]
    );
    // MachineToolType's Mandatory tree: Identification and its three properties,
    // Monitoring/MachineTool/OperationMode, Production/ActiveProgram with Name,
    // NumberInList and the State machine's CurrentState with Id and Number, Equipment,
    // Notification.
    assert_eq!(c["checked"], 17, "{}", c["machines"]);
    let nodes = c["nodes"][&format!("PB:{MACHINE}")].as_array().unwrap();
    let served: std::collections::BTreeSet<(String, String, String)> =
        nodes.iter().filter_map(table_row).collect();
    let documented = docs_table();
    let only_served: Vec<_> = served.difference(&documented).collect();
    let only_documented: Vec<_> = documented.difference(&served).collect();
    assert!(
        only_served.is_empty() && only_documented.is_empty(),
        "docs/opcua.md's table and the server differ:\nnot in the docs: \
         {only_served:#?}\nnot on the server: {only_documented:#?}"
    );
    nodes
        .iter()
        .map(|n| {
            let path = n["path"].as_str().unwrap().trim_start_matches('/');
            (path.to_string(), n["value"].clone())
        })
        .collect()
}

/// A node of companion.py's tree as docs/opcua.md's table has it (path, type
/// definition, data type): the runs as `RunNN`, the cycles as `CycleNNN`, their
/// results as `<result>`; the AddIns of MachineryBuildingBlocks without their children
/// (the table shows them where they are components).
fn table_row(n: &serde_json::Value) -> Option<(String, String, String)> {
    let mut parts: Vec<String> = n["path"]
        .as_str()?
        .trim_start_matches('/')
        .split('/')
        .map(str::to_string)
        .collect();
    if parts[0] == "Machinery:MachineryBuildingBlocks" && parts.len() > 2 {
        return None;
    }
    for (i, p) in parts.clone().iter().enumerate() {
        let numbered = |prefix: &str| {
            p.strip_prefix(prefix)
                .is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))
        };
        if numbered("PB:Run") {
            parts[i] = "PB:RunNN".into();
        }
        if numbered("PB:Cycle") {
            parts[i] = "PB:CycleNNN".into();
            if let Some(r) = parts.get_mut(i + 1) {
                if !["PB:Time", "PB:ResultNames", "PB:ResultValues"].contains(&r.as_str()) {
                    *r = "PB:<result>".into();
                }
            }
        }
    }
    let text = |v: &serde_json::Value| v.as_str().unwrap_or("").to_string();
    let ty = match n["class"].as_str() {
        Some("Method") => "method".to_string(),
        _ => text(&n["type"]),
    };
    Some((parts.join("/"), ty, text(&n["data_type"])))
}

/// docs/opcua.md's table of the machine's nodes: (path, type definition, data type).
fn docs_table() -> std::collections::BTreeSet<(String, String, String)> {
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/opcua.md"))
            .unwrap();
    let section = doc
        .split("### The machine\n")
        .nth(1)
        .and_then(|s| s.split("\n### ").next())
        .expect("docs/opcua.md: ### The machine");
    let rows: std::collections::BTreeSet<_> = section
        .lines()
        .filter(|l| l.starts_with("| `"))
        .map(|l| {
            let cells: Vec<String> = l
                .split('|')
                .skip(1)
                .map(|c| c.trim_matches(|ch| ch == ' ' || ch == '`').to_string())
                .collect();
            (cells[0].clone(), cells[1].clone(), cells[2].clone())
        })
        .collect();
    assert!(rows.len() > 50, "{rows:?}");
    rows
}

/// Browse by browse names, anonymously; asyncua's uals and uaread as the docs show them.
fn browse_and_tools(serve: &Serve, py: &Path) {
    let machine = MACHINE;
    // Browse by browse names, anonymously: identification and state.
    let b = serve.mes(py, machine, &["browse"]);
    assert_eq!(
        b["children"],
        serde_json::json!([
            "Equipment",
            "Identification",
            "MachineryBuildingBlocks",
            "Measurements",
            "Monitoring",
            "Notification",
            "Production"
        ]),
        "{b}"
    );
    assert_eq!(
        b["methods"],
        serde_json::json!(["Abort", "Acknowledge", "StartProgram"])
    );
    let v = &b["values"];
    assert_eq!(
        v["DI:Identification/DI:Manufacturer"],
        "ACME Werkzeugmaschinen"
    );
    assert_eq!(v["DI:Identification/DI:SerialNumber"], "SN-0451");
    assert!(v["DI:Identification/DI:SoftwareRevision"]
        .as_str()
        .unwrap()
        .starts_with("probebridge "));
    // The manufacturer's URI and the serial number name the machine.
    assert_eq!(
        v["DI:Identification/DI:ProductInstanceUri"],
        format!("{MANUFACTURER_URI}/SN-0451")
    );
    assert_eq!(
        v["MT:Monitoring/MT:MachineTool/M:MachineryItemState/0:CurrentState"],
        "NotExecuting"
    );
    assert_eq!(v["MT:Monitoring/MachineOk"], true);
    assert_eq!(v["MT:Monitoring/Bus"], "simulator");
    assert_eq!(v["MT:Monitoring/RunState"], "idle");
    assert!(
        ["BadNotWritable", "BadUserAccessDenied"].contains(&b["anonymous_write"].as_str().unwrap()),
        "{b}"
    );

    // asyncua's own tools, as the docs show them.
    let ls = serve.ua_tool(py, "uals", &["-n", "i=85", "-d", "3"]);
    assert!(
        ls.contains("Machines") && ls.contains(machine) && ls.contains("Monitoring"),
        "{ls}"
    );
    // The namespace indexes of this server (docs/opcua.md): 5 Machinery, 7
    // MachineTool, 8 the gateway's.
    let read = serve.ua_tool(
        py,
        "uaread",
        &[
            "-p",
            &format!("0:Objects,5:Machines,8:{machine},7:Monitoring,8:RunState"),
        ],
    );
    assert_eq!(read.trim(), "idle", "{read}");
}

/// Failed logins slow the next ones of the name (the refusals' wrong password was the
/// first): the 4th and 5th logins wait 1 s and 2 s, the right password after them
/// 4 s (and logs in); the log sums them up in one line, not a line per guess. Before, about 17
/// guesses a second were answered at once, two log lines each (issue 36).
fn failed_logins_are_throttled(serve: &Serve, py: &Path) {
    let g = serve.mes(py, MACHINE, &["guesses", "4"]);
    println!("guesses: {g}");
    // The server's waits follow one another, each from a failure after its attempt
    // began: together at least 1 + 2 + 4 s (the client's single times vary with load).
    assert!(g["total_s"].as_f64().unwrap() >= 7.0, "{g}");
    assert_eq!(g["wrong_s"].as_array().map(Vec::len), Some(4), "{g}");
    let log = serve.log();
    let lines = log.lines().filter(|l| l.contains("failed login")).count();
    assert_eq!(lines, 1, "{log}");
    assert!(!log.contains("login refused"), "{log}");
    assert!(!log.contains("BadIdentityTokenRejected"), "{log}");
}

/// The PLC's 431, then the MES's over SignAndEncrypt: the same results, the history's.
fn the_431_as_the_plc(serve: &Serve, py: &Path) {
    let machine = MACHINE;
    // The PLC's 431, then the MES's: the same results, and the history's.
    let plc = serve.plc(py, &["run", "431"]);
    let mes = serve.mes(py, machine, &["run", "431"]);
    println!(
        "OPC UA change latencies (ms, client clock): {:?}",
        mes["latencies_ms"]
    );
    let lat: Vec<f64> = mes["latencies_ms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(!lat.is_empty());
    // The 100 ms goal is measured (printed above), not asserted: a shared 2-core host
    // at load 14 once took 4 s. The bound only catches a change that never comes.
    assert!(
        lat.iter().all(|&l| l < 15_000.0),
        "a generous bound: {lat:?}"
    );
    let states: Vec<&str> = mes["states"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert!(
        states.windows(2).all(|w| w[0] != w[1]),
        "each change once: {states:?}"
    );
    assert!(
        states.contains(&"busy") && states.last() == Some(&"done"),
        "{states:?}"
    );
    let active = &mes["active"];
    assert_eq!(active["MT:Production/MT:ActiveProgram/StartedBy"], "opcua");
    assert_eq!(
        active["MT:Production/MT:ActiveProgram/MT:State/0:CurrentState"],
        "Ended"
    );
    assert_eq!(active["MT:Production/MT:ActiveProgram/Number"], 431);
    let (start, end) = (
        active["MT:Production/MT:ActiveProgram/StartTime"].as_f64(),
        active["MT:Production/MT:ActiveProgram/EndTime"].as_f64(),
    );
    assert!(
        matches!((start, end), (Some(s), Some(e)) if s <= e),
        "the run's start and end times: {active}"
    );
    // The PLC face's result block holds this run's results too, under the result
    // sequence 0, which no PLC request has.
    let plc_now = serve.plc(py, &["last"]);
    assert_eq!(plc_now["cycle"], 431, "{plc_now}");
    assert_eq!(plc_now["seq"], 0, "{plc_now}");
    let all = mes["results"].as_object().unwrap();
    // Each result and its standard uncertainty are nodes of their own (u.Q158 ...).
    let (mut results, mut u) = (serde_json::Map::new(), serde_json::Map::new());
    for (name, v) in all {
        match name.strip_prefix("u.") {
            Some(of) => u.insert(of.to_string(), v.clone()),
            None => results.insert(name.clone(), v.clone()),
        };
    }
    assert_eq!(results.len(), 8, "{all:?}");
    assert_eq!(u.len(), 8, "an uncertainty node per result: {all:?}");
    // The same run on both faces, and the PLC's own 431 of the same plane before.
    for (mine, block) in [(&results, "real"), (&u, "u")] {
        for theirs in [&plc_now[block], &plc[block]] {
            let theirs = theirs.as_object().unwrap();
            assert_eq!(mine.len(), theirs.len(), "{mine:?} / {theirs:?}");
            for (name, v) in mine {
                let (v, p) = (v.as_f64().unwrap(), theirs[name].as_f64().unwrap());
                assert!(
                    (v - p).abs() <= 1e-6 * v.abs().max(1.0),
                    "{block} {name}: OPC UA {v}, PLC {p}"
                );
            }
        }
    }
    let h = history(&serve.dir);
    let row = h
        .iter()
        .find(|r| r["source"] == "opcua")
        .expect("the MES's run in the history");
    assert_eq!(row["status"], "done");
    assert_eq!(row["program_number"], 431);
    assert_eq!(row["request_seq"], serde_json::Value::Null);
    assert_eq!(
        row["parameters"],
        serde_json::json!([1.5, -2.25, 0.0, 0.0, 0.0, 0.0, 0.0, 1000.125])
    );
    for x in row["results"].as_array().unwrap() {
        assert_eq!(results[x["name"].as_str().unwrap()], x["value"], "{x}");
    }
    let run01 = &mes["run01"];
    assert_eq!(run01["Id"], row["id"]);
    assert_eq!(
        (run01["Source"].as_str(), run01["Status"].as_str()),
        (Some("opcua"), Some("done"))
    );
    assert_eq!(run01["Parameters"], row["parameters"]);
    // How long the 431 kept the machine: the history's figure, about 7 s.
    let t = row["machine_time_s"]
        .as_f64()
        .expect("a machine time in the history");
    assert!((5.0..9.0).contains(&t), "{row}");
    assert_eq!(run01["MachineTime"], row["machine_time_s"]);
    // Run01's results: every result of the history's row as `CYCLE.NAME`.
    let (names, values) = (
        run01["ResultNames"].as_array().unwrap(),
        run01["ResultValues"].as_array().unwrap(),
    );
    assert_eq!(names.len(), values.len(), "{run01}");
    let recorded = row["results"].as_array().unwrap();
    assert!(!recorded.is_empty(), "{row}");
    for x in recorded {
        let name = format!("{}.{}", x["cycle"], x["name"].as_str().unwrap());
        let i = names
            .iter()
            .position(|n| n.as_str() == Some(name.as_str()))
            .unwrap_or_else(|| panic!("{name} in Run01: {run01}"));
        assert_eq!(values[i], x["value"], "{name}");
    }
}

/// A subscriber that never publishes; the connection cap.
fn stalled_and_capped(serve: &Serve, py: &Path) {
    let machine = MACHINE;
    // A subscriber that never publishes: at most max_queued_notifications are kept.
    let s = serve.mes(py, machine, &["stalled", &MAX_QUEUED.to_string()]);
    println!("stalled subscriber: {s}");
    assert!(
        s["heartbeat_changes"].as_u64().unwrap() >= 4 * MAX_QUEUED as u64,
        "{s}"
    );
    // Without publish requests the server keeps the item's queue (1 value here, at most
    // 10) and at most max_queued_notifications messages, not every change.
    let messages = s["messages"].as_u64().unwrap();
    assert!((1..=MAX_QUEUED as u64).contains(&messages), "{s}");
    assert!(s["values"].as_u64().unwrap() <= MAX_QUEUED as u64, "{s}");

    idle_sockets_lock_nobody_out(serve, py);
    the_cap_holds_for_clients_that_said_hello(serve);
}

/// More silent sockets than max_connections, held open: a real client still connects
/// (each new connection closes the oldest one that sent no Hello) and calls a method;
/// the silent ones are closed. Before, they held the door for minutes (issue 36).
fn idle_sockets_lock_nobody_out(serve: &Serve, py: &Path) {
    let port = serve.opcua_port();
    let idle: Vec<std::net::TcpStream> = (0..MAX_CONNECTIONS + 3)
        .map(|_| std::net::TcpStream::connect(("127.0.0.1", port)).unwrap())
        .collect();
    let c = serve.mes(py, MACHINE, &["call"]);
    println!("a client among idle sockets: {c}");
    // Within 5 s when not loaded; the bound only catches a client kept waiting.
    assert!(c["connect_s"].as_f64().unwrap() < 30.0, "{c}");
    assert_eq!(c["acknowledge"].as_array().map(Vec::len), Some(2), "{c}");
    assert_eq!(c["int32"], "BadTypeMismatch", "{c}");
    let want = serve.url.clone();
    assert_eq!(c["discovery_urls"], serde_json::json!([want]), "{c}");
    // Every silent socket is closed: at once to make room, or after the Hello timeout.
    for mut s in idle {
        s.set_read_timeout(Some(std::time::Duration::from_secs(60)))
            .unwrap();
        let mut b = [0u8; 1];
        assert_eq!(s.read(&mut b).unwrap_or(1), 0, "a silent socket is closed");
    }
}

/// An OPC UA Hello message (OPC 10000-6 §7.1.2.3) for `url`.
fn hello(url: &str) -> Vec<u8> {
    let mut m = b"HELF".to_vec();
    m.extend((32 + url.len() as u32).to_le_bytes());
    for v in [0u32, 65536, 65536, 0, 0] {
        m.extend(v.to_le_bytes());
    }
    m.extend((url.len() as i32).to_le_bytes());
    m.extend(url.as_bytes());
    m
}

/// max_connections clients that sent a Hello (and got the server's Acknowledge): one
/// more is closed at once, and said in the log.
fn the_cap_holds_for_clients_that_said_hello(serve: &Serve) {
    let port = serve.opcua_port();
    let open: Vec<std::net::TcpStream> = (0..MAX_CONNECTIONS)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
            s.write_all(&hello(&serve.url)).unwrap();
            let mut ack = [0u8; 4];
            s.read_exact(&mut ack).unwrap();
            assert_eq!(&ack, b"ACKF");
            s
        })
        .collect();
    let mut extra = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    let mut buf = [0u8; 8];
    assert_eq!(
        extra.read(&mut buf).unwrap_or(0),
        0,
        "the extra one is closed"
    );
    drop(open);
    assert!(
        serve.log().contains("opcua.max_connections"),
        "{}",
        serve.log()
    );
}

/// Issue 35: the history's WAL and first page overwritten while `serve` runs. The
/// MES's first start is refused (reason 9) once its `running` row cannot be read
/// back; from then on the history is known down and a start is refused at once (no
/// write tried: the recorder's "unavailable"), as the PLC's is (history_faults.rs).
#[test]
fn a_start_over_opcua_is_refused_at_once_while_the_history_is_known_corrupted() {
    let Some(py) = python() else { return };
    let machine = MACHINE;
    let serve = Serve::start(
        "histdown",
        "tilted-plane.toml",
        &[(431, "431-plane.h")],
        "may_start = true\n",
        &[],
        true,
    );
    trust_the_mes(&serve, &py, machine);
    let db = serve.dir.join("history.sqlite");
    overwrite_with_noise(&serve.dir.join("history.sqlite-wal"), 0, u64::MAX);
    overwrite_with_noise(&db, 0, 4096);
    let first = serve.mes(&py, machine, &["start", "431"]);
    assert_eq!(first["answer"][0], 9, "{first}\n{}", serve.log());
    let log = serve.log();
    assert!(log.contains("cannot be read back"), "{log}");
    for _ in 0..2 {
        let again = serve.mes(&py, machine, &["start", "431"]);
        assert_eq!(again["answer"][0], 9, "{again}");
        eprintln!(
            "OPC UA start refused (history known down) in {} ms",
            again["ms"]
        );
    }
    let refusals = serve.log().matches("start refused: history").count();
    let at_once = serve.log().matches("unavailable: history").count();
    assert!(at_once >= 2, "{refusals} refusals:\n{}", serve.log());
    let dir = serve.dir.clone();
    drop(serve);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_start_while_the_plc_runs_one_is_refused_and_an_abort_ends_a_451() {
    let Some(py) = python() else { return };
    let machine = MACHINE;
    let mut serve = Serve::start(
        "abort",
        "demo-sphere.toml",
        &[
            (451, "451-check.h"),
            (431, "431-plane.h"),
            (460, "460-calibrate.h"),
        ],
        "may_start = true\n",
        &[],
        true,
    );
    trust_the_mes(&serve, &py, machine);
    the_460_as_the_plc(&serve, &py);
    // The PLC runs a 451: the MES's start is refused as busy, its abort ends the run.
    serve.plc(&py, &["start_busy", "451"]);
    let w = serve.mes(&py, machine, &["while_plc_runs", "431"]);
    assert_eq!(w["state"], "busy");
    assert_eq!(w["started_by"], "plc");
    assert_eq!(
        w["refused"],
        serde_json::json!([1, "a measurement is running"]),
        "{w}"
    );
    assert_eq!(w["abort"][0], 0, "{w}");
    assert_eq!(w["after"]["MT:Monitoring/RunState"], "aborted", "{w}");
    assert_eq!(w["after"]["MT:Monitoring/ErrorKind"], 20, "{w}");
    assert_eq!(
        w["after"]["MT:Production/MT:ActiveProgram/MT:State/0:CurrentState"], "Aborted",
        "{w}"
    );
    assert_eq!(w["abort_again"][0], 6, "not busy: {w}");
    assert!(
        serve.log().contains("abort requested over OPC UA"),
        "{}",
        serve.log()
    );
    let h = history(&serve.dir);
    let r451 = h.iter().find(|r| r["program_number"] == 451).unwrap();
    assert_eq!(
        (r451["source"].as_str(), r451["status"].as_str()),
        (Some("serve"), Some("aborted"))
    );

    // The MES's own 451, aborted by the MES once it has probed a point, on a fresh
    // machine: the PLC's 451 was cut short anywhere (the table tilted, the stylus on
    // the sphere), where a next 451 may miss the sphere or not start. The service
    // comes back on the same state folder: its certificate is kept, and the MES it
    // trusted connects again without a new trust.
    let cert = std::fs::read(serve.dir.join("pki/own/cert.der")).unwrap();
    assert_eq!(serve.stop().code(), Some(0), "{}", serve.log());
    let dir = serve.dir.clone();
    drop(serve);
    let serve = Serve::spawn(dir.clone(), &dir.join("gateway.toml"), &[]);
    assert_eq!(std::fs::read(dir.join("pki/own/cert.der")).unwrap(), cert);
    assert_eq!(serve.mes(&py, machine, &["connect"])["connected"], true);
    let a = serve.mes(&py, machine, &["start_abort", "451"]);
    assert_eq!(a["abort"][0], 0, "{a}");
    assert_eq!(
        a["states"],
        serde_json::json!(["busy", "aborted", "idle"]),
        "aborted, then acknowledged: {a}"
    );
    assert_eq!(a["acknowledge"][0], 0, "{a}");
    assert_eq!(a["error_kind_after_ack"], 0, "{a}");
    assert!(a["after"]["MT:Monitoring/Point"].as_u64() >= Some(1), "{a}");
    assert_eq!(a["after"]["MT:Monitoring/RunState"], "aborted", "{a}");
    assert_eq!(a["after"]["MT:Monitoring/ErrorKind"], 20, "{a}");
    assert_eq!(
        a["after"]["MT:Production/MT:ActiveProgram/StartedBy"], "opcua",
        "{a}"
    );
    let h = history(&serve.dir);
    assert!(
        h.iter().any(|r| r["source"] == "opcua"
            && r["status"] == "aborted"
            && r["program_number"] == 451),
        "{h:?}"
    );
    drop(serve);
    let _ = std::fs::remove_dir_all(dir);
}

/// The MES's 460 (on the fresh machine, before any abort): Cycle460 shows the probe
/// table row by its column names and their uncertainties, as the PLC face's
/// calibration block and the history have them.
fn the_460_as_the_plc(serve: &Serve, py: &Path) {
    let mes = serve.mes(py, MACHINE, &["run", "460"]);
    assert_eq!(
        (
            mes["run01"]["Source"].as_str(),
            mes["run01"]["Status"].as_str()
        ),
        (Some("opcua"), Some("done"))
    );
    let plc = serve.plc(py, &["last"]);
    assert_eq!(plc["cycle"], 460, "{plc}");
    let got = mes["results"].as_object().unwrap();
    assert_eq!(got.len(), 8, "the 4 columns and their u: {got:?}");
    let h = history(&serve.dir);
    let row = h
        .iter()
        .find(|r| r["source"] == "opcua" && r["program_number"] == 460)
        .expect("the MES's 460 in the history");
    assert_eq!(row["status"], "done");
    let near = |a: f64, b: f64, floor: f64| (a - b).abs() <= 1e-6 * a.abs().max(floor);
    for col in ["R", "CAL_OF1", "CAL_OF2", "L"] {
        let v = got[col].as_f64().unwrap_or_else(|| panic!("{col}: {mes}"));
        let recorded = row["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["cycle"] == 460 && x["name"] == col)
            .unwrap_or_else(|| panic!("{col} in the history: {row}"));
        assert_eq!(recorded["value"].as_f64(), Some(v), "{col}");
        let p = plc["cal"][col].as_f64().unwrap();
        assert!(near(v, p, 1.0), "{col}: OPC UA {v}, PLC {p}");
        let u = &got[&format!("u.{col}")];
        match plc["cal_u"][col].as_f64() {
            Some(pu) => assert!(near(u.as_f64().unwrap(), pu, 1e-3), "u.{col}: {u} / {pu}"),
            None => assert!(u.is_null(), "u.{col}: {u}, none on the PLC face"),
        }
    }
    assert!(!plc["cal_u"].as_object().unwrap().is_empty(), "{plc}");
}

#[test]
fn opcua_errors_say_where_and_why_before_the_machine_opens() {
    for (extra, users_mode, want) in [
        (
            "listen = \"opc.tcp://gateway:4840\"\n",
            None,
            "opcua.listen",
        ),
        (
            "listen = \"opc.tcp://127.0.0.1:0\"\nsecurity = [\"basic128rsa15\"]\n",
            None,
            "opcua.security",
        ),
        (
            "listen = \"opc.tcp://127.0.0.1:0\"\n",
            Some(0o644),
            "opcua.users",
        ),
    ] {
        let dir = tmpdir("opcua-bad");
        std::fs::create_dir_all(dir.join("programs")).unwrap();
        if let Some(mode) = users_mode {
            write_users(&dir);
            std::fs::set_permissions(dir.join("users"), std::fs::Permissions::from_mode(mode))
                .unwrap();
        }
        let config = dir.join("gateway.toml");
        std::fs::write(
            &config,
            format!(
                "[machine]\nscenario = {:?}\n[programs]\nfolder = \"programs\"\n\
                 [history]\nenabled = false\n[plc]\nlisten = \"127.0.0.1:0\"\n\
                 [opcua]\npki = \"pki\"\nusers = \"users\"\n{extra}",
                configs()
                    .join("scenarios/demo-sphere.toml")
                    .to_str()
                    .unwrap(),
            ),
        )
        .unwrap();
        let out = bin()
            .args(["serve", "--config", config.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra}: {err}");
        assert!(
            err.contains(config.to_str().unwrap()) && err.contains(want),
            "{extra}: {err}"
        );
        assert!(!err.contains("machine up"), "before the machine: {err}");
        if users_mode.is_some() {
            assert!(err.contains("chmod 600"), "{err}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn the_opcua_face_s_death_ends_the_service() {
    if python().is_none() {
        return;
    }
    let mut serve = Serve::start(
        "death",
        "demo-sphere.toml",
        &[],
        "",
        &[("PROBEBRIDGE_FAULT_OPCUA_FACE", "end")],
        false,
    );
    let status = serve.child.wait().unwrap();
    assert!(!status.success(), "{status:?}");
    let log = serve.log();
    assert!(log.contains("the OPC UA face is dead"), "{log}");
    let _ = std::fs::remove_dir_all(&serve.dir);
}

/// Python (cryptography, asyncua's): the certificate's SANs and its days of validity.
const CERT_NAMES_PY: &str = r#"
import json, sys
from cryptography import x509
c = x509.load_der_x509_certificate(open(sys.argv[1], "rb").read())
san = c.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
print(json.dumps({
    "uri": [str(v) for v in san.get_values_for_type(x509.UniformResourceIdentifier)],
    "dns": [str(v) for v in san.get_values_for_type(x509.DNSName)],
    "ip": [str(v) for v in san.get_values_for_type(x509.IPAddress)],
    "days": (c.not_valid_after_utc - c.not_valid_before_utc).total_seconds() / 86400,
}))
"#;

/// Python: an expired self-signed certificate and its key, where the face keeps them.
const EXPIRED_PY: &str = r#"
import datetime, sys
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from cryptography.x509.oid import NameOID
key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "expired")])
now = datetime.datetime.now(datetime.timezone.utc)
cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(1)
        .not_valid_before(now - datetime.timedelta(days=20))
        .not_valid_after(now - datetime.timedelta(days=1))
        .sign(key, hashes.SHA256()))
open(sys.argv[1], "wb").write(cert.public_bytes(serialization.Encoding.DER))
open(sys.argv[2], "wb").write(key.private_bytes(serialization.Encoding.PEM,
    serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
"#;

/// `python -c SCRIPT ARGS`: its JSON, or null when it prints none.
fn python_json(py: &Path, script: &str, args: &[&Path]) -> serde_json::Value {
    let mut cmd = Command::new(py);
    cmd.arg("-c").arg(script).args(args);
    python_peer(cmd, "python -c", String::new)
}

/// A script of `bridge/tests/gateway/`.
fn gateway_script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/gateway")
        .join(name)
}

/// Runs a Python peer (`cmd`); it must succeed, else the test fails with `what`, its
/// stderr and `context()` (serve's log). Its stdout is JSON; null when it prints
/// nothing (a peer that only writes files).
fn python_peer(
    mut cmd: Command,
    what: &str,
    context: impl FnOnce() -> String,
) -> serde_json::Value {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what}: {}\nserve log:\n{}",
        String::from_utf8_lossy(&out.stderr),
        context()
    );
    if out.stdout.iter().all(u8::is_ascii_whitespace) {
        return serde_json::Value::Null;
    }
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{what}: its output is no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// The certificate: its lifetime as configured, its names the host name and the
/// listened address, a warning when it expires within 30 days; an expired one stops
/// `serve` until `probebridge opcua-certificate --renew` makes a new one. Before, the
/// certificate lived 365 days with the stack's names, and an expired one was served.
#[test]
fn the_certificate_is_named_checked_and_renewed() {
    let Some(py) = python() else { return };
    let mut serve = Serve::start(
        "cert",
        "demo-sphere.toml",
        &[],
        "hostname = \"gw-test\"\ncertificate_days = 10\n",
        &[],
        false,
    );
    let dir = serve.dir.clone();
    let (cert, key) = (
        dir.join("pki/own/cert.der"),
        dir.join("pki/private/private.pem"),
    );
    let names = python_json(&py, CERT_NAMES_PY, &[&cert]);
    assert_eq!(
        names["uri"],
        serde_json::json!([format!("urn:probebridge:gw-test:{MACHINE}")]),
        "{names}"
    );
    assert_eq!(names["dns"], serde_json::json!(["gw-test"]), "{names}");
    assert_eq!(names["ip"], serde_json::json!(["127.0.0.1"]), "{names}");
    let days = names["days"].as_f64().unwrap();
    assert!((9.9..=10.1).contains(&days), "{names}");
    let log = serve.log();
    assert!(
        ["expires in 9 days", "expires in 10 days"]
            .iter()
            .any(|w| log.contains(w))
            && log.contains("probebridge opcua-certificate --renew"),
        "{log}"
    );
    assert_eq!(serve.stop().code(), Some(0), "{}", serve.log());
    drop(serve);

    // An expired certificate: refused before the machine opens, with the command.
    python_json(&py, EXPIRED_PY, &[&cert, &key]);
    let config = dir.join("gateway.toml");
    let out = bin()
        .args(["serve", "--config", config.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("expired") && err.contains("probebridge opcua-certificate --renew"),
        "{err}"
    );
    assert!(!err.contains("machine up"), "before the machine: {err}");
    let expired = std::fs::read(&cert).unwrap();

    // Renewed by the command: a new certificate, and serve starts with it.
    let out = run(bin().args([
        "opcua-certificate",
        "--config",
        config.to_str().unwrap(),
        "--renew",
    ]));
    assert!(out.status.success());
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("days left"), "{said}");
    assert_ne!(std::fs::read(&cert).unwrap(), expired);
    assert_eq!(key.metadata().unwrap().permissions().mode() & 0o777, 0o600);
    let mut serve = Serve::spawn(dir.clone(), &config, &[]);
    assert_eq!(serve.stop().code(), Some(0), "{}", serve.log());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The README's first connection, as printed, on the default security (no `none`
/// endpoint): a client certificate made with openssl, uals refused until it is moved
/// from pki/rejected/ to pki/trusted/, then the machine listed. Before, the README's
/// `uals -u opc.tcp://GATEWAY:4840 -n i=85 -d 3` found no endpoint it could use.
#[test]
fn the_readme_s_uals_works_on_the_default_configuration() {
    let Some(py) = python() else { return };
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md"))
            .unwrap();
    let commands: Vec<&str> = readme
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("openssl req ") || l.starts_with("uals "))
        .collect();
    assert_eq!(commands.len(), 2, "the README's openssl and uals lines");
    let serve = Serve::start("uals", "demo-sphere.toml", &[], "", &[], false);
    let uals = |cmd: &str| {
        Command::new("sh")
            .arg("-c")
            .arg(cmd.replace("opc.tcp://127.0.0.1:4840", &serve.url))
            .current_dir(&serve.dir)
            .env(
                "PATH",
                format!(
                    "{}:{}",
                    py.parent().unwrap().display(),
                    std::env::var("PATH").unwrap_or_default()
                ),
            )
            .output()
            .unwrap()
    };
    let made = uals(commands[0]);
    assert!(made.status.success(), "{made:?}");
    let first = uals(commands[1]);
    assert!(!first.status.success(), "untrusted yet: {first:?}");
    let rejected: Vec<PathBuf> = std::fs::read_dir(serve.dir.join("pki/rejected"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(rejected.len(), 1, "{rejected:?}\n{}", serve.log());
    let name = rejected[0].file_name().unwrap();
    std::fs::rename(&rejected[0], serve.dir.join("pki/trusted").join(name)).unwrap();
    let listed = uals(commands[1]);
    let out = String::from_utf8_lossy(&listed.stdout);
    assert!(
        listed.status.success() && out.contains("Machines") && out.contains(MACHINE),
        "{listed:?}\n{}",
        serve.log()
    );
    let dir = serve.dir.clone();
    drop(serve);
    let _ = std::fs::remove_dir_all(dir);
}
