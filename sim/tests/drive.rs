//! The simulated drive as any CANopen master sees it (CiA 301 / CiA 402): every
//! request and every answer written out as the bytes on the bus (candump notation),
//! node 1 throughout.

use hal::can::{candump, CanFrame};
use probebridge_sim::drive::SimDrive;

fn fr(s: &str) -> CanFrame {
    candump::parse_line(&format!("(0.0) can0 {s}"))
        .unwrap_or_else(|e| panic!("{s}: {e}"))
        .2
}

fn texts(frames: Vec<CanFrame>) -> Vec<String> {
    frames.iter().map(|f| format!("{f:?}")).collect()
}

/// A drive at position 0 and its clock.
struct Bench {
    d: SimDrive,
}

impl Bench {
    fn new() -> Self {
        Self {
            d: SimDrive::new(1, 0),
        }
    }

    /// Sends `frame` to the drive; its answers.
    fn rx(&mut self, frame: &str) -> Vec<String> {
        let mut out = Vec::new();
        self.d.on_frame(&fr(frame), &mut |f| out.push(*f));
        texts(out)
    }

    /// Sends a frame the drive must acknowledge with exactly `answer`.
    fn expect(&mut self, frame: &str, answer: &str) {
        assert_eq!(self.rx(frame), [answer], "request {frame}");
    }

    /// A SYNC as the simulated machine handles it, at `now_us`: synchronous RPDO data
    /// takes effect, one step (the axis goes where it is told), the answer.
    fn sync(&mut self, now_us: u64) -> Vec<String> {
        let mut out = Vec::new();
        self.d.on_sync();
        self.d.begin_step();
        let to = self.d.next_position_inc();
        self.d.end_step(to, None, false);
        self.d.answer_sync(now_us, &mut |f| out.push(*f));
        texts(out)
    }

    fn poll(&mut self, now_us: u64) -> Vec<String> {
        let mut out = Vec::new();
        self.d.poll(now_us, &mut |f| out.push(*f));
        texts(out)
    }

    fn statusword(&mut self) -> String {
        let r = self.rx("601#4041600000000000");
        assert_eq!(r.len(), 1);
        r[0].clone()
    }

    /// RPDO1 on 0x201 and RPDO2 on 0x301, both mapping the controlword: RPDO1 with
    /// transmission type `tt1`, RPDO2 with 255 (event-driven).
    fn map_controlword_rpdos(&mut self, tt1: u8) {
        for (req, ans) in [
            ("601#2300140101020080", "581#6000140100000000"),
            (
                &format!("601#2F001402{tt1:02X}000000"),
                "581#6000140200000000",
            ),
            ("601#2F00160000000000", "581#6000160000000000"),
            ("601#2300160110004060", "581#6000160100000000"),
            ("601#2F00160001000000", "581#6000160000000000"),
            ("601#2300140101020000", "581#6000140100000000"),
            ("601#2301140101030080", "581#6001140100000000"),
            ("601#2F011402FF000000", "581#6001140200000000"),
            ("601#2F01160000000000", "581#6001160000000000"),
            ("601#2301160110004060", "581#6001160100000000"),
            ("601#2F01160001000000", "581#6001160000000000"),
            ("601#2301140101030000", "581#6001140100000000"),
        ] {
            self.expect(req, ans);
        }
    }
}

#[test]
fn boot_up_at_power_on_and_after_every_reset() {
    let mut b = Bench::new();
    let mut out = Vec::new();
    b.d.power_on(&mut |f| out.push(*f));
    assert_eq!(texts(out), ["701#00"]);
    assert_eq!(b.rx("000#8201"), ["701#00"]);
    assert_eq!(b.rx("000#8101"), ["701#00"]);
    assert_eq!(b.rx("000#8100"), ["701#00"]);
    // Another node's reset.
    assert_eq!(b.rx("000#8102"), Vec::<String>::new());
}

