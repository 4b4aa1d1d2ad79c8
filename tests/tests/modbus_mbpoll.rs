//! mbpoll (a third-party Modbus master) reads the simulated PLC's status block at the
//! addresses of docs/modbus.md (zero-based, `-0`) and word order: 16-bit fields, and the actual
//! positions as 32-bit integers, CDAB (mbpoll's default word order) and ABCD (`-B`).
//! Skipped with a line saying why where mbpoll is missing, never in CI
//! (`scripts/install-test-peers` installs it).

use hal::modbus::WordOrder;
use hal::{Axis, AxisPositions, Machine};
use probebridge_tests::conformance_modbus::open_tcp;
use std::collections::BTreeMap;
use std::process::Command;

fn have_mbpoll() -> bool {
    if Command::new("mbpoll").arg("-V").output().is_ok() {
        return true;
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "mbpoll missing in CI: scripts/install-test-peers should have installed it"
    );
    eprintln!("SKIPPED: mbpoll is not installed (scripts/install-test-peers)");
    false
}

/// `mbpoll -1 -0 ...`: register address -> value.
fn mbpoll(port: u16, args: &[&str]) -> BTreeMap<u16, i64> {
    let out = Command::new("mbpoll")
        .args(["-m", "tcp", "-a", "1", "-0", "-1", "-p", &port.to_string()])
        .args(args)
        .arg("127.0.0.1")
        .output()
        .expect("run mbpoll");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "mbpoll failed:\n{text}");
    text.lines()
        .filter_map(|l| {
            let (a, v) = l.trim().strip_prefix('[')?.split_once("]:")?;
            Some((a.parse().ok()?, v.trim().parse().ok()?))
        })
        .collect()
}

#[test]
fn mbpoll_reads_the_status_block_at_the_documented_addresses() {
    if !have_mbpoll() {
        return;
    }
    for (order, flag) in [(WordOrder::CDAB, None), (WordOrder::ABCD, Some("-B"))] {
        let sc = probebridge_tests::scenario(
            "machine = \"table-ac\"\n[probe]\nball_radius = 3.0\n[[plane]]\npoint = [0.0, 0.0, -150.0]\nnormal = [0.0, 0.0, 1.0]\n",
        );
        let mut m = open_tcp(&sc, |b| b.word_order = order);
        let target = AxisPositions::linear([12.345678, -7.5, 80.0]).with(Axis::C, -90.0);
        m.move_to(&target, 5000.0).unwrap();
        let port = m.plc.local_addr().unwrap().port();
        // Status block at 100: 16-bit fields.
        let s = mbpoll(port, &["-r", "100", "-c", "8", "-t", "4"]);
        assert_eq!(s[&101], 1, "acknowledged command sequence: {s:?}");
        assert_eq!(s[&102], 1, "done command sequence: {s:?}");
        assert_eq!(s[&103], 0b101, "ready + in position: {s:?}");
        assert_eq!(s[&104], 0, "result ok: {s:?}");
        // Actual positions at 108..119, 32-bit counts (1e6 per mm / deg).
        let mut args = vec!["-r", "108", "-c", "6", "-t", "4:int"];
        args.extend(flag);
        let p = mbpoll(port, &args);
        assert_eq!(p[&108], 12_345_678, "{order}: {p:?}");
        assert_eq!(p[&110], -7_500_000, "{order}: {p:?}");
        assert_eq!(p[&112], 80_000_000, "{order}: {p:?}");
        assert_eq!(p[&118], -90_000_000, "{order}: {p:?}");
    }
}
