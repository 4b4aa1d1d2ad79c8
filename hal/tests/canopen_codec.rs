//! Byte-for-byte checks of the CANopen (CiA 301) and CiA 402 codecs against the
//! layouts of the standards, and client/server round trips through the same code.

use std::collections::BTreeMap;

use probebridge_hal::can::candump;
use probebridge_hal::can::CanFrame;
use probebridge_hal::canopen::heartbeat::{self, HeartbeatConsumer, HeartbeatEvent};
use probebridge_hal::canopen::pdo::{
    configuration_writes, MapEntry, PdoDirection, PdoMapping, PdoParameters, SdoWrite,
};
use probebridge_hal::canopen::sdo::{
    ObjectDictionary, SdoAbortCode, SdoClient, SdoClientEvent, SdoOutcome, SdoServer,
};
use probebridge_hal::canopen::{emcy, nmt, sync, Emcy, NmtCommand, NmtState};
use probebridge_hal::cia402::{Controlword, State, TouchProbeFunction};

/// A frame from candump notation ("605#2F60...").
fn fr(s: &str) -> CanFrame {
    candump::parse_line(&format!("(0.0) can0 {s}")).unwrap().2
}

fn txt(f: &CanFrame) -> String {
    format!("{f:?}")
}

/// Object dictionary over a map; 0x1008 is read only, 0x6041 too.
#[derive(Default)]
struct MapOd {
    objects: BTreeMap<(u16, u8), Vec<u8>>,
}

impl MapOd {
    fn with(mut self, index: u16, sub: u8, v: &[u8]) -> Self {
        self.objects.insert((index, sub), v.to_vec());
        self
    }
}

impl ObjectDictionary for MapOd {
    fn read(&mut self, index: u16, sub: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
        let v = self
            .objects
            .get(&(index, sub))
            .ok_or(SdoAbortCode::OBJECT_DOES_NOT_EXIST)?;
        buf[..v.len()].copy_from_slice(v);
        Ok(v.len())
    }
    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        if matches!(index, 0x1008 | 0x6041) {
            return Err(SdoAbortCode::READ_ONLY);
        }
        self.objects.insert((index, sub), data.to_vec());
        Ok(())
    }
}

/// Runs a transfer between client and server; returns the outcome and every frame
/// that went over the bus.
fn exchange(
    client: &mut SdoClient,
    server: &mut SdoServer,
    od: &mut impl ObjectDictionary,
    first: CanFrame,
) -> (SdoOutcome, Vec<String>) {
    let mut log = vec![txt(&first)];
    let mut request = first;
    for _ in 0..100 {
        let response = server.on_frame(&request, od).expect("server answers");
        log.push(txt(&response));
        match client.on_frame(&response) {
            SdoClientEvent::Transmit(next) => {
                log.push(txt(&next));
                request = next;
            }
            SdoClientEvent::Done(outcome) => return (outcome, log),
            other => panic!("unexpected {other:?}"),
        }
    }
    panic!("transfer did not end: {log:?}");
}

#[test]
fn sdo_expedited_download_mode_of_operation() {
    let mut client = SdoClient::new(5);
    let req = client.download_u8(0x6060, 0, 8).unwrap();
    assert_eq!(txt(&req), "605#2F60600008000000");
    assert!(client.is_busy());
    let mut server = SdoServer::new(5);
    let mut od = MapOd::default();
    let resp = server.on_frame(&req, &mut od).unwrap();
    assert_eq!(txt(&resp), "585#6060600000000000");
    assert_eq!(od.objects[&(0x6060, 0)], vec![8]);
    assert_eq!(
        client.on_frame(&resp),
        SdoClientEvent::Done(SdoOutcome::Downloaded)
    );
    assert!(!client.is_busy());
}