#[test]
fn heartbeat_is_timed_by_0x1017_on_the_drive_clock_without_sync() {
    let mut b = Bench::new();
    b.expect("601#2B17100064000000", "581#6017100000000000"); // 100 ms
    assert!(b.poll(1_000).is_empty(), "the producer starts now");
    assert!(b.poll(100_999).is_empty());
    assert_eq!(b.poll(101_000), ["701#7F"]);
    assert!(b.poll(150_000).is_empty());
    assert_eq!(b.poll(201_000), ["701#7F"]);
    assert_eq!(b.d.next_deadline_us(), Some(301_000));
    assert!(b.rx("000#0101").is_empty());
    assert_eq!(b.poll(301_500), ["701#05"]);
    assert!(b.rx("000#0201").is_empty());
    assert_eq!(b.poll(401_000), ["701#04"], "heartbeats go on in stopped");
    assert!(b.rx("000#8001").is_empty());
    b.expect("601#2B17100000000000", "581#6017100000000000");
    assert!(b.poll(10_000_000).is_empty(), "0: no heartbeat");
    assert_eq!(b.d.next_deadline_us(), None);
}

#[test]
fn reset_communication_restores_only_the_communication_area() {
    let mut b = Bench::new();
    b.expect("601#2F60600008000000", "581#6060600000000000");
    b.expect("601#2B17100064000000", "581#6017100000000000");
    b.expect("601#23061000E8030000", "581#6006100000000000");
    assert_eq!(b.rx("000#8201"), ["701#00"]);
    b.expect("601#4060600000000000", "581#4F60600008000000");
    b.expect("601#4017100000000000", "581#4B17100000000000");
    b.expect("601#4006100000000000", "581#43061000D0070000");
    // Reset node restores the drive profile area too.
    assert_eq!(b.rx("000#8101"), ["701#00"]);
    b.expect("601#4060600000000000", "581#4F60600000000000");
}

#[test]
fn identity_sync_emcy_cob_ids_and_supported_modes() {
    let mut b = Bench::new();
    b.expect("601#4018100000000000", "581#4F18100004000000");
    b.expect("601#4018100100000000", "581#4318100100000000");
    b.expect("601#4018100200000000", "581#4318100202040000");
    b.expect("601#4018100300000000", "581#4318100300000100");
    b.expect("601#4018100400000000", "581#4318100401000000");
    b.expect("601#4005100000000000", "581#4305100080000000");
    b.expect("601#4014100000000000", "581#4314100081000000");
    b.expect("601#4002650000000000", "581#4302650080000000");
    // The drive consumes SYNC; it cannot be made the producer (bit 30).
    b.expect("601#2305100080000040", "581#8005100030000906");
    b.expect("601#2305100080000000", "581#6005100000000000");
}

#[test]
fn abort_codes_name_the_reason() {
    let mut b = Bench::new();
    // Write to an existing read-only object: 0x06010002.
    b.expect("601#2B41600000000000", "581#8041600002000106");
    b.expect("601#2300100000000000", "581#8000100002000106");
    b.expect("601#2318100101000000", "581#8018100102000106");
    // Missing sub-index of an existing object: 0x06090011.
    b.expect("601#4041600100000000", "581#8041600111000906");
    b.expect("601#2B40600106000000", "581#8040600111000906");
    b.expect("601#4018100500000000", "581#8018100511000906");
    b.expect("601#4000180400000000", "581#8000180411000906");
    // Missing object: 0x06020000.
    b.expect("601#4000200000000000", "581#8000200000000206");
}

#[test]
fn emcy_error_register_is_0x1001() {
    let mut b = Bench::new();
    b.d.raise_fault(0x2310);
    assert_eq!(b.sync(2_000), ["081#1023030000000000"]);
    b.expect("601#4001100000000000", "581#4F01100003000000");
    b.expect("601#403F600000000000", "581#4B3F600010230000");

    // A communication error: an RPDO of the wrong length.
    let mut b = Bench::new();
    b.map_controlword_rpdos(255);
    assert!(b.rx("000#0101").is_empty());
    assert_eq!(b.rx("201#06"), ["081#1082110000000000"]);
    b.expect("601#4001100000000000", "581#4F01100011000000");
    // The next good one ends it: "error reset", register 0.
    assert_eq!(b.rx("201#0600"), ["081#0000000000000000"]);
    b.expect("601#4001100000000000", "581#4F01100000000000");
}

