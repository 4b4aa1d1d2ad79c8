//! The gateway's web face (`[web] listen`) from a running `probebridge serve` on the
//! simulator, with a stored history: five weekly 451 runs of table-ac whose EX0C
//! drifts (4 µm a week, then 12 µm in the last week: over the 5 µm alarm), and a
//! machine whose stored name carries markup. Over raw HTTP: GET and HEAD only, the
//! fixed list of paths, the Content-Security-Policy, the connection cap and the request
//! timeout. In headless Chromium: every page's elements in the DOM, a clean console
//! (no CSP refusal), the alarm on exactly the run that crossed the threshold, the
//! tampered name inert.

#[path = "common/browser.rs"]
mod browser;
mod common;
#[path = "common/stored_history.rs"]
mod stored_history;

use common::*;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Stdio};
use std::time::Duration;
use stored_history::{store, StoredRun};

const TAMPERED: &str = "<img src=x onerror=alert(1)>\"'";

struct Serve {
    child: Child,
    web: SocketAddr,
    dir: PathBuf,
}

impl Drop for Serve {
    fn drop(&mut self) {
        // SAFETY: signalling our own child.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        let _ = self.child.wait();
    }
}

/// The stored history; the ids of table-ac's runs.
fn history(dir: &std::path::Path) -> Vec<i64> {
    let db = dir.join("history.sqlite");
    let ex0c = [0.012, 0.016, 0.020, 0.024, 0.036];
    let mut ids = Vec::new();
    for (week, ex) in ex0c.iter().enumerate() {
        let started = format!(
            "2026-{}T07:30:00Z",
            ["10-28", "11-04", "11-11", "11-18", "11-25"][week]
        );
        let errors = [
            ("EX0C", 0.0, *ex),
            ("EY0C", 0.0, -0.008 + 0.0002 * week as f64),
            ("EA0C", 0.0, 0.0005),
            ("EB0C", 0.0, -0.0003),
            ("EY0A", 0.0, 0.003),
            ("EZ0A", 0.0, -0.002),
        ];
        let dispersion = [("A", 0.0021, 0.0008), ("C", 0.0034, 0.0011)];
        ids.extend(store(
            &db,
            &[StoredRun {
                machine: "table-ac",
                started: &started,
                errors: &errors,
                dispersion: &dispersion,
                max_modification: 0.03,
                program: "/etc/probebridge/programs/451.h",
            }],
        ));
    }
    store(
        &db,
        &[StoredRun {
            machine: TAMPERED,
            started: "2026-11-20T10:00:00Z",
            errors: &[("EX0C\"><script>alert(2)</script>", 0.0, 0.001)],
            dispersion: &[],
            max_modification: 0.03,
            program: "/p/451.h",
        }],
    );
    ids
}