#[test]
fn sdo_expedited_download_sizes() {
    let mut c = SdoClient::new(5);
    assert_eq!(
        txt(&c.download_u16(0x6040, 0, 0x000F).unwrap()),
        "605#2B4060000F000000"
    );
    c.abort(SdoAbortCode::TIMEOUT);
    assert_eq!(
        txt(&c.download_i32(0x607A, 0, -2).unwrap()),
        "605#237A6000FEFFFFFF"
    );
    c.abort(SdoAbortCode::TIMEOUT);
    assert_eq!(
        txt(&c.download(0x2000, 3, &[1, 2, 3]).unwrap()),
        "605#2700200301020300"
    );
}

#[test]
fn sdo_expedited_upload_statusword() {
    let mut client = SdoClient::new(5);
    let req = client.upload(0x6041, 0).unwrap();
    assert_eq!(txt(&req), "605#4041600000000000");
    let mut server = SdoServer::new(5);
    let mut od = MapOd::default().with(0x6041, 0, &[0x37, 0x02]);
    let resp = server.on_frame(&req, &mut od).unwrap();
    assert_eq!(txt(&resp), "585#4B41600037020000");
    // Decoded from the literal bytes, not from our own server.
    let SdoClientEvent::Done(SdoOutcome::Uploaded(v)) =
        client.on_frame(&fr("585#4B41600037020000"))
    else {
        panic!("expected an upload")
    };
    assert_eq!(v.as_slice(), &[0x37, 0x02]);
    assert_eq!(
        State::from_statusword(u16::from_le_bytes([v[0], v[1]])),
        Some(State::OperationEnabled)
    );
}

#[test]
fn sdo_segmented_upload_device_name() {
    let name = b"PB-DRIVE-01";
    assert_eq!(name.len(), 11);
    let mut client = SdoClient::new(5);
    let mut server = SdoServer::new(5);
    let mut od = MapOd::default().with(0x1008, 0, name);
    let first = client.upload(0x1008, 0).unwrap();
    let (outcome, log) = exchange(&mut client, &mut server, &mut od, first);
    assert_eq!(
        log,
        [
            "605#4008100000000000",
            // scs 2, s = 1, e = 0: size 11 in bytes 4..8.
            "585#410810000B000000",
            // Upload segment request, toggle 0.
            "605#6000000000000000",
            // toggle 0, n = 0, c = 0: "PB-DRIV".
            "585#0050422D44524956",
            "605#7000000000000000",
            // toggle 1, n = 3, c = 1: "E-01" and three unused bytes.
            "585#17452D3031000000",
        ]
    );
    assert_eq!(
        outcome,
        SdoOutcome::Uploaded(heapless::Vec::from_slice(name).unwrap())
    );
}

#[test]
fn sdo_segmented_download_round_trip() {
    let data: Vec<u8> = (1..=20).collect();
    let mut client = SdoClient::new(9);
    let mut server = SdoServer::new(9);
    let mut od = MapOd::default();
    let first = client.download(0x2000, 1, &data).unwrap();
    let (outcome, log) = exchange(&mut client, &mut server, &mut od, first);
    assert_eq!(outcome, SdoOutcome::Downloaded);
    assert_eq!(
        log,
        [
            // ccs 1, s = 1, e = 0: size 20.
            "609#2100200114000000",
            "589#6000200100000000",
            // toggle 0, 7 bytes, c = 0
            "609#0001020304050607",
            "589#2000000000000000",
            // toggle 1
            "609#1008090A0B0C0D0E",
            "589#3000000000000000",
            // toggle 0, n = 1, c = 1: six bytes.
            "609#030F101112131400",
            "589#2000000000000000",
        ]
    );
    assert_eq!(od.objects[&(0x2000, 1)], data);
}

#[test]
fn sdo_round_trips_every_length() {
    let mut client = SdoClient::new(1);
    let mut server = SdoServer::new(1);
    let mut od = MapOd::default();
    for len in 0..=256usize {
        let data: Vec<u8> = (0..len).map(|i| (i * 7 + len) as u8).collect();
        let first = client.download(0x2100, 0, &data).unwrap();
        let (outcome, _) = exchange(&mut client, &mut server, &mut od, first);
        assert_eq!(outcome, SdoOutcome::Downloaded, "download of {len}");
        let first = client.upload(0x2100, 0).unwrap();
        let (outcome, _) = exchange(&mut client, &mut server, &mut od, first);
        assert_eq!(
            outcome,
            SdoOutcome::Uploaded(heapless::Vec::from_slice(&data).unwrap()),
            "upload of {len}"
        );
    }
    assert!(client.download(0x2100, 0, &[0; 257]).is_err());
}