#[test]
fn tpdo_transmission_types_every_nth_sync_and_on_change() {
    let mut b = Bench::new();
    for (req, ans) in [
        ("601#23001801810100C0", "581#6000180100000000"),
        ("601#2F00180203000000", "581#6000180200000000"),
        ("601#2F001A0000000000", "581#60001A0000000000"),
        ("601#23001A0110004160", "581#60001A0100000000"),
        ("601#2F001A0001000000", "581#60001A0000000000"),
        ("601#2300180181010040", "581#6000180100000000"),
        // TPDO2: the statusword, acyclic synchronous (0): at SYNC, when it changed.
        ("601#23011801810200C0", "581#6001180100000000"),
        ("601#2F01180200000000", "581#6001180200000000"),
        ("601#2F011A0000000000", "581#60011A0000000000"),
        ("601#23011A0110004160", "581#60011A0100000000"),
        ("601#2F011A0001000000", "581#60011A0000000000"),
        ("601#2301180181020040", "581#6001180100000000"),
    ] {
        b.expect(req, ans);
    }
    assert!(b.rx("000#0101").is_empty());
    let syncs: Vec<Vec<String>> = (1..=6).map(|i| b.sync(i * 2000)).collect();
    assert_eq!(
        syncs,
        [
            vec!["281#4002"],
            vec![],
            vec!["181#4002"],
            vec![],
            vec![],
            vec!["181#4002"],
        ]
    );
    b.expect("601#2B40600006000000", "581#6040600000000000");
    assert_eq!(b.sync(14_000), ["281#3102"]);
}

#[test]
fn event_driven_tpdo_goes_out_when_its_data_changes() {
    let mut b = Bench::new();
    for (req, ans) in [
        ("601#23011801810200C0", "581#6001180100000000"),
        ("601#2F011802FF000000", "581#6001180200000000"),
        ("601#2F011A0000000000", "581#60011A0000000000"),
        ("601#23011A011000B960", "581#60011A0100000000"),
        ("601#2F011A0001000000", "581#60011A0000000000"),
        ("601#2301180181020040", "581#6001180100000000"),
    ] {
        b.expect(req, ans);
    }
    assert!(b.rx("000#0101").is_empty());
    assert_eq!(b.poll(1_000), ["281#0000"]);
    assert!(b.poll(2_000).is_empty());
    b.expect("601#2BB8600011000000", "581#60B8600000000000");
    assert_eq!(b.poll(3_000), ["281#0100"]);
    assert!(b.sync(4_000).is_empty());
}

#[test]
fn controlword_by_sdo_drives_the_state_machine_and_0x6041_shows_it() {
    let mut b = Bench::new();
    b.expect("601#2F60600008000000", "581#6060600000000000");
    assert_eq!(b.statusword(), "581#4B41600040020000");
    b.expect("601#2B40600006000000", "581#6040600000000000");
    // Ready to switch on, voltage enabled (bit 4), remote.
    assert_eq!(b.statusword(), "581#4B41600031020000");
    b.expect("601#2B40600007000000", "581#6040600000000000");
    assert_eq!(b.statusword(), "581#4B41600033020000");
    b.expect("601#2B4060000F000000", "581#6040600000000000");
    // Operation enabled in cyclic synchronous position: bit 12 (follows the target)
    // and bit 4 (voltage enabled).
    assert_eq!(b.statusword(), "581#4B41600037120000");
}

#[test]
fn synchronous_rpdo_takes_effect_at_the_next_sync_event_driven_on_arrival() {
    let mut b = Bench::new();
    b.map_controlword_rpdos(1);
    assert!(b.rx("000#0101").is_empty());
    assert!(b.rx("201#0600").is_empty());
    assert_eq!(
        b.statusword(),
        "581#4B41600040020000",
        "not before the SYNC"
    );
    b.sync(2_000);
    assert_eq!(b.statusword(), "581#4B41600031020000");
    // RPDO2, event-driven: at once.
    assert!(b.rx("301#0700").is_empty());
    assert_eq!(b.statusword(), "581#4B41600033020000");
}

