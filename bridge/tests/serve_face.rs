//! The PLC face of `probebridge serve` under a hostile network, each test a finding of
//! issue 20 reproduced: descriptors exhausted by idle connections (a lowered
//! `RLIMIT_NOFILE`), the connection limit, a squatter that wrote once and went silent,
//! a PLC that lost power while it owned the request block (network namespaces this
//! test makes), the peer allow-list, a connect loop flooding the log; and the edges of
//! the register table, the order of start-up, the size of the files read, and a dead
//! or stalled face ending the service.
//!
//! The PLC is pymodbus (`tests/gateway/plc.py`) where a third-party client matters;
//! hostile peers are raw sockets. Tests that need pymodbus or namespaces are skipped
//! with a line saying why where those are missing, never in CI.

#[allow(
    dead_code,
    reason = "each test binary uses a part of the shared helpers"
)]
mod common;
#[path = "common/pymodbus_venv.rs"]
mod pymodbus_venv;
use pymodbus_venv::python;
#[path = "common/serve.rs"]
mod serve;
use serve::{copy_programs, Serve as Gateway};

use common::*;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Writes a gateway configuration in `dir` serving `scenario` with the programs
/// `(number, shipped program)`; `plc` adds keys to `[plc]` (after `listen`).
fn gateway_config(
    dir: &Path,
    name: &str,
    scenario: &str,
    programs: &[(u16, &str)],
    plc: &str,
) -> PathBuf {
    copy_programs(dir, programs);
    let config = dir.join("gateway.toml");
    std::fs::write(
        &config,
        format!(
            "[machine]\nscenario = {:?}\nservice = \"pbface-{name}-{}\"\nkinematics = {:?}\n\
             [programs]\nfolder = \"programs\"\n[history]\nsqlite = {:?}\n{HISTORY_TIMEOUT}[plc]\n{plc}",
            configs().join("scenarios").join(scenario).to_str().unwrap(),
            std::process::id(),
            dir.join("kinematics.toml").to_str().unwrap(),
            dir.join("history.sqlite").to_str().unwrap(),
        ),
    )
    .unwrap();
    config
}

impl Gateway {
    fn start(name: &str, programs: &[(u16, &str)], plc: &str, env: &[(&str, &str)]) -> Self {
        let dir = tmpdir(&format!("face-{name}"));
        let plc = format!("listen = \"127.0.0.1:0\"\n{plc}");
        let config = gateway_config(&dir, name, "tilted-plane.toml", programs, &plc);
        let mut cmd = bin();
        for (k, v) in env {
            cmd.env(k, v);
        }
        Self::spawn(cmd, &dir, &config)
    }