#[test]
fn sdo_server_aborts_on_toggle_error() {
    let mut server = SdoServer::new(5);
    let mut od = MapOd::default();
    let init = fr("605#2100200114000000");
    assert_eq!(
        txt(&server.on_frame(&init, &mut od).unwrap()),
        "585#6000200100000000"
    );
    // First segment with toggle 1 instead of 0.
    let resp = server
        .on_frame(&fr("605#1001020304050607"), &mut od)
        .unwrap();
    assert_eq!(txt(&resp), "585#8000200100000305");
    assert!(!server.is_busy());
    assert!(od.objects.is_empty());
}

#[test]
fn sdo_client_aborts_on_toggle_error() {
    let mut client = SdoClient::new(5);
    client.upload(0x1008, 0).unwrap();
    let SdoClientEvent::Transmit(req) = client.on_frame(&fr("585#410810000B000000")) else {
        panic!("expected a segment request")
    };
    assert_eq!(txt(&req), "605#6000000000000000");
    // Segment answered with toggle 1.
    match client.on_frame(&fr("585#1050422D44524956")) {
        SdoClientEvent::Aborting { frame, code } => {
            assert_eq!(code, SdoAbortCode::TOGGLE_BIT_NOT_ALTERNATED);
            assert_eq!(txt(&frame), "605#8008100000000305");
        }
        other => panic!("expected an abort, got {other:?}"),
    }
    assert!(!client.is_busy());
}

#[test]
fn sdo_abort_is_data() {
    let mut client = SdoClient::new(5);
    client.upload(0x1234, 0).unwrap();
    let ev = client.on_frame(&fr("585#8034120000000206"));
    assert_eq!(
        ev,
        SdoClientEvent::Done(SdoOutcome::Aborted(SdoAbortCode::OBJECT_DOES_NOT_EXIST))
    );
    assert_eq!(
        SdoAbortCode::OBJECT_DOES_NOT_EXIST.to_string(),
        "SDO abort 0x06020000: object does not exist in the object dictionary"
    );
    assert_eq!(
        SdoAbortCode(0x1234_5678).to_string(),
        "SDO abort 0x12345678"
    );

    // The server sends the OD's refusal the same way.
    let mut server = SdoServer::new(5);
    let mut od = MapOd::default();
    let resp = server
        .on_frame(&fr("605#2F41600001000000"), &mut od)
        .unwrap();
    assert_eq!(txt(&resp), "585#8041600002000106");
    let resp = server
        .on_frame(&fr("605#4034120000000000"), &mut od)
        .unwrap();
    assert_eq!(txt(&resp), "585#8034120000000206");
    // Block download initiate (ccs 6): not supported.
    let resp = server
        .on_frame(&fr("605#C600200100010000"), &mut od)
        .unwrap();
    assert_eq!(txt(&resp), "585#8000200101000405");
}

#[test]
fn sdo_client_timeout_abort_and_misuse() {
    let mut client = SdoClient::new(5);
    assert_eq!(client.abort(SdoAbortCode::TIMEOUT), None);
    client.upload(0x6064, 0).unwrap();
    assert!(client.upload(0x6064, 0).is_err());
    let f = client.abort(SdoAbortCode::TIMEOUT).unwrap();
    assert_eq!(txt(&f), "605#8064600000000405");
    assert!(!client.is_busy());
    // A late answer is no longer ours.
    assert_eq!(
        client.on_frame(&fr("585#4364600001000000")),
        SdoClientEvent::Ignored
    );
    // Other nodes' answers are ignored.
    client.upload(0x6064, 0).unwrap();
    assert_eq!(
        client.on_frame(&fr("586#4364600001000000")),
        SdoClientEvent::Ignored
    );
}