#[test]
fn touch_probe_status_follows_an_sdo_write_of_the_function() {
    let mut b = Bench::new();
    b.expect("601#40B9600000000000", "581#4BB9600000000000");
    b.expect("601#2BB8600011000000", "581#60B8600000000000");
    b.expect("601#40B9600000000000", "581#4BB9600001000000");
    b.expect("601#2BB8600000000000", "581#60B8600000000000");
    b.expect("601#40B9600000000000", "581#4BB9600000000000");
}

#[test]
fn no_emcy_in_stopped_it_goes_out_when_the_node_leaves_stopped() {
    let mut b = Bench::new();
    assert!(b.rx("000#0201").is_empty());
    b.d.raise_fault(0x5000);
    assert!(b.sync(2_000).is_empty());
    assert!(b.poll(3_000).is_empty());
    assert_eq!(b.rx("000#8001"), ["081#0050010000000000"]);
}

#[test]
fn fault_reset_edge_leaves_fault_and_the_standard_sequence_enables_again() {
    let mut b = Bench::new();
    b.expect("601#2F60600008000000", "581#6060600000000000");
    for cw in ["06", "07", "0F"] {
        b.expect(&format!("601#2B406000{cw}000000"), "581#6040600000000000");
    }
    assert_eq!(b.statusword(), "581#4B41600037120000");
    b.d.raise_fault(0x2310);
    assert_eq!(b.sync(2_000), ["081#1023030000000000"]);
    assert_eq!(b.statusword(), "581#4B41600008020000");
    b.expect("601#2B4060000F000000", "581#6040600000000000");
    assert_eq!(b.statusword(), "581#4B41600008020000", "no edge, no reset");
    // Bit 7 rises: Fault -> Switch on disabled, EMCY "error reset".
    assert_eq!(
        b.rx("601#2B40600080000000"),
        ["581#6040600000000000", "081#0000000000000000"]
    );
    assert_eq!(b.statusword(), "581#4B41600040020000");
    b.expect("601#4001100000000000", "581#4F01100000000000");
    for cw in ["06", "07", "0F"] {
        b.expect(&format!("601#2B406000{cw}000000"), "581#6040600000000000");
    }
    assert_eq!(b.statusword(), "581#4B41600037120000");
}

#[test]
fn emcy_goes_to_the_cob_id_of_0x1014_and_not_at_all_when_invalid() {
    let mut b = Bench::new();
    // A valid entry's identifier changes only through an invalid one.
    b.expect("601#2314100090000000", "581#8014100030000906");
    b.expect("601#2314100081000080", "581#6014100000000000");
    b.expect("601#2314100090000000", "581#6014100000000000");
    b.d.raise_fault(0x5000);
    assert_eq!(b.sync(2_000), ["090#0050010000000000"]);
    b.expect("601#2314100090000080", "581#6014100000000000");
    b.expect("601#2B40600080000000", "581#6040600000000000");
}

#[test]
fn event_driven_tpdo_waits_out_its_inhibit_time_and_repeats_by_its_event_timer() {
    let mut b = Bench::new();
    for (req, ans) in [
        ("601#23011801810200C0", "581#6001180100000000"),
        ("601#2F011802FF000000", "581#6001180200000000"),
        // Inhibit time 10 ms (100 x 100 us), event timer 50 ms.
        ("601#2B01180364000000", "581#6001180300000000"),
        ("601#2B01180532000000", "581#6001180500000000"),
        ("601#2F011A0000000000", "581#60011A0000000000"),
        ("601#23011A011000B960", "581#60011A0100000000"),
        ("601#2F011A0001000000", "581#60011A0000000000"),
        ("601#2301180181020040", "581#6001180100000000"),
    ] {
        b.expect(req, ans);
    }
    assert!(b.rx("000#0101").is_empty());
    assert_eq!(b.poll(100_000), ["281#0000"]);
    b.expect("601#2BB8600011000000", "581#60B8600000000000");
    assert!(b.poll(105_000).is_empty(), "inhibited until 110 ms");
    assert_eq!(b.d.next_deadline_us(), Some(110_000));
    assert_eq!(b.poll(110_000), ["281#0100"]);
    assert!(b.poll(159_999).is_empty());
    assert_eq!(b.poll(160_000), ["281#0100"], "the event timer repeats it");
}

