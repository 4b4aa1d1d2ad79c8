//! Every CANopen frame decoder, the stateful SDO and heartbeat sides, and the
//! simulated drive, fed frame sequences.

use super::frames::{frame, literal};
use crate::driver::Target;
use crate::sig::Sig;
use arbitrary::{Result, Unstructured};
use hal::can::CanFrame;
use hal::canopen::pdo::{self, PdoParameters};
use hal::canopen::sdo::MAX_TRANSFER;
use hal::canopen::{
    cob_id, heartbeat, nmt, Emcy, HeartbeatConsumer, MapEntry, NmtState, ObjectDictionary,
    PdoDirection, PdoMapping, SdoAbortCode, SdoClient, SdoClientEvent, SdoServer,
};
use sim::drive::SimDrive;
use std::collections::BTreeMap;

const NODE: u8 = 5;

/// A target over a structured input: `$ops` reads its operations from the bytes.
macro_rules! target {
    ($name:literal, $about:literal, $seeds:expr, $ops:path) => {
        Target {
            name: $name,
            about: $about,
            max_len: 4096,
            prepare: || {},
            seeds: $seeds,
            dictionary: &[],
            run: |d| structured(d, $ops),
        }
    };
}

/// Runs `ops` on the bytes; running out of bytes ends the sequence (not an error).
fn structured(data: &[u8], ops: fn(&mut Unstructured<'_>, &mut Sig) -> Result<()>) -> Sig {
    let mut u = Unstructured::new(data);
    let mut sig = Sig::default();
    let _ = ops(&mut u, &mut sig);
    sig
}

pub fn targets() -> Vec<Target> {
    vec![
        target!(
            "nmt",
            "NMT command frames: decode, and encode of what decoded gives the same frame",
            || vec![literal(&[(0x000, &[0x01, 0x05]), (0x000, &[0x82, 0x00]), (0x000, &[0x80])])],
            nmt_ops
        ),
        target!(
            "heartbeat",
            "heartbeat and boot-up frames, and the heartbeat consumer over time",
            || vec![literal(&[(0x705, &[0x7F]), (0x705, &[0x05]), (0x706, &[0x00]), (0x705, &[0x85])])],
            heartbeat_ops
        ),
        target!(
            "emcy",
            "EMCY frames: decode, and encode of what decoded gives the same frame",
            || vec![literal(&[(0x085, &[0x10, 0x82, 0x11, 0, 0, 0, 0, 0]), (0x080, &[0; 8])])],
            emcy_ops
        ),
        target!(
            "pdo",
            "PDO mappings, packing and unpacking, and the device side of PDO configuration over SDO",
            || vec![literal(&[(0x1600, &[0x20, 0x00, 0x7A, 0x60, 0x10, 0x00, 0x40, 0x60])])],
            pdo_ops
        ),
        target!(
            "sdo-client",
            "the SDO client fed server answers during downloads and uploads",
            || {
                vec![literal(&[
                    (0x585, &[0x60, 0x40, 0x60, 0x00, 0, 0, 0, 0]),
                    (0x585, &[0x41, 0x08, 0x10, 0x00, 0x0B, 0, 0, 0]),
                    (0x585, &[0x00, b'p', b'r', b'o', b'b', b'e', b'b', b'r']),
                    (0x585, &[0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x02, 0x06]),
                ])]
            },
            sdo_client_ops
        ),
        target!(
            "sdo-server",
            "the SDO server fed client requests over an object dictionary",
            || {
                vec![literal(&[
                    (0x605, &[0x40, 0x00, 0x20, 0x01, 0, 0, 0, 0]),
                    (0x605, &[0x23, 0x00, 0x20, 0x02, 1, 2, 3, 4]),
                    (0x605, &[0x21, 0x00, 0x20, 0x03, 10, 0, 0, 0]),
                    (0x605, &[0x00, 1, 2, 3, 4, 5, 6, 7]),
                ])]
            },
            sdo_server_ops
        ),
        target!(
            "sim-drive",
            "the simulated CiA 402 drive fed NMT, SDO, RPDO and SYNC frames, steps and time",
            || {
                vec![literal(&[
                    (0x000, &[0x01, 0x05]),
                    (0x205, &[0x0F, 0x00, 0x08]),
                    (0x080, &[]),
                    (0x605, &[0x2F, 0x60, 0x60, 0x00, 0x08, 0, 0, 0]),
                ])]
            },
            drive_ops
        ),
    ]
}

fn nmt_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    while !u.is_empty() {
        let f = frame(u, &[cob_id::NMT], 2)?;
        sig.debug(&cob_id::classify(f.cob_id()));
        match nmt::decode(&f) {
            Ok((cmd, node)) => {
                assert_eq!(
                    nmt::encode(cmd, node),
                    f,
                    "NMT {f:?} decoded as {cmd:?} {node}"
                );
                for state in [NmtState::BootUp, NmtState::Stopped, NmtState::Operational] {
                    sig.debug(&state.after(cmd));
                }
            }
            Err(e) => {
                sig.debug(&e);
            }
        }
    }
    Ok(())
}