#[test]
fn nmt_frames() {
    assert_eq!(txt(&nmt::encode(NmtCommand::Start, 5)), "000#0105");
    assert_eq!(
        txt(&nmt::encode(NmtCommand::ResetCommunication, 0)),
        "000#8200"
    );
    assert_eq!(
        nmt::decode(&fr("000#8100")).unwrap(),
        (NmtCommand::ResetNode, 0)
    );
    assert_eq!(
        nmt::decode(&fr("000#807F")).unwrap(),
        (NmtCommand::EnterPreOperational, 127)
    );
}

#[test]
fn sync_frames() {
    assert_eq!(txt(&sync::encode()), "080#");
    assert_eq!(txt(&sync::encode_with_counter(240)), "080#F0");
    assert_eq!(sync::decode(&fr("080#")).unwrap(), None);
    assert_eq!(sync::decode(&fr("080#07")).unwrap(), Some(7));
}

#[test]
fn emcy_layout() {
    let e = Emcy {
        error_code: 0x8110,
        error_register: emcy::error_register::GENERIC | emcy::error_register::COMMUNICATION,
        manufacturer: [0; 5],
    };
    assert_eq!(txt(&e.encode(5)), "085#1081110000000000");
    let (node, d) = Emcy::decode_with_node(&fr("085#1186210A0B0C0D0E")).unwrap();
    assert_eq!(node, 5);
    assert_eq!(d.error_code, 0x8611);
    assert_eq!(d.error_register, 0x21);
    assert_eq!(d.manufacturer, [0x0A, 0x0B, 0x0C, 0x0D, 0x0E]);
    assert_eq!(d.describe(), "following error");
    assert!(Emcy::decode(&fr("085#0000000000000000"))
        .unwrap()
        .is_reset());
    assert_eq!(emcy::describe(0x8110), "CAN overrun (objects lost)");
    assert_eq!(emcy::describe(0x4321), "temperature");
}

#[test]
fn heartbeat_frames() {
    assert_eq!(txt(&heartbeat::encode(5, NmtState::Operational)), "705#05");
    assert_eq!(txt(&heartbeat::boot_up(5)), "705#00");
    assert_eq!(
        txt(&heartbeat::encode(5, NmtState::PreOperational)),
        "705#7F"
    );
    assert_eq!(
        heartbeat::decode(&fr("705#05")).unwrap(),
        (5, NmtState::Operational)
    );
    assert_eq!(
        heartbeat::decode(&fr("77F#04")).unwrap(),
        (127, NmtState::Stopped)
    );
    assert!(heartbeat::decode(&fr("705#0500")).is_err());
}

#[test]
fn heartbeat_loss_reported_exactly_once() {
    const MS: u64 = 1_000_000;
    let mut c = HeartbeatConsumer::new();
    c.watch(5, 100 * MS).unwrap();
    c.watch(6, 100 * MS).unwrap();
    // Not lost before the first heartbeat (CiA 301: monitoring starts with it).
    assert_eq!(c.check(1_000 * MS), None);
    c.on_frame(&fr("705#05"), 1_000 * MS);
    c.on_frame(&fr("706#05"), 1_050 * MS);
    assert_eq!(c.state(5), Some(NmtState::Operational));
    assert_eq!(c.check(1_100 * MS), None);
    assert_eq!(
        c.check(1_100 * MS + 1),
        Some(HeartbeatEvent::Lost {
            node: 5,
            silent_for_ns: 100 * MS + 1
        })
    );
    assert_eq!(c.check(1_100 * MS + 1), None);
    assert_eq!(c.check(1_120 * MS), None);
    assert_eq!(
        c.check(1_151 * MS),
        Some(HeartbeatEvent::Lost {
            node: 6,
            silent_for_ns: 101 * MS
        })
    );
    for t in 1_152..1_300 {
        assert_eq!(c.check(t * MS), None);
    }
    // Back again; a later silence is a new loss.
    assert_eq!(
        c.on_frame(&fr("705#05"), 1_300 * MS),
        Some(HeartbeatEvent::Resumed {
            node: 5,
            state: NmtState::Operational
        })
    );
    assert!(matches!(
        c.check(1_401 * MS),
        Some(HeartbeatEvent::Lost { node: 5, .. })
    ));
    // Unrelated frames teach nothing.
    assert_eq!(c.on_frame(&fr("185#0102"), 1_402 * MS), None);
}

