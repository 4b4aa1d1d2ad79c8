//! `[bus] kind = "modbus"` in a machine TOML: accepted as documented, and every bad
//! value refused at load with the file, the key and the reason.

use probebridge_hal::config::{BusConfig, MachineConfig};
use probebridge_hal::modbus::{CaptureKind, Transport, WordOrder};
use std::path::Path;

const AXES: &str = r#"
name = "plc"
[[axis]]
name = "X"
node = 1
increments_per_unit = 1000000.0
min = -400.0
max = 400.0
max_feed = 10000.0
max_acceleration = 2000.0
[[axis]]
name = "Y"
node = 2
increments_per_unit = 1000000.0
min = -300.0
max = 300.0
max_feed = 10000.0
max_acceleration = 2000.0
[[axis]]
name = "Z"
node = 3
increments_per_unit = 1000000.0
min = -200.0
max = 400.0
max_feed = 10000.0
max_acceleration = 2000.0
"#;

const BUS: &str = r#"
[bus]
kind = "modbus"
transport = "tcp"
address = "192.168.0.10:502"
unit = 1
timeout_ms = 200
word_order = "CDAB"
command_base = 0
status_base = 100
ring_base = 200
ring_slots = 4
capture = "plc_cycle"
plc_cycle_us = 1000
"#;

fn parse(bus: &str) -> Result<MachineConfig, String> {
    MachineConfig::parse(&format!("{AXES}{bus}"), Path::new("plc.toml")).map_err(|e| e.to_string())
}

fn refused(bus: &str, key: &str, reason: &str) {
    let e = parse(bus).expect_err("bad config accepted");
    assert!(
        e.starts_with("plc.toml") && e.contains(key) && e.contains(reason),
        "want file, key {key:?} and reason {reason:?} in: {e}"
    );
}

#[test]
fn the_documented_example_parses() {
    let c = parse(BUS).unwrap();
    let BusConfig::Modbus(m) = &c.bus else {
        panic!("not modbus: {:?}", c.bus)
    };
    assert_eq!(m.transport, Transport::Tcp);
    assert_eq!(m.word_order, WordOrder::CDAB);
    assert_eq!(m.capture, CaptureKind::PlcCycle);
    assert_eq!((m.max_read, m.max_write), (125, 123));
    assert!(c.canopen_bus().is_none());
    assert_eq!(c.modbus_bus(), Some(m));
}

#[test]
fn an_unknown_word_order_is_refused() {
    refused(
        &BUS.replace("\"CDAB\"", "\"BACD\""),
        "word_order: \"BACD\" is not one of \"ABCD\" \"CDAB\" \"BADC\" \"DCBA\"",
        "[bus]",
    );
}

#[test]
fn overlapping_blocks_are_refused() {
    // The status block (22 registers from 100) runs into a ring at 110.
    refused(
        &BUS.replace("ring_base = 200", "ring_base = 110"),
        "bus.ring_base",
        "overlap status_base (100..121)",
    );
    refused(
        &BUS.replace("status_base = 100", "status_base = 19"),
        "bus.status_base",
        "overlap command_base (0..19)",
    );
}

#[test]
fn a_ring_of_zero_slots_is_refused() {
    refused(
        &BUS.replace("ring_slots = 4", "ring_slots = 0"),
        "bus.ring_slots",
        "at least one slot",
    );
}

#[test]
fn more_than_125_registers_in_one_read_is_refused() {
    // 8 slots of 18 registers = 144, read whole in one request.
    refused(
        &BUS.replace("ring_slots = 4", "ring_slots = 8"),
        "bus.ring_slots",
        "144 registers, more than one read of 125",
    );
    refused(
        &BUS.replace("unit = 1", "unit = 1\nmax_read = 200"),
        "bus.max_read",
        "Modbus reads 1..125 at once",
    );
    refused(
        &BUS.replace("unit = 1", "unit = 1\nmax_write = 124"),
        "bus.max_write",
        "Modbus writes 1..123 at once",
    );
    // A device limit below a block is refused too.
    refused(
        &BUS.replace("unit = 1", "unit = 1\nmax_read = 64"),
        "bus.ring_slots",
        "72 registers, more than one read of 64",
    );
}

#[test]
fn other_bad_values_name_their_key() {
    refused(
        &BUS.replace("address = \"192.168.0.10:502\"\n", ""),
        "bus.address",
        "needs an address",
    );
    refused(
        &BUS.replace("transport = \"tcp\"", "transport = \"rtu\""),
        "bus.device",
        "needs a serial device",
    );
    refused(
        &BUS.replace("ring_slots = 4", "ring_slots = 3"),
        "bus.ring_slots",
        "must divide 65536",
    );
    refused(
        &BUS.replace("unit = 1", "unit = 1\ncounts_per_mm = 1e7"),
        "bus.counts_per_mm",
        "overflow the PLC's 32-bit position",
    );
    refused(
        &BUS.replace("unit = 1", "unit = 1\nbaud_rate = 9600"),
        "baud_rate",
        "unknown field",
    );
    refused(
        &BUS.replace("kind = \"modbus\"", "kind = \"profibus\""),
        "profibus",
        "unknown variant",
    );
}