fn heartbeat_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    let mut hb = HeartbeatConsumer::new();
    let mut now: u64 = 0;
    let cobs: Vec<u16> = (0..4).map(|n| cob_id::heartbeat_cob(NODE + n)).collect();
    while !u.is_empty() {
        now = now.saturating_add(u64::from(u.arbitrary::<u32>()?));
        match u.int_in_range(0..=5)? {
            0 => {
                let node: u8 = u.arbitrary()?;
                let timeout = u64::from(u.arbitrary::<u32>()?);
                sig.value(u64::from(hb.watch(node, timeout).is_ok()));
            }
            1 => {
                let node: u8 = u.arbitrary()?;
                sig.value(u64::from(hb.unwatch(node).is_ok()));
            }
            2 => {
                while let Some(e) = hb.check(now) {
                    sig.debug(&e);
                }
            }
            3 => {
                let node: u8 = u.arbitrary()?;
                sig.debug(&(
                    hb.state(node),
                    hb.is_lost(node),
                    hb.last_seen_ns(node).is_some(),
                ));
            }
            _ => {
                let f = frame(u, &cobs, 1)?;
                if let Ok((node, state)) = heartbeat::decode(&f) {
                    let back = heartbeat::encode(node, state);
                    assert_eq!(
                        (back.cob_id(), back.data()[0]),
                        (f.cob_id(), f.data()[0] & 0x7F),
                        "heartbeat {f:?} decoded as node {node} {state:?}"
                    );
                }
                sig.debug(&hb.on_frame(&f, now));
            }
        }
    }
    Ok(())
}

fn emcy_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    let cobs: Vec<u16> = (1..=3).map(cob_id::emcy_cob).collect();
    while !u.is_empty() {
        let f = frame(u, &cobs, 8)?;
        match Emcy::decode_with_node(&f) {
            Ok((node, e)) => {
                assert_eq!(e.encode(node), f, "EMCY {f:?} decoded as node {node} {e:?}");
                sig.text("emcy");
            }
            Err(e) => {
                sig.debug(&e);
            }
        }
    }
    Ok(())
}