fn probe_mapping() -> PdoMapping {
    PdoMapping::from_entries(&[
        MapEntry::from_u32(0x6041_0010),
        MapEntry::from_u32(0x6064_0020),
        MapEntry::from_u32(0x60B9_0010),
    ])
    .unwrap()
}

#[test]
fn pdo_pack_unpack() {
    let m = probe_mapping();
    assert_eq!(
        m.entries()[1],
        MapEntry {
            index: 0x6064,
            sub: 0,
            bits: 32
        }
    );
    assert_eq!(m.entries()[2].to_u32(), 0x60B9_0010);
    assert_eq!(m.total_bits(), 64);
    let position: i32 = -1000;
    let (data, len) = m.pack(&[0x0237, u64::from(position as u32), 0x0003]);
    assert_eq!(len, 8);
    assert_eq!(data, [0x37, 0x02, 0x18, 0xFC, 0xFF, 0xFF, 0x03, 0x00]);
    let v = m.unpack(&data).unwrap();
    assert_eq!(v.as_slice(), &[0x0237, 0xFFFF_FC18, 0x0003]);
    assert_eq!(v[1] as u32 as i32, -1000);
    assert!(m.unpack(&data[..7]).is_err());
    assert!(PdoMapping::from_entries(&[
        MapEntry::from_u32(0x6064_0020),
        MapEntry::from_u32(0x6064_0020),
        MapEntry::from_u32(0x6041_0010),
    ])
    .is_err());
}

#[test]
fn pdo_configuration_sequence_tpdo1_node3() {
    let w = configuration_writes(PdoDirection::Tpdo, 1, 3, &probe_mapping(), 1);
    assert_eq!(
        w.as_slice(),
        &[
            // COB-ID invalid (bit 31), no RTR (bit 30), 0x183.
            SdoWrite::new(0x1800, 1, 0xC000_0183, 4),
            SdoWrite::new(0x1800, 2, 1, 1),
            SdoWrite::new(0x1A00, 0, 0, 1),
            SdoWrite::new(0x1A00, 1, 0x6041_0010, 4),
            SdoWrite::new(0x1A00, 2, 0x6064_0020, 4),
            SdoWrite::new(0x1A00, 3, 0x60B9_0010, 4),
            SdoWrite::new(0x1A00, 0, 3, 1),
            SdoWrite::new(0x1800, 1, 0x4000_0183, 4),
        ]
    );
    let r = configuration_writes(
        PdoDirection::Rpdo,
        2,
        3,
        &PdoMapping::from_entries(&[MapEntry::new(0x60B8, 0, 16)]).unwrap(),
        0xFF,
    );
    assert_eq!(r[0], SdoWrite::new(0x1401, 1, 0x8000_0303, 4));
    assert_eq!(r[2], SdoWrite::new(0x1601, 0, 0, 1));
    assert_eq!(r.last(), Some(&SdoWrite::new(0x1401, 1, 0x0000_0303, 4)));
}