/// Mode 8 and the controlword 06, 07, 0F by SDO: Operation enabled (0x1237).
fn enabled(b: &mut Bench) {
    b.expect("601#2F60600008000000", "581#6060600000000000");
    for cw in ["06", "07", "0F"] {
        b.expect(&format!("601#2B406000{cw}000000"), "581#6040600000000000");
    }
    assert_eq!(b.statusword(), "581#4B41600037120000");
}

#[test]
fn a_lost_master_heartbeat_sends_emcy_8130_quick_stops_then_disables() {
    let mut b = Bench::new();
    enabled(&mut b);
    // 0x1016: one entry; sub 1 = node 127 (0x7F) << 16 | 300 ms.
    b.expect("601#4016100000000000", "581#4F16100001000000");
    b.expect("601#231610012C017F00", "581#6016100100000000");
    b.expect("601#401610012C017F00", "581#431610012C017F00");
    // 0x6007 abort connection option code: 3, quick stop (the default).
    b.expect("601#4007600000000000", "581#4B07600003000000");
    // A target the axis would go to at the next step.
    b.expect("601#237A6000E8030000", "581#607A600000000000");
    assert_eq!(b.d.next_position_inc(), 1000);

    // No heartbeat seen yet: nothing is watched (CiA 301), however long.
    assert!(b.poll(1_000_000).is_empty());
    assert_eq!(b.d.next_deadline_us(), None);
    // Another node's heartbeat is not the master's.
    assert!(b.rx("705#05").is_empty());
    assert!(b.poll(1_100_000).is_empty());
    assert_eq!(b.d.next_deadline_us(), None);
    // The master's: watched from now (the drive's clock at its last look, 1.1 s).
    assert!(b.rx("77F#05").is_empty());
    assert_eq!(b.d.next_deadline_us(), Some(1_400_001));
    assert!(b.poll(1_200_000).is_empty());
    assert!(b.rx("77F#05").is_empty());
    assert_eq!(b.d.next_deadline_us(), Some(1_500_001));
    for t in [1_300_000, 1_400_000, 1_500_000] {
        assert!(
            b.poll(t).is_empty(),
            "{t} us: 300 ms silent is not yet lost"
        );
    }
    assert_eq!(b.d.statusword(), 0x1237);
    // 300 ms and 1 us silent: EMCY 8130 (heartbeat error), error register 0x11
    // (generic + communication), and the quick stop: statusword 0x0217.
    assert_eq!(b.poll(1_500_001), ["081#3081110000000000"]);
    assert_eq!(b.statusword(), "581#4B41600017020000");
    assert_eq!(b.d.next_position_inc(), 0, "the axis stops where it is");
    b.expect("601#4001100000000000", "581#4F01100011000000");
    // Enable operation cannot leave the quick stop (quick stop option code 2).
    b.expect("601#2B4060000F000000", "581#6040600000000000");
    assert_eq!(b.statusword(), "581#4B41600017020000");
    // A cycle period (0x1006, 2 ms) later the stop is over: Switch on disabled.
    assert_eq!(b.d.next_deadline_us(), Some(1_502_001));
    assert!(b.poll(1_502_001).is_empty());
    assert_eq!(b.statusword(), "581#4B41600040020000");
    assert!(b.poll(5_000_000).is_empty(), "one EMCY per loss");
    let loss = b.d.take_heartbeat_loss().unwrap();
    assert_eq!(
        (loss.node, loss.consumer_ms, loss.silent_us),
        (127, 300, 300_001)
    );
    assert_eq!(loss.at_us, 1_500_001);
    assert_eq!(
        (loss.from, loss.to),
        (
            hal::cia402::State::OperationEnabled,
            hal::cia402::State::QuickStopActive
        )
    );
    assert_eq!(b.d.take_heartbeat_loss(), None, "taken once");
    // The master is back: EMCY 0000 (error reset), register 0; the drive stays
    // disabled until the master enables it again.
    assert_eq!(b.rx("77F#05"), ["081#0000000000000000"]);
    b.expect("601#4001100000000000", "581#4F01100000000000");
    assert_eq!(b.statusword(), "581#4B41600040020000");
}