fn pdo_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    // A mapping as a device would accept it, and its data round trip.
    let n = u.int_in_range(0..=10)?;
    let entries: Vec<MapEntry> = (0..n)
        .map(|_| Ok(MapEntry::from_u32(u.arbitrary()?)))
        .collect::<Result<_>>()?;
    match PdoMapping::from_entries(&entries) {
        Ok(m) => {
            let values: Vec<u64> = (0..m.entries().len())
                .map(|_| u.arbitrary())
                .collect::<Result<_>>()?;
            let (bytes, len) = m.pack(&values);
            assert_eq!(len, m.byte_len());
            let back = m.unpack(&bytes[..len]).expect("packed data unpacks");
            for ((e, v), b) in m.entries().iter().zip(&values).zip(&back) {
                let mask = if e.bits >= 64 {
                    u64::MAX
                } else {
                    (1 << e.bits) - 1
                };
                assert_eq!(v & mask, *b, "PDO value of {e:?} changed in a round trip");
            }
            let data: Vec<u8> = u.arbitrary()?;
            sig.text("mapped").debug(&m.unpack(&data).map(|_| ()));
            let f = frame(u, &[0x185], m.byte_len())?;
            sig.debug(&m.unpack_frame(&f).map(|_| ()));
        }
        Err(e) => {
            sig.debug(&e);
        }
    }
    // The device side: a sequence of SDO writes and reads on one PDO's objects.
    let direction = if u.arbitrary()? {
        PdoDirection::Rpdo
    } else {
        PdoDirection::Tpdo
    };
    let num = if u.ratio(7u8, 8u8)? {
        u.int_in_range(1..=4)?
    } else {
        u.arbitrary()?
    };
    let mut p = match PdoParameters::new(direction, num, NODE) {
        Ok(p) => p,
        Err(e) => {
            sig.debug(&e);
            return Ok(());
        }
    };
    let comm = pdo::communication_index(direction, num).unwrap_or(0);
    let map = pdo::mapping_index(direction, num).unwrap_or(0);
    while !u.is_empty() {
        let index = *u.choose(&[comm, map, comm, map, 0x6040])?;
        let sub = u.int_in_range(0..=9)?;
        if u.arbitrary()? {
            let mut buf = [0u8; MAX_TRANSFER];
            sig.debug(&p.read(index, sub, &mut buf));
        } else {
            let data: Vec<u8> = u.arbitrary()?;
            let data = &data[..data.len().min(8)];
            let r = p.write(index, sub, data, |e| e.index >= 0x2000);
            sig.debug(&r.map_err(SdoAbortCode::description));
            assert!(p.mapping().total_bits() <= 64, "PDO mapping over 64 bits");
        }
    }
    Ok(())
}

fn sdo_client_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    let mut c = SdoClient::new(NODE);
    let response = cob_id::sdo_response_cob(NODE);
    while !u.is_empty() {
        match u.int_in_range(0..=9)? {
            0 => {
                let len = if u.ratio(3u8, 4u8)? {
                    u.int_in_range(0..=24)?
                } else {
                    u.int_in_range(0..=MAX_TRANSFER + 8)?
                };
                let data = u.bytes(len)?;
                sig.debug(&c.download(u.arbitrary()?, u.arbitrary()?, data).map(|_| ()));
            }
            1 => {
                sig.debug(&c.upload(u.arbitrary()?, u.arbitrary()?).map(|_| ()));
            }
            2 => {
                let code = SdoAbortCode(u.arbitrary()?);
                if let Some(f) = c.abort(code) {
                    assert_eq!(f.data().len(), 8, "abort frame {f:?}");
                }
                assert!(!c.is_busy());
            }
            _ => {
                let was_busy = c.is_busy();
                let f = frame(u, &[response], 8)?;
                let e = c.on_frame(&f);
                match &e {
                    SdoClientEvent::Done(_) | SdoClientEvent::Aborting { .. } => {
                        assert!(!c.is_busy(), "{e:?} but the client is still busy")
                    }
                    SdoClientEvent::Transmit(t) => {
                        assert!(was_busy && t.data().len() == 8, "{t:?} sent")
                    }
                    SdoClientEvent::Ignored => {}
                }
                sig.debug(&std::mem::discriminant(&e));
            }
        }
    }
    Ok(())
}

/// An object dictionary of byte strings; 0x1000 is read-only, 0x1F00 refuses writes
/// longer than 4 bytes.
struct Od(BTreeMap<(u16, u8), Vec<u8>>);