/// The drive's object dictionary accepts the master's sequence over real SDO frames.
#[test]
fn pdo_configuration_accepted_by_device_objects() {
    struct DriveOd(PdoParameters);
    impl ObjectDictionary for DriveOd {
        fn read(&mut self, i: u16, s: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
            self.0.read(i, s, buf)
        }
        fn write(&mut self, i: u16, s: u8, d: &[u8]) -> Result<(), SdoAbortCode> {
            self.0
                .write(i, s, d, |e| matches!(e.index, 0x6041 | 0x6064 | 0x60B9))
        }
    }
    let mut od = DriveOd(PdoParameters::new(PdoDirection::Tpdo, 1, 3).unwrap());
    let mut client = SdoClient::new(3);
    let mut server = SdoServer::new(3);
    for w in configuration_writes(PdoDirection::Tpdo, 1, 3, &probe_mapping(), 1) {
        let first = client.download_write(&w).unwrap();
        let (outcome, _) = exchange(&mut client, &mut server, &mut od, first);
        assert_eq!(outcome, SdoOutcome::Downloaded, "{w:?}");
    }
    assert!(od.0.is_enabled());
    assert_eq!(od.0.cob_id(), 0x183);
    assert_eq!(od.0.transmission_type(), 1);
    assert_eq!(od.0.mapping(), &probe_mapping());
    // An object the drive cannot map is refused with the CiA 301 code.
    let mut od = DriveOd(PdoParameters::new(PdoDirection::Tpdo, 1, 3).unwrap());
    let bad = PdoMapping::from_entries(&[MapEntry::new(0x6040, 0, 16)]).unwrap();
    let outcomes: Vec<_> = configuration_writes(PdoDirection::Tpdo, 1, 3, &bad, 1)
        .iter()
        .map(|w| {
            let first = client.download_write(w).unwrap();
            exchange(&mut client, &mut server, &mut od, first).0
        })
        .collect();
    assert_eq!(
        outcomes[3],
        SdoOutcome::Aborted(SdoAbortCode::CANNOT_BE_MAPPED)
    );
}

#[test]
fn statusword_table() {
    let table = [
        (0x0250, State::SwitchOnDisabled),
        (0x0231, State::ReadyToSwitchOn),
        (0x0233, State::SwitchedOn),
        (0x0237, State::OperationEnabled),
        (0x0217, State::QuickStopActive),
        (0x021F, State::FaultReactionActive),
        (0x0218, State::Fault),
        (0x0200, State::NotReadyToSwitchOn),
    ];
    for (sw, state) in table {
        assert_eq!(State::from_statusword(sw), Some(state), "{sw:#06X}");
    }
}

#[test]
fn drive_state_machine_walk() {
    let mut s = State::SwitchOnDisabled;
    let mut prev = 0u16;
    let mut seen = vec![s];
    for cw in [
        Controlword::SHUTDOWN,
        Controlword::SWITCH_ON_CMD,
        Controlword::ENABLE_OPERATION_CMD,
    ] {
        s = s.on_controlword(cw, prev, false);
        prev = cw;
        seen.push(s);
    }
    assert_eq!(
        seen,
        [
            State::SwitchOnDisabled,
            State::ReadyToSwitchOn,
            State::SwitchedOn,
            State::OperationEnabled
        ]
    );
    // The master's choice of controlword, state by state.
    assert_eq!(
        State::SwitchOnDisabled.command_towards_operation_enabled(),
        Some(0x0006)
    );
    assert_eq!(
        State::ReadyToSwitchOn.command_towards_operation_enabled(),
        Some(0x0007)
    );
    assert_eq!(
        State::SwitchedOn.command_towards_operation_enabled(),
        Some(0x000F)
    );
    assert_eq!(
        State::Fault.command_towards_operation_enabled(),
        Some(0x0080)
    );
    assert_eq!(
        State::QuickStopActive.command_towards_operation_enabled(),
        Some(0x0000)
    );
    assert_eq!(
        State::OperationEnabled.command_towards_operation_enabled(),
        None
    );
    // Disable operation leads back to Switched on.
    assert_eq!(
        State::OperationEnabled.on_controlword(Controlword::DISABLE_OPERATION, 0x000F, false),
        State::SwitchedOn
    );
}