fn start(dir: PathBuf, web: &str) -> Serve {
    let folder = dir.join("programs");
    let logs = dir.join("logs");
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::create_dir_all(&logs).unwrap();
    let config = dir.join("gateway.toml");
    std::fs::write(
        &config,
        format!(
            "[machine]\nscenario = {:?}\nservice = \"pbweb-{}\"\nkinematics = {:?}\n\
             [programs]\nfolder = \"programs\"\nout = \"logs\"\n\
             [history]\nsqlite = \"history.sqlite\"\nalarm_um = 5.0\n{HISTORY_TIMEOUT}\
             [plc]\nlisten = \"127.0.0.1:0\"\n[web]\n{web}",
            configs()
                .join("scenarios/demo-sphere.toml")
                .to_str()
                .unwrap(),
            std::process::id(),
            dir.join("kinematics.toml").to_str().unwrap(),
        ),
    )
    .unwrap();
    let log = std::fs::File::create(dir.join("serve.log")).unwrap();
    let mut child = bin()
        .args(["serve", "--config", config.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(log)
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut lines = [String::new(), String::new()];
    for l in &mut lines {
        out.read_line(l).unwrap();
    }
    let Some(web) = lines[1]
        .trim()
        .strip_prefix("probebridge serve: web face on http://")
    else {
        let _ = child.kill();
        let log = std::fs::read_to_string(dir.join("serve.log")).unwrap_or_default();
        panic!("serve did not say its web face: {lines:?}\n{log}");
    };
    let web = web.parse().unwrap();
    Serve { child, web, dir }
}

/// One request on its own connection; (status line, head, body).
fn request(addr: SocketAddr, method: &str, path: &str) -> (String, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut all = Vec::new();
    s.read_to_end(&mut all).unwrap();
    let split = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("an HTTP answer");
    let head = String::from_utf8_lossy(&all[..split]).into_owned();
    let status = head.lines().next().unwrap().to_string();
    (status, head.to_lowercase(), all[split + 4..].to_vec())
}

#[test]
fn the_web_face_serves_trend_protocols_and_status_read_only() {
    let dir = tmpdir("web-face");
    let ids = history(&dir);
    // A measuring protocol of a real 451 in the logs folder.
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).unwrap();
    let (out, _) = run_program(
        &configs().join("programs/451-check.h"),
        &configs().join("scenarios/demo-sphere.toml"),
        &logs,
        &[
            "--yes",
            "--kinematics",
            dir.join("k0.toml").to_str().unwrap(),
        ],
    );
    assert!(out.status.success());
    assert!(logs.join("TCHPRAUTO.html").is_file());
    let serve = start(
        dir.clone(),
        "listen = \"127.0.0.1:0\"\nmax_connections = 3\nrequest_timeout_ms = 3000\n",
    );
    let web = serve.web;
    assert!(web.ip().is_loopback());

    // The fixed list of pages, each with the strict policy.
    for path in [
        "/",
        "/status",
        "/trend",
        "/trend/1",
        "/trend/2",
        "/protocols",
        "/style.css",
    ] {
        let (status, head, body) = request(web, "GET", path);
        assert_eq!(status, "HTTP/1.1 200 OK", "{path}");
        assert!(
            head.contains("content-security-policy: default-src 'none'; style-src 'self';"),
            "{path}: {head}"
        );
        assert!(head.contains("x-content-type-options: nosniff"));
        assert!(!body.is_empty());
    }
    let (status, head, body) = request(web, "GET", "/protocols/TCHPRAUTO.html");
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(
        head.contains("sandbox") && !head.contains("script-src"),
        "{head}"
    );
    assert_eq!(body, std::fs::read(logs.join("TCHPRAUTO.html")).unwrap());
    // HEAD: the head alone.
    let (status, head, body) = request(web, "HEAD", "/trend");
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(
        head.contains("content-length:") && body.is_empty(),
        "{head}"
    );
    // Read-only.
    for method in ["POST", "PUT", "DELETE", "OPTIONS"] {
        let (status, head, _) = request(web, method, "/");
        assert_eq!(status, "HTTP/1.1 405 Method Not Allowed", "{method}");
        assert!(head.contains("allow: get, head"));
    }
    // Nothing else reaches the file system.
    for path in [
        "/protocols/../gateway.toml",
        "/protocols/%2e%2e/gateway.toml",
        "/protocols/TCHPR431.TXT/../../gateway.toml",
        "/gateway.toml",
        "/logs/TCHPRAUTO.html",
        "/protocols/tchprauto.html",
        "/trend/01",
        "/trend/3",
        "/trend/0",
    ] {
        let (status, _, body) = request(web, "GET", path);
        assert_eq!(status, "HTTP/1.1 404 Not Found", "{path}");
        assert!(!String::from_utf8_lossy(&body).contains("[machine]"));
    }
    // A protocol not written yet is a 404, not an error of the service.
    let (status, _, _) = request(web, "GET", "/protocols/TCHPR431.TXT");
    assert_eq!(status, "HTTP/1.1 404 Not Found");

    browser_checks(&serve, &ids);

    // Request timeout: a client that sends nothing is closed (read ends, no error).
    let mut idle = TcpStream::connect(web).unwrap();
    idle.set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    let mut buf = [0u8; 64];
    let n = idle
        .read(&mut buf)
        .expect("closed by the face, not by our guard");
    assert_eq!(n, 0);
    // Connection cap: three held, the fourth is closed at once without an answer.
    let held: Vec<TcpStream> = (0..3).map(|_| TcpStream::connect(web).unwrap()).collect();
    let mut fourth = TcpStream::connect(web).unwrap();
    fourth
        .set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    let _ = fourth.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n");
    let mut answer = Vec::new();
    let _ = fourth.read_to_end(&mut answer);
    assert!(answer.is_empty(), "{}", String::from_utf8_lossy(&answer));
    drop(held);
    let log = std::fs::read_to_string(serve.dir.join("serve.log")).unwrap();
    assert!(log.contains("web face: connection limit reached"), "{log}");
}

fn browser_checks(serve: &Serve, ids: &[i64]) {
    let Some(browser) = browser::Browser::find(&serve.dir.join("chromium-profile")) else {
        return;
    };
    let base = format!("http://{}", serve.web);
    let mut pages = std::collections::BTreeMap::new();
    for path in [
        "/",
        "/trend",
        "/trend/1",
        "/trend/2",
        "/protocols",
        "/protocols/TCHPRAUTO.html",
    ] {
        let page = browser.load(&format!("{base}{path}"));
        assert!(page.console.is_empty(), "{path} logged: {:?}", page.console);
        pages.insert(path, page.dom);
    }
    // The status page.
    let status = &pages["/"];
    assert!(status.contains("<td id=\"state\">idle</td>"), "{status}");
    assert!(status.contains("id=\"machine-ok\" class=\"ok\""));
    assert!(status.contains("<progress"));
    // The index of the two machines links both pages; the tampered name is text.
    let index = &pages["/trend"];
    assert!(index.contains("href=\"/trend/2\">table-ac</a>"), "{index}");
    assert!(index.contains("&lt;img src=x onerror=alert(1)&gt;"));
    // table-ac: six errors and two dispersions, before and after per run; the alarm
    // ring on exactly the last run (EX0C +12 µm > 5 µm), nowhere else.
    let table = &pages["/trend/2"];
    assert_eq!(table.matches("<svg class=\"trend\"").count(), 8, "{table}");
    assert_eq!(table.matches("class=\"pt after\"").count(), 8 * 5);
    assert_eq!(table.matches("class=\"pt before\"").count(), 8 * 5);
    assert_eq!(table.matches("class=\"alarm-ring\"").count(), 1);
    let last = ids[4];
    assert!(table.contains(&format!("class=\"alarm-ring\" data-run=\"{last}\"")));
    let ex0c_chart = &table[table
        .find("<text class=\"title\" x=\"72\" y=\"18\">EX0C<")
        .unwrap()..];
    let ex0c_chart = &ex0c_chart[..ex0c_chart.find("</figure>").unwrap()];
    assert!(
        ex0c_chart.contains("alarm-ring"),
        "the ring is on EX0C's chart"
    );
    // Units, dates, the latest value and its change beside the chart.
    assert!(ex0c_chart.contains("EX0C (µm)"));
    assert!(ex0c_chart.contains(">11-25<") && ex0c_chart.contains(">10-28<"));
    assert!(
        ex0c_chart.contains("class=\"value latest\">+36.0 µm"),
        "{ex0c_chart}"
    );
    assert!(ex0c_chart.contains("class=\"value change bad\">+12.0 µm"));
    assert!(
        ex0c_chart.contains("OUT OF TOLERANCE"),
        "36 µm > 30 µm maxModification"
    );
    // The headline names the drift without an axis read.
    let headline = &table[table.find("id=\"headline\"").unwrap()..];
    let headline = &headline[..headline.find("</p>").unwrap()];
    assert!(
        headline.contains("<b>EX0C</b>")
            && headline.contains("<b>+24.0 µm</b> over 5 run(s)")
            && headline.contains("<b>+12.0 µm</b> since the previous run (2026-11-18 07:30)"),
        "{headline}"
    );
    // The tampered machine's page: no element made of its name.
    let tampered = &pages["/trend/1"];
    for bad in ["<img", "<script"] {
        assert!(!tampered.contains(bad), "{bad} in {tampered}");
    }
    for tag in tampered
        .split('<')
        .filter_map(|t| t.split_once('>'))
        .map(|t| t.0)
    {
        assert!(!tag.contains(" onerror="), "<{tag}>");
    }
    assert!(pages["/protocols"].contains("href=\"/protocols/TCHPRAUTO.html\""));
    assert!(pages["/protocols/TCHPRAUTO.html"].contains("<svg"));
    let shot = serve.dir.join("trend.png");
    browser.screenshot(
        &format!("{base}/trend/2"),
        &shot,
        "1100,1500",
        "PROBEBRIDGE_WEB_TREND_SCREENSHOT",
    );
    browser.screenshot(
        &format!("{base}/"),
        &serve.dir.join("status.png"),
        "800,360",
        "PROBEBRIDGE_WEB_STATUS_SCREENSHOT",
    );
}

/// Issue 35: a slowloris (the three places held, then 200 connections) wrote one WARN
/// line per refused connection (3872 in 60 s at the plant), pushing the service's own
/// lines out of journald's rate limit. Now one line per 10 s with the count held back.
#[test]
fn a_slowloris_costs_one_warning_not_one_per_refused_connection() {
    let dir = tmpdir("web-slowloris");
    let serve = start(
        dir.clone(),
        "listen = \"127.0.0.1:0\"\nmax_connections = 3\nrequest_timeout_ms = 60000\n",
    );
    let held: Vec<TcpStream> = (0..3)
        .map(|_| TcpStream::connect(serve.web).unwrap())
        .collect();
    // Each one closed by the face (end of file) before the next: all 200 were seen.
    for _ in 0..200 {
        let mut s = TcpStream::connect(serve.web).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        assert_eq!(
            s.read(&mut [0u8; 16]).unwrap(),
            0,
            "closed without an answer"
        );
    }
    let log = std::fs::read_to_string(dir.join("serve.log")).unwrap();
    let warnings = log.matches("connection limit reached").count();
    eprintln!("200 refused connections: {warnings} warning line(s)");
    assert_eq!(warnings, 1, "{log}");
    drop(held);
    let _ = std::fs::remove_dir_all(&dir);
}