impl ObjectDictionary for Od {
    fn read(
        &mut self,
        index: u16,
        sub: u8,
        buf: &mut [u8],
    ) -> std::result::Result<usize, SdoAbortCode> {
        let v = self
            .0
            .get(&(index, sub))
            .ok_or(SdoAbortCode::OBJECT_DOES_NOT_EXIST)?;
        let n = v.len().min(buf.len());
        buf[..n].copy_from_slice(&v[..n]);
        Ok(n)
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> std::result::Result<(), SdoAbortCode> {
        match index {
            0x1000 => Err(SdoAbortCode::READ_ONLY),
            0x1F00 if data.len() > 4 => Err(SdoAbortCode::LENGTH_TOO_HIGH),
            _ => {
                self.0.insert((index, sub), data.to_vec());
                Ok(())
            }
        }
    }
}

fn sdo_server_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    let mut od = Od(BTreeMap::from([
        ((0x1000, 0), vec![0x92, 0x01, 0x02, 0x00]),
        ((0x1008, 0), b"probebridge simulated drive".to_vec()),
        ((0x2000, 1), vec![1]),
        ((0x2000, 2), vec![0; MAX_TRANSFER]),
    ]));
    let mut s = SdoServer::new(NODE);
    let request = cob_id::sdo_request_cob(NODE);
    while !u.is_empty() {
        if u.ratio(1u8, 16u8)? {
            s.reset();
            continue;
        }
        let f = frame(u, &[request], 8)?;
        let answer = s.on_frame(&f, &mut od);
        if let Some(a) = &answer {
            assert_eq!(
                (a.cob_id(), a.data().len()),
                (cob_id::sdo_response_cob(NODE), 8),
                "SDO answer {a:?} to {f:?}"
            );
            sig.value(u64::from(a.data()[0] >> 5));
        } else {
            sig.text("none");
        }
    }
    Ok(())
}

fn drive_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    // An axis drive (cyclic synchronous position) or a spindle drive (profile position).
    let mut d = if u.arbitrary()? {
        SimDrive::spindle(NODE, u.arbitrary()?)
    } else {
        SimDrive::new(NODE, u.arbitrary()?)
    };
    let mut sent: Vec<CanFrame> = Vec::new();
    d.power_on(&mut |f| sent.push(*f));
    let mut now: u64 = 0;
    let cobs = [
        cob_id::NMT,
        cob_id::SYNC,
        cob_id::sdo_request_cob(NODE),
        cob_id::rpdo_cob(1, NODE),
        cob_id::rpdo_cob(2, NODE),
        cob_id::rpdo_cob(3, NODE),
    ];
    while !u.is_empty() && sent.len() < 10_000 {
        now = now.saturating_add(u64::from(u.arbitrary::<u16>()?));
        match u.int_in_range(0..=9)? {
            0 => d.on_sync(),
            1 => d.poll(now, &mut |f| sent.push(*f)),
            2 => d.answer_sync(now, &mut |f| sent.push(*f)),
            3 => {
                d.begin_step();
                // Where the drive goes on its own (the CSP target, a profile position
                // step), or anywhere near.
                let to = if u.arbitrary()? {
                    d.next_position_inc()
                } else {
                    d.actual_inc()
                        .wrapping_add(i32::from(u.arbitrary::<i16>()?))
                };
                let latch = if u.arbitrary()? {
                    Some(f64::from(u.int_in_range(0..=1000u16)?) / 1000.0)
                } else {
                    None
                };
                sig.value(u64::from(d.end_step(to, latch, u.arbitrary()?)));
            }
            4 if u.ratio(1u8, 8u8)? => d.raise_fault(u.arbitrary()?),
            _ => {
                let f = frame(u, &cobs, 8)?;
                d.on_frame(&f, &mut |f| sent.push(*f));
            }
        }
        let _ = (d.next_deadline_us(), d.next_position_inc());
        sig.debug(&(d.state(), d.nmt_state()));
    }
    for f in &sent {
        sig.debug(&cob_id::classify(f.cob_id()));
    }
    Ok(())
}