#[test]
fn fault_reset_only_on_rising_edge() {
    // Bit 7 held high: no edge, stays in Fault.
    assert_eq!(
        State::Fault.on_controlword(0x0080, 0x0080, false),
        State::Fault
    );
    assert_eq!(
        State::Fault.on_controlword(0x008F, 0x0080, false),
        State::Fault
    );
    // Rising edge.
    assert_eq!(
        State::Fault.on_controlword(0x0080, 0x000F, false),
        State::SwitchOnDisabled
    );
    // The master side gets its edge after a held bit 7.
    assert_eq!(State::Fault.next_controlword(0x0080), Some(0x0000));
    assert_eq!(State::Fault.next_controlword(0x0000), Some(0x0080));
}

#[test]
fn touch_probe_function_for_one_probing_move() {
    assert_eq!(TouchProbeFunction::probe1_first_positive_edge(), 0x0011);
}

#[test]
fn candump_round_trip() {
    let log = "\
(1700000000.000100) vcan0 000#0105
(1700000000.000200) vcan0 080#
(1700000000.000300) vcan0 605#2F60600008000000
(1700000000.000400) vcan0 705#R1
(1700000000.123456) vcan0 185#3702180CFFFF0300
";
    let entries = candump::parse_log(log).unwrap();
    assert_eq!(entries.len(), 5);
    assert_eq!(entries[0].0, 1_700_000_000_000_100_000);
    assert_eq!(entries[0].1, "vcan0");
    assert_eq!(nmt::decode(&entries[0].2).unwrap(), (NmtCommand::Start, 5));
    assert!(entries[3].2.is_rtr());
    let back: String = entries
        .iter()
        .map(|(t, i, f)| candump::format_line(*t, i, f) + "\n")
        .collect();
    assert_eq!(back, log);
    let err = candump::parse_log("(1.0) vcan0 000#0105\n(2.0) vcan0 7FF#0G\n").unwrap_err();
    assert_eq!(err.line, Some(2));
    assert_eq!(err.column, 18);
}

/// Our SDO client against the answers of a device that is not ours: python-canopen
/// 2.4.1's SDO server (`LocalNode`, tests/vcan/foreign_device.py), frames captured from
/// it. A 38-byte 0x1008 comes segmented, size indicated, the last segment with 4
/// unused bytes; aborts carry the multiplexer.
#[test]
fn sdo_client_takes_what_python_canopen_answers() {
    let mut c = SdoClient::new(1);
    let first = c.upload(0x1008, 0).unwrap();
    let mut log = vec![txt(&first)];
    let answers = [
        "581#4108100026000000",
        "581#00707974686F6E2D",
        "581#1063616E6F70656E",
        "581#00204C6F63616C4E",
        "581#106F646520436941",
        "581#0020343032206472",
        "581#1969766500000000",
    ];
    let mut outcome = None;
    for a in answers {
        match c.on_frame(&fr(a)) {
            SdoClientEvent::Transmit(next) => log.push(txt(&next)),
            SdoClientEvent::Done(o) => outcome = Some(o),
            other => panic!("{a}: {other:?}"),
        }
    }
    assert_eq!(
        log,
        [
            "601#4008100000000000",
            "601#6000000000000000",
            "601#7000000000000000",
            "601#6000000000000000",
            "601#7000000000000000",
            "601#6000000000000000",
            "601#7000000000000000",
        ]
    );
    match outcome {
        Some(SdoOutcome::Uploaded(v)) => {
            assert_eq!(v.as_slice(), b"python-canopen LocalNode CiA 402 drive")
        }
        other => panic!("{other:?}"),
    }
    for (index, sub, write, answer, code) in [
        (0x2000, 0, false, "581#8000200000000206", 0x0602_0000),
        (0x1018, 9, false, "581#8018100911000906", 0x0609_0011),
        (0x1000, 0, true, "581#8000100002000106", 0x0601_0002),
    ] {
        let request = if write {
            c.download(index, sub, &[0, 0, 0, 0])
        } else {
            c.upload(index, sub)
        }
        .unwrap();
        assert_eq!(
            c.on_frame(&fr(answer)),
            SdoClientEvent::Done(SdoOutcome::Aborted(SdoAbortCode(code))),
            "{request:?}"
        );
    }
}