#[test]
fn the_consumer_ignores_its_own_hosts_stall_and_reset_communication_ends_it() {
    let mut b = Bench::new();
    enabled(&mut b);
    b.expect("601#231610012C017F00", "581#6016100100000000");
    assert!(b.poll(0).is_empty());
    assert!(b.rx("77F#05").is_empty());
    // The drive's host stalls for 2 s and looks again: a look counts at most 100 ms
    // (and at most half the consumer time), and the heartbeat queued meanwhile is
    // taken.
    assert!(b.poll(2_000_000).is_empty());
    assert!(b.rx("77F#05").is_empty());
    assert!(b.poll(2_100_000).is_empty());
    assert_eq!(b.d.statusword(), 0x1237);
    // Reset communication: 0x1016 back to 0, nothing watched.
    assert_eq!(b.rx("000#8201"), ["701#00"]);
    b.expect("601#4016100100000000", "581#4316100100000000");
    assert!(b.poll(60_000_000).is_empty());
    assert_eq!(b.d.heartbeat_loss(), None);
    // Node 0 with a time, reserved bits, a node beyond 127: value range (0x06090030);
    // sub 0 is read-only.
    b.expect("601#231610012C010000", "581#8016100130000906");
    b.expect("601#231610012C017F01", "581#8016100130000906");
    b.expect("601#231610012C018000", "581#8016100130000906");
    b.expect("601#2F16100002000000", "581#8016100002000106");
}

#[test]
fn abort_connection_option_code_0x6007_chooses_the_reaction() {
    // (0x6007, EMCY, statusword after the loss).
    for (code, emcy, after) in [
        // 0: no action but the EMCY.
        ("0000", "081#3081110000000000", "581#4B41600037120000"),
        // 1: fault signal: Fault, 0x603F = 8130.
        ("0100", "081#3081110000000000", "581#4B41600008020000"),
        // 2: disable voltage: Switch on disabled at once.
        ("0200", "081#3081110000000000", "581#4B41600040020000"),
    ] {
        let mut b = Bench::new();
        enabled(&mut b);
        b.expect(&format!("601#2B076000{code}0000"), "581#6007600000000000");
        b.expect("601#2316100164007F00", "581#6016100100000000"); // 100 ms
        assert!(b.poll(0).is_empty());
        assert!(b.rx("77F#05").is_empty());
        // Looks every 50 ms: half the consumer time, all of it counts.
        assert!(b.poll(50_000).is_empty());
        assert!(b.poll(100_000).is_empty());
        assert_eq!(b.poll(100_001), [emcy], "0x6007 = {code}");
        assert_eq!(b.statusword(), after, "0x6007 = {code}");
        if code == "0100" {
            b.expect("601#403F600000000000", "581#4B3F600030810000");
            // The fault outlives the heartbeat's return: no error reset until a fault
            // reset.
            assert!(b.rx("77F#05").is_empty());
        }
    }
    // Manufacturer-specific (negative) and undefined codes: value range exceeded.
    let mut b = Bench::new();
    b.expect("601#2B076000FFFF0000", "581#8007600030000906");
    b.expect("601#2B07600004000000", "581#8007600030000906");
    b.expect("601#4007600000000000", "581#4B07600003000000");
}

#[test]
fn on_the_virtual_clock_syncs_without_the_masters_heartbeat_stop_the_drive() {
    let mut b = Bench::new();
    enabled(&mut b);
    b.expect("601#231610012C017F00", "581#6016100100000000");
    // Simulated time: SYNC every 2 ms; the master's heartbeat with the first only.
    assert!(b.sync(0).is_empty());
    assert!(b.rx("77F#05").is_empty());
    for n in 1..=150 {
        assert!(b.sync(n * 2_000).is_empty(), "SYNC {n}");
    }
    // 302 ms after it, the drive's answer to SYNC is the EMCY; then it is stopped and
    // disabled a cycle later.
    assert_eq!(b.sync(302_000), ["081#3081110000000000"]);
    assert_eq!(b.statusword(), "581#4B41600017020000");
    assert!(b.sync(304_000).is_empty());
    assert_eq!(b.statusword(), "581#4B41600040020000");
}