    /// Polls the log until `pred` holds (at most 60 s, then fails with the log).
    fn wait_log(&self, what: &str, pred: impl Fn(&str) -> bool) {
        let deadline = Instant::now() + Duration::from_secs(60);
        while !pred(&self.log()) {
            assert!(Instant::now() < deadline, "{what}:\n{}", self.log());
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn history_statuses(&self) -> Vec<String> {
        let out = run(bin()
            .args(["history", "--json", "--since", "2000-01-01", "--db"])
            .arg(self.dir.join("history.sqlite")));
        assert!(out.status.success());
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        v.as_array()
            .unwrap()
            .iter()
            .map(|r| r["status"].as_str().unwrap().to_string())
            .collect()
    }
}

/// A Modbus TCP client on a bare socket: hostile peers, and frames pymodbus refuses
/// to send.
struct Raw {
    s: TcpStream,
    tid: u16,
}

impl Raw {
    fn connect(addr: SocketAddr) -> Self {
        let s = TcpStream::connect(addr).unwrap();
        // A safety net against a hung test, not a timed assertion.
        s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        Self { s, tid: 0 }
    }

    /// Connects from the loopback address `src` (127.0.0.2: another host as the
    /// gateway sees it, still loopback).
    fn connect_from(src: [u8; 4], addr: SocketAddr) -> Self {
        use std::os::fd::FromRawFd;
        let SocketAddr::V4(to) = addr else {
            panic!("IPv4 only")
        };
        let sockaddr = |ip: [u8; 4], port: u16| {
            // SAFETY: sockaddr_in is plain data; all zeroes is a valid value.
            let mut a: libc::sockaddr_in = unsafe { std::mem::zeroed() };
            a.sin_family = libc::AF_INET as libc::sa_family_t;
            a.sin_port = port.to_be();
            a.sin_addr.s_addr = u32::from_ne_bytes(ip);
            a
        };
        let len = std::mem::size_of::<libc::sockaddr_in>() as libc::socklen_t;
        // SAFETY: a new socket of ours, bound and connected with valid sockaddr_in
        // pointers, then owned by the TcpStream.
        let s = unsafe {
            let fd = libc::socket(libc::AF_INET, libc::SOCK_STREAM | libc::SOCK_CLOEXEC, 0);
            assert!(fd >= 0);
            let from = sockaddr(src, 0);
            assert_eq!(libc::bind(fd, (&raw const from).cast(), len), 0);
            let to = sockaddr(to.ip().octets(), to.port());
            assert_eq!(libc::connect(fd, (&raw const to).cast(), len), 0);
            TcpStream::from_raw_fd(fd)
        };
        s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        Self { s, tid: 0 }
    }

    /// Sends a PDU, returns the answer's PDU; Err when the gateway closed instead.
    fn ask(&mut self, pdu: &[u8]) -> std::io::Result<Vec<u8>> {
        self.tid = self.tid.wrapping_add(1);
        let mut f = Vec::new();
        f.extend_from_slice(&self.tid.to_be_bytes());
        f.extend_from_slice(&[0, 0]);
        f.extend_from_slice(&(pdu.len() as u16 + 1).to_be_bytes());
        f.push(1);
        f.extend_from_slice(pdu);
        self.s.write_all(&f)?;
        let mut head = [0u8; 7];
        self.s.read_exact(&mut head)?;
        assert_eq!(u16::from_be_bytes([head[0], head[1]]), self.tid);
        let mut body = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
        self.s.read_exact(&mut body)?;
        Ok(body)
    }

    /// FC3: the registers, or the exception code.
    fn read(&mut self, addr: u16, count: u16) -> std::io::Result<Result<Vec<u16>, u8>> {
        let mut pdu = vec![3];
        pdu.extend_from_slice(&addr.to_be_bytes());
        pdu.extend_from_slice(&count.to_be_bytes());
        let a = self.ask(&pdu)?;
        Ok(if a[0] == 0x83 {
            Err(a[1])
        } else {
            Ok(a[2..]
                .chunks(2)
                .map(|w| u16::from_be_bytes([w[0], w[1]]))
                .collect())
        })
    }

    /// FC16 (FC6 for one register when `single`): Ok, or the exception code.
    fn write(&mut self, addr: u16, values: &[u16], single: bool) -> Result<(), u8> {
        let mut pdu = vec![if single { 6 } else { 16 }];
        pdu.extend_from_slice(&addr.to_be_bytes());
        if single {
            pdu.extend_from_slice(&values[0].to_be_bytes());
        } else {
            pdu.extend_from_slice(&(values.len() as u16).to_be_bytes());
            pdu.push((values.len() * 2) as u8);
            values
                .iter()
                .for_each(|v| pdu.extend_from_slice(&v.to_be_bytes()));
        }
        let a = self.ask(&pdu).expect("an answer, not a closed connection");
        if a[0] & 0x80 != 0 {
            Err(a[1])
        } else {
            Ok(())
        }
    }

    /// The whole request block (code, sequence, program, zero flags and parameters).
    fn request(&mut self, code: u16, seq: u16, program: u16) -> Result<(), u8> {
        let mut block = vec![0u16; 21];
        (block[0], block[1], block[2]) = (code, seq, program);
        self.write(0, &block, false)
    }

    /// The state block once the gateway has acknowledged sequence `seq` (register 32):
    /// a start is answered once prepared, as the handshake says.
    fn acknowledged(&mut self, seq: u16) -> Vec<u16> {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let st = self.read(32, 4).unwrap().unwrap();
            if st[0] == seq {
                return st;
            }
            assert!(
                Instant::now() < deadline,
                "seq {seq} never acknowledged: {st:?}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Whether the gateway serves this connection: a read answered (not closed).
    fn served(&mut self) -> bool {
        matches!(self.read(32, 1), Ok(Ok(_)))
    }

    /// The gateway has closed this connection (its end read, nothing waiting).
    fn closed_by_the_gateway(&self) -> bool {
        self.s.set_nonblocking(true).unwrap();
        let closed = matches!(self.s.peek(&mut [0u8; 1]), Ok(0));
        self.s.set_nonblocking(false).unwrap();
        closed
    }
}

/// The open descriptors of process `pid`.
fn open_fds(pid: u32) -> Vec<u64> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok())
        .collect()
}

#[test]
fn accept_errors_under_fd_exhaustion_are_retried_and_the_plc_gets_in() {
    let Some(py) = python() else { return };
    // One address for every peer here: its cap as high as the face's.
    let g = Gateway::start(
        "fds",
        &[(431, "431-plane.h")],
        "max_connections_per_peer = 8\n",
        &[],
    );
    // Lower the running gateway's soft RLIMIT_NOFILE so that exactly 7 more
    // descriptors can be opened (a descriptor must be below the limit): the 8th idle
    // connection makes accept() fail with EMFILE, before the connection limit of 8.
    let fds = open_fds(g.child.id());
    let limit = (0u64..)
        .find(|&l| l - fds.iter().filter(|&&f| f < l).count() as u64 == 7)
        .unwrap();
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: prlimit(2) on our own child, with valid rlimit pointers.
    unsafe {
        assert_eq!(
            libc::prlimit(
                g.child.id() as i32,
                libc::RLIMIT_NOFILE,
                std::ptr::null(),
                &mut lim
            ),
            0
        );
    }
    let original = lim.rlim_cur;
    lim.rlim_cur = limit;
    // SAFETY: as above.
    unsafe {
        assert_eq!(
            libc::prlimit(
                g.child.id() as i32,
                libc::RLIMIT_NOFILE,
                &lim,
                std::ptr::null_mut()
            ),
            0
        );
    }
    let idle: Vec<TcpStream> = (0..12)
        .map(|_| TcpStream::connect(g.addr()).unwrap())
        .collect();
    // The face says so and goes on; before, it returned, closing every connection
    // and its listener, and the service lived on deaf.
    let deadline = Instant::now() + Duration::from_secs(60);
    while !g.log().contains("PLC face: accept failed") {
        assert!(
            TcpStream::connect(g.addr()).is_ok(),
            "the PLC face closed its listener:\n{}",
            g.log()
        );
        assert!(Instant::now() < deadline, "no accept error:\n{}", g.log());
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(g.log().contains("Too many open files"), "{}", g.log());
    // The idle peers go: under the same lowered limit the PLC is served again.
    drop(idle);
    let st = g.plc(&py, &["state"]);
    assert_eq!(st["state"], 0, "{st}");
    // With the descriptors a run writes (history, protocol, log) back, it measures.
    lim.rlim_cur = original;
    // SAFETY: as above.
    unsafe {
        assert_eq!(
            libc::prlimit(
                g.child.id() as i32,
                libc::RLIMIT_NOFILE,
                &lim,
                std::ptr::null_mut()
            ),
            0
        );
    }
    let got = g.plc(&py, &["run", "431"]);
    assert_eq!(got["cycle"], 431, "{got}");
    assert_eq!(g.history_statuses(), ["done"]);
}

#[test]
fn the_connection_limit_refuses_extras_and_a_silent_one_makes_room() {
    let Some(py) = python() else { return };
    let g = Gateway::start(
        "limit",
        &[(431, "431-plane.h")],
        "max_connections_per_peer = 8\n",
        &[("PROBEBRIDGE_LOG", "debug")],
    );
    // 20 peers connect and ask once; the default limit is 8.
    let mut peers: Vec<Raw> = (0..20).map(|_| Raw::connect(g.addr())).collect();
    let served: Vec<bool> = peers.iter_mut().map(Raw::served).collect();
    assert_eq!(
        served.iter().filter(|&&s| s).count(),
        8,
        "{served:?}\n{}",
        g.log()
    );
    assert!(served[..8].iter().all(|&s| s), "the first 8: {served:?}");
    g.wait_log("refusals at the limit are logged", |l| {
        l.contains("connections open (plc.max_connections)")
    });
    // The 8 stay connected and silent. A PLC that tries again gets in once one of
    // them has been silent for the owner timeout (10 s): it is closed for the PLC.
    let got = g.plc(&py, &["patient_run", "431"]);
    assert_eq!(got["cycle"], 431, "{got}");
    assert!(got["connect_attempts"].as_u64().unwrap() > 1, "{got}");
    assert!(g.log().contains("for a new one from"), "{}", g.log());
    drop(peers);
}

/// Issue 35: idle connections opened at 20 a second and held, from two other hosts
/// (127.0.0.2 and 127.0.0.3, loopback as well), while the PLC (127.0.0.1, the last
/// owner of the request block) connects again and again. Before, the flood held all 8
/// places within 0.4 s and a new connection got in only past one silent for 10 s:
/// the PLC was refused. Now each host holds at most its 4 (half the face's 8) and the
/// PLC's address keeps a place: every reconnect is served (a read answered within
/// 1 s, a bound generous enough never to decide the outcome on a loaded machine).
#[test]
fn a_slow_flood_from_other_hosts_never_keeps_the_plc_out() {
    let g = Gateway::start("flood", &[(431, "431-plane.h")], "", &[]);
    let mut plc = Raw::connect(g.addr());
    assert_eq!(plc.write(20, &[1], true), Ok(()), "the PLC owns the block");
    drop(plc);
    let mut flood: Vec<Raw> = Vec::new();
    let mut reconnects = Vec::new();
    // 20 connections a second for 60 s, as issue 35 asked; the flooder holds every
    // connection until the gateway closes it (those it closed are let go here, or the
    // test process would run out of descriptors).
    for i in 0..1200 {
        let host = if i % 2 == 0 {
            [127, 0, 0, 2]
        } else {
            [127, 0, 0, 3]
        };
        flood.push(Raw::connect_from(host, g.addr()));
        if i % 10 == 9 {
            flood.retain(|c| !c.closed_by_the_gateway());
            let t = Instant::now();
            let mut p = Raw::connect(g.addr());
            p.s.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
            reconnects.push((p.served(), t.elapsed().as_millis()));
        }
        // The flood's pace: 20 connections a second.
        std::thread::sleep(Duration::from_millis(50));
    }
    eprintln!(
        "PLC reconnects during the flood (served, ms): {reconnects:?}; connections the \
         gateway holds of the flood's: {}",
        flood.len()
    );
    // Served within 1 s each (the read timeout): a correctness bound, far above the
    // few ms they take.
    assert!(
        reconnects.iter().all(|(served, _)| *served),
        "{reconnects:?}\n{}",
        g.log()
    );
    assert!(
        g.log().contains("(plc.max_connections_per_peer)"),
        "{}",
        g.log()
    );
    drop(flood);
    let dir = g.dir.clone();
    drop(g);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_squatter_that_wrote_once_loses_the_block_to_the_plc() {
    let Some(py) = python() else { return };
    let g = Gateway::start("squat", &[(431, "431-plane.h")], "", &[]);
    // One register written, then silence, the connection kept (from another
    // address than the PLC's).
    let mut squatter = Raw::connect_from([127, 0, 0, 2], g.addr());
    assert_eq!(squatter.write(20, &[1], true), Ok(()));
    // The PLC's starts are refused (ServerDeviceBusy) until the squatter has been
    // silent for the owner timeout (10 s by default); then the PLC owns the block.
    let got = g.plc(&py, &["patient_run", "431"]);
    assert_eq!(got["cycle"], 431, "{got}");
    assert!(got["busy_refusals"].as_u64().unwrap() > 0, "{got}");
    assert!(
        g.log()
            .contains("takes the request block over from connection 1, silent for"),
        "{}",
        g.log()
    );
    assert_eq!(g.history_statuses(), ["done"]);
    drop(squatter);
}

#[test]
fn a_plc_that_lost_power_gets_its_block_back_at_once() {
    let Some(py) = python() else { return };
    let usable = Command::new("unshare")
        .args([
            "-rn", "ip", "link", "add", "name", "probe0", "type", "veth", "peer", "name", "probe1",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if !usable {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI: unshare -rn with ip link (util-linux, iproute2, user namespaces) is needed"
        );
        eprintln!("SKIPPED: no network namespaces with veth here (unshare -rn, ip)");
        return;
    }
    let dir = tmpdir("face-halfopen");
    let config = gateway_config(
        &dir,
        "halfopen",
        "tilted-plane.toml",
        &[(431, "431-plane.h")],
        "listen = \"10.77.0.1:0\"\n",
    );
    let gateway = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gateway");
    let log = dir.join("serve.log");
    let out = Command::new("unshare")
        .arg("-rn")
        .arg(&py)
        .arg(gateway.join("half_open.py"))
        .arg(env!("CARGO_BIN_EXE_probebridge"))
        .arg(&config)
        .arg(gateway.join("plc.py"))
        .arg("431")
        .arg(&log)
        .output()
        .unwrap();
    let serve_log = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        out.status.success(),
        "{}\nserve log:\n{serve_log}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["cycle"], 431, "{v}");
    assert_eq!(v["half_open"].as_array().unwrap().len(), 1, "{v}");
    // The block passed from the half-open connection to the new one of the same
    // address once the old one had been silent for 3 s, not after the owner timeout
    // of 10 s.
    assert!(v["busy_refusals"].as_u64().unwrap() < 20, "{v}");
    assert!(
        serve_log.contains("from connection 1 of the same address (the PLC connected again)"),
        "{serve_log}"
    );
}

#[test]
fn the_allow_list_refuses_other_peers_and_says_so_sparingly() {
    let Some(py) = python() else { return };
    let g = Gateway::start("allow", &[], "allow = [\"127.0.0.1\"]\n", &[]);
    // 200 connections from 127.0.0.2 (loopback too), then one from 127.0.0.1.
    let script = r#"
import socket, struct, sys
port = int(sys.argv[1])
def served(src):
    s = socket.socket()
    s.bind((src, 0))
    s.connect(("127.0.0.1", port))
    s.settimeout(120)
    s.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 32, 1))
    try:
        answer = s.recv(64)
    except ConnectionResetError:
        answer = b""
    s.close()
    return len(answer) > 0
refused = sum(not served("127.0.0.2") for _ in range(200))
print(refused, served("127.0.0.1"))
"#;
    let out = Command::new(&py)
        .args(["-c", script, &g.port.to_string()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "200 True");
    let log = g.log();
    let lines = log.matches("not in plc.allow").count();
    // The first refusal at once, then at most one line per 10 s.
    assert!((1..=5).contains(&lines), "{lines} lines:\n{log}");
    assert!(log.contains("refused 127.0.0.2:"), "{log}");
}

#[test]
fn a_connect_loop_does_not_flood_the_log() {
    let g = Gateway::start("flood", &[], "", &[]);
    for _ in 0..500 {
        let mut peer = Raw::connect(g.addr());
        assert!(peer.served());
    }
    let log = g.log();
    let face_lines = log.lines().filter(|l| l.contains("PLC face")).count();
    // Before: two INFO lines per connection. Now debug lines, and a summary a minute.
    assert!(face_lines <= 2, "{face_lines} lines:\n{log}");
}

#[test]
fn the_register_table_holds_at_its_edges() {
    let g = Gateway::start("edges", &[], "", &[]);
    // A program that is not UTF-8.
    std::fs::write(
        g.dir.join("programs/432.h"),
        b"0 BEGIN PGM 432 MM\n1 ; \xff\xfe\n2 END PGM 432 MM\n",
    )
    .unwrap();
    let mut plc = Raw::connect(g.addr());
    // FC16 of 124 registers: IllegalDataValue, and the connection stays.
    assert_eq!(plc.write(0, &[0; 124], false), Err(3));
    assert!(plc.served(), "the connection is still served");
    // A start of a program that does not exist: reason 3, nothing moves.
    assert_eq!(plc.request(1, 1, 999), Ok(()));
    let st = plc.acknowledged(1);
    assert_eq!((st[0], st[1], st[2]), (1, 0x8001, 3), "{st:?}");
    // FC6 to the sequence register alone would re-run the request block as it
    // stands: refused with IllegalDataValue, the sequence and the state unchanged.
    assert_eq!(plc.write(1, &[2], true), Err(3));
    assert_eq!(
        plc.write(0, &[1, 2], false),
        Err(3),
        "code and sequence only"
    );
    let st = plc.read(0, 2).unwrap().unwrap();
    assert_eq!(st, [1, 1], "the request block as it was");
    assert_eq!(plc.read(32, 1).unwrap().unwrap(), [1]);
    // A program that is not UTF-8: reason 4 (invalid), not 3 (no such program).
    assert_eq!(plc.request(1, 2, 432), Ok(()));
    let st = plc.acknowledged(2);
    assert_eq!((st[0], st[1], st[2]), (2, 0x8001, 4), "{st:?}");
    assert!(g.log().contains("not UTF-8"), "{}", g.log());
    // The heartbeat alone and the same sequence again are ordinary writes.
    assert_eq!(plc.write(20, &[7], true), Ok(()));
    assert_eq!(plc.write(1, &[2], true), Ok(()));
}

/// `serve` with this configuration: its exit status and stderr.
fn serve_fails(config: &Path) -> (std::process::ExitStatus, String) {
    let out = run(bin().args(["serve", "--config", config.to_str().unwrap()]));
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_port_in_use_and_a_broken_history_are_found_before_the_machine_opens() {
    // The machine is a Modbus PLC nobody serves: opening it fails. What is found
    // first says what is checked first.
    let dir = tmpdir("face-order");
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let plc = format!("listen = \"{}\"\n", taken.local_addr().unwrap());
    let config = gateway_config(&dir, "order", "plane-z10.toml", &[], &plc);
    let text = std::fs::read_to_string(&config)
        .unwrap()
        .replace("[programs]", "modbus = \"127.0.0.1:1\"\n[programs]");
    std::fs::write(&config, &text).unwrap();
    let (status, err) = serve_fails(&config);
    assert!(!status.success());
    assert!(
        err.contains("plc.listen: cannot bind") && !err.contains("cannot open the machine"),
        "{err}"
    );
    // The port free, a history that cannot open (its path is a folder): it is tried,
    // and said, before the machine. (A gateway whose history is down still starts: it
    // refuses starts with reason 9 and opens the history again in the background; see
    // history_faults.rs.)
    drop(taken);
    std::fs::create_dir_all(dir.join("history.sqlite")).unwrap();
    let text = text.replace(&plc, "listen = \"127.0.0.1:0\"\n");
    std::fs::write(&config, text).unwrap();
    let (status, err) = serve_fails(&config);
    assert!(!status.success());
    let history = err.find("history.sqlite: unable to open");
    let machine = err.find("cannot open the machine");
    assert!(
        matches!((history, machine), (Some(h), Some(m)) if h < m),
        "{err}"
    );
}

#[test]
fn oversized_gateway_machine_and_scenario_files_are_refused_at_once() {
    let (status, err) = serve_fails(Path::new("/dev/zero"));
    assert!(!status.success());
    assert!(
        err.contains("/dev/zero") && err.contains("larger than"),
        "{err}"
    );
    let dir = tmpdir("face-big");
    let big = dir.join("big.toml");
    std::fs::write(&big, "# padding\n".repeat(120_000)).unwrap();
    let config = gateway_config(&dir, "big", "tilted-plane.toml", &[], "");
    let text = std::fs::read_to_string(&config).unwrap();
    let scenario = configs().join("scenarios/tilted-plane.toml");
    let scenario = scenario.to_str().unwrap();
    for replaced in [
        text.replace(scenario, big.to_str().unwrap()),
        text.replace(
            &format!("scenario = {scenario:?}"),
            &format!("config = {:?}", big.to_str().unwrap()),
        ),
        format!("{text}\n{}", "# padding\n".repeat(120_000)),
    ] {
        std::fs::write(&config, replaced).unwrap();
        let (status, err) = serve_fails(&config);
        assert!(!status.success());
        assert!(err.contains("larger than 1048576 bytes"), "{err}");
    }
}

#[test]
fn a_plc_face_that_ends_ends_the_service_non_zero() {
    let mut g = Gateway::start("faceend", &[], "", &[("PROBEBRIDGE_FAULT_PLC_FACE", "end")]);
    let status = g.child.wait().unwrap();
    assert_eq!(status.code(), Some(1), "{}", g.log());
    assert!(g.log().contains("the PLC face is dead"), "{}", g.log());
}

/// A gateway whose PLC face stalls (the test-only fault switch), with systemd's notify
/// socket and a watchdog: returns once it has said "PLC face not answering", with the
/// socket and the notifications so far.
fn stalled_plc_face(name: &str) -> (Gateway, std::os::unix::net::UnixDatagram, Vec<String>) {
    // Not the gateway's own folder (pb-cli-face-NAME-PID), which it makes afresh.
    let dir = tmpdir(&format!("face-{name}-notify"));
    let socket = dir.join("notify.sock");
    let listener = std::os::unix::net::UnixDatagram::bind(&socket).unwrap();
    listener
        .set_read_timeout(Some(Duration::from_secs(120)))
        .unwrap();
    let g = Gateway::start(
        name,
        &[],
        "",
        &[
            ("PROBEBRIDGE_FAULT_PLC_FACE", "stall"),
            ("NOTIFY_SOCKET", socket.to_str().unwrap()),
            ("WATCHDOG_USEC", "200000"),
        ],
    );
    let mut buf = [0u8; 512];
    let mut seen = Vec::new();
    while !seen
        .iter()
        .any(|s: &String| s.contains("PLC face not answering"))
    {
        match listener.recv(&mut buf) {
            Ok(n) => seen.push(String::from_utf8_lossy(&buf[..n]).into_owned()),
            Err(e) => panic!("no notification ({e}) after {seen:?}\n{}", g.log()),
        }
    }
    (g, listener, seen)
}

/// A stop (SIGTERM) while the PLC face is stalled (its thread never returns) ends the
/// service as any stop does (exit 0), the stalled face left behind. Before: the stop
/// waited for the face's thread for good, and systemd killed the service after
/// TimeoutStopSec (30 s: the systemd VM's restart after its wedged face took that much
/// longer than the others).
#[test]
fn a_stop_while_the_plc_face_is_stalled_leaves_the_face_behind() {
    let (mut g, _, _) = stalled_plc_face("stall-stop");
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(g.child.id() as i32, libc::SIGTERM) };
    // A safety net, not a timed assertion: without the fix the process never exits.
    let mut status = None;
    for _ in 0..600 {
        status = g.child.try_wait().unwrap();
        if status.is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let Some(status) = status else {
        let _ = g.child.kill();
        panic!("the stop hung on the stalled face's thread\n{}", g.log())
    };
    assert_eq!(status.code(), Some(0), "{}", g.log());
    assert!(
        g.log()
            .contains("the PLC face is not answering: stopping without it"),
        "{}",
        g.log()
    );
}

#[test]
fn a_stalled_plc_face_starves_the_watchdog_and_ends_the_service() {
    let (mut g, listener, mut seen) = stalled_plc_face("stall");
    let mut buf = [0u8; 512];
    let status = g.child.wait().unwrap();
    assert_eq!(status.code(), Some(1), "{}", g.log());
    listener.set_nonblocking(true).unwrap();
    while let Ok(n) = listener.recv(&mut buf) {
        seen.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    let stall = seen
        .iter()
        .position(|s| s.contains("PLC face not answering"))
        .unwrap();
    assert!(
        seen[..stall].iter().any(|s| s.contains("WATCHDOG=1")),
        "{seen:?}"
    );
    assert!(
        !seen[stall..].iter().any(|s| s.contains("WATCHDOG=1")),
        "fed after the stall: {seen:?}"
    );
    assert!(g.log().contains("the PLC face is dead"), "{}", g.log());
}
