//! The Modbus codecs (word order, mailbox blocks, latch ring, exceptions) and the
//! gateway's PLC face (register map and handshake, on the measurement service), fed
//! registers, requests, OPC UA's commands and the machine thread's answers.

use crate::driver::Target;
use crate::sig::Sig;
use arbitrary::{Result, Unstructured};
use hal::axis::{Axis, MAX_AXES};
use hal::modbus::config::ModbusBusConfig;
use hal::modbus::exception::{describe, exception_kind};
use hal::modbus::latch_ring::{LatchTracker, RingEvent};
use hal::modbus::mailbox::{
    CommandBlock, CommandCode, LatchSlot, ResultCode, Scale, StatusBlock, COMMAND_LEN, SLOT_LEN,
    STATUS_LEN,
};
use hal::modbus::word_order::WordOrder;
use probebridge::serve::handshake::Handshake;
use probebridge::serve::measurement::{Command, Origin, State, NO_REQUEST, START_PARAMS};
use probebridge::serve::outcome::{AbortReason, Outcome, Refusal};
use probebridge::serve::ownership::Ownership;
use probebridge::serve::plc_registers::PlcRegisters;
use probebridge::serve::register_map::{self as map, RegisterMap, StateView};
use probebridge::serve::results::{self, Quantity, ResultKey};
use probebridge::serve::service::{Service, ToMachine};
use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

macro_rules! target {
    ($name:literal, $about:literal, $ops:path) => {
        Target {
            name: $name,
            about: $about,
            max_len: 4096,
            prepare: || {},
            seeds: || vec![(0..=255u8).collect(), vec![0; 64], vec![0xFF; 64]],
            dictionary: &[],
            run: |d| {
                let mut u = Unstructured::new(d);
                let mut sig = Sig::default();
                let _ = $ops(&mut u, &mut sig);
                sig
            },
        }
    };
}

pub fn targets() -> Vec<Target> {
    vec![
        target!(
            "modbus-codecs",
            "word orders, the mailbox's command/status/latch-slot blocks, scales and exception codes",
            codec_ops
        ),
        target!(
            "modbus-latch-ring",
            "the latch ring tracker on whole rings as read, for every valid layout",
            latch_ring_ops
        ),
        target!(
            "gateway-register-map",
            "the gateway's register map: FC3 reads, FC6/FC16 writes, requests, states and results",
            register_map_ops
        ),
        target!(
            "gateway-handshake",
            "the PLC face on the measurement service, driven by request blocks, OPC UA commands, answers, progress, ends of runs and time",
            handshake_ops
        ),
    ]
}

fn order(u: &mut Unstructured<'_>) -> Result<WordOrder> {
    u.choose(&WordOrder::ALL).copied()
}

fn regs(u: &mut Unstructured<'_>, usual: usize) -> Result<Vec<u16>> {
    let n = if u.ratio(7u8, 8u8)? {
        usual
    } else {
        u.int_in_range(0..=usual + 4)?
    };
    (0..n).map(|_| u.arbitrary()).collect()
}

fn codec_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    while !u.is_empty() {
        let o = order(u)?;
        match u.int_in_range(0..=6)? {
            0 => {
                let v: u32 = u.arbitrary()?;
                assert_eq!(o.decode_u32(o.encode_u32(v)), v, "{o} u32 round trip");
                let r: [u16; 2] = u.arbitrary()?;
                assert_eq!(o.encode_i32(o.decode_i32(r)), r, "{o} i32 round trip");
            }
            1 => {
                let c = CommandBlock {
                    command: u.arbitrary()?,
                    axis_mask: u.arbitrary()?,
                    feed_milli: u.arbitrary()?,
                    targets: u.arbitrary()?,
                    probe_edge: u.arbitrary()?,
                    latch_ack: u.arbitrary()?,
                    heartbeat: u.arbitrary()?,
                    sequence: u.arbitrary()?,
                };
                let r = c.encode(o);
                assert_eq!(r.len(), COMMAND_LEN as usize);
                assert_eq!(CommandBlock::decode(o, &r), c, "command block round trip");
                sig.debug(&CommandCode::from_u16(c.command));
            }
            2 => {
                let r = regs(u, STATUS_LEN as usize)?;
                match StatusBlock::decode(o, &r) {
                    Some(s) => {
                        assert_eq!(
                            s.encode(o).as_slice(),
                            r.as_slice(),
                            "status block round trip"
                        );
                        sig.debug(&ResultCode::from_u16(s.result));
                    }
                    None => {
                        assert_ne!(r.len(), STATUS_LEN as usize);
                        sig.text("short");
                    }
                }
            }
            3 => {
                let r: [u16; SLOT_LEN as usize] = u.arbitrary()?;
                let s = LatchSlot::decode(o, &r);
                assert_eq!(s.encode(o), r, "latch slot round trip");
            }
            4 => {
                // Scales as the configuration admits them: finite and positive.
                let scale = Scale {
                    per_mm: f64::from(u.int_in_range(1..=u32::MAX)?) / 1000.0,
                    per_deg: f64::from(u.int_in_range(1..=u32::MAX)?) / 1000.0,
                };
                let axis = *u.choose(&Axis::ALL)?;
                let v = f64::from_bits(u.arbitrary()?);
                let c = scale.to_counts(axis, v);
                sig.value(u64::from(c.is_some()));
                if let Some(c) = c {
                    assert!(scale.from_counts(axis, c).is_finite());
                }
                let counts: [i32; MAX_AXES] = u.arbitrary()?;
                assert!(scale.positions(&counts).iter().all(|p| p.is_finite()));
            }
            5 => {
                let e = tokio_modbus::ExceptionCode::new(u.arbitrary()?);
                sig.debug(&exception_kind(e));
                assert!(!describe(e).is_empty());
            }
            _ => {
                sig.debug(&ResultCode::from_u16(u.arbitrary()?));
            }
        }
    }
    Ok(())
}

/// A mailbox layout the configuration accepts, from the bytes; `None`: refused.
fn layout(u: &mut Unstructured<'_>) -> Result<Option<hal::modbus::mailbox::Layout>> {
    let mut c = ModbusBusConfig::tcp("127.0.0.1:502");
    c.ring_slots = *u.choose(&[1, 2, 4, 4, 8, 0, 3])?;
    c.ring_base = if u.arbitrary()? { 200 } else { u.arbitrary()? };
    c.word_order = order(u)?;
    c.max_read = u.int_in_range(1..=125)?;
    Ok(c.validate().is_ok().then(|| c.layout()))
}

fn latch_ring_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    let Some(layout) = layout(u)? else {
        sig.text("layout refused");
        return Ok(());
    };
    let o = layout.word_order;
    let mut tracker = LatchTracker::resume(layout, u.arbitrary()?);
    let mut ring = vec![0u16; usize::from(layout.ring_len())];
    let mut count = tracker.acked();
    let command: u16 = u.arbitrary()?;
    while !u.is_empty() {
        match u.int_in_range(0..=5)? {
            // The PLC latches: a whole slot, or a torn one, of this or another command.
            0 | 1 => {
                count = count.wrapping_add(1);
                let slot = LatchSlot {
                    sequence_head: count,
                    command_sequence: if u.ratio(3u8, 4u8)? {
                        command
                    } else {
                        u.arbitrary()?
                    },
                    axis_mask: u.arbitrary()?,
                    positions: u.arbitrary()?,
                    latch_time_us: u.arbitrary()?,
                    sequence_tail: if u.ratio(7u8, 8u8)? {
                        count
                    } else {
                        u.arbitrary()?
                    },
                };
                let at = tracker.slot_of(count) * SLOT_LEN as usize;
                ring[at..at + SLOT_LEN as usize].copy_from_slice(&slot.encode(o));
            }
            2 => {
                count = u.arbitrary()?;
            }
            3 => {
                let i = u.int_in_range(0..=ring.len())?;
                if i < ring.len() {
                    ring[i] = u.arbitrary()?;
                }
            }
            _ => {
                // What was read: the whole ring, sometimes cut short.
                let read = if u.ratio(7u8, 8u8)? {
                    &ring[..]
                } else {
                    &ring[..u.int_in_range(0..=ring.len())?]
                };
                let e = tracker.examine(count, read, command);
                let next = tracker.acked().wrapping_add(1);
                match e {
                    RingEvent::Contact { n, slot } | RingEvent::Foreign { n, slot } => {
                        assert_eq!(n, next, "{e:?} after acknowledge {}", tracker.acked());
                        assert_eq!((slot.sequence_head, slot.sequence_tail), (n, n));
                        tracker.acknowledged(n);
                    }
                    RingEvent::Overflow { lost, count: c } => {
                        assert!(lost > 0 && c == count, "{e:?}");
                        tracker.acknowledged(c);
                    }
                    RingEvent::Torn { n } => assert_eq!(n, next),
                    RingEvent::Empty => assert_eq!(tracker.pending(count), 0),
                }
                sig.debug(&std::mem::discriminant(&e));
            }
        }
    }
    Ok(())
}

fn map_order(u: &mut Unstructured<'_>) -> Result<map::WordOrder> {
    Ok(if u.arbitrary()? {
        map::WordOrder::HighFirst
    } else {
        map::WordOrder::LowFirst
    })
}

/// A result value: mostly ordinary, sometimes huge, tiny or not a number.
fn result_value(u: &mut Unstructured<'_>) -> Result<f64> {
    Ok(match u.int_in_range(0..=3)? {
        0 => f64::from_bits(u.arbitrary()?),
        1 => f64::from(u.arbitrary::<i32>()?) * 1e-4,
        _ => f64::from(u.arbitrary::<i16>()?) * 1e-3,
    })
}

fn image(m: &RegisterMap) -> Vec<u16> {
    (0..=map::RES_SEQ_TAIL).map(|a| m.get(a)).collect()
}

fn register_map_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    // int_scale as the gateway configuration admits it: 1..1e9.
    let scale = *u.choose(&[1.0, 10_000.0, 1e9, 3.5])?;
    let mut m = RegisterMap::new(map_order(u)?, scale);
    let slots = results::slots();
    while !u.is_empty() {
        match u.int_in_range(0..=5)? {
            0 => {
                let addr = if u.arbitrary()? {
                    u.int_in_range(0..=340)?
                } else {
                    u.arbitrary()?
                };
                let count = u.int_in_range(0..=130)?;
                let r = m.read(addr, count);
                if let Ok(v) = &r {
                    assert_eq!(v.len(), usize::from(count));
                }
                sig.debug(&r.map(|_| ()));
            }
            1 | 2 => {
                let addr = if u.arbitrary()? {
                    u.int_in_range(0..=40)?
                } else {
                    u.arbitrary()?
                };
                let n = u.int_in_range(0..=130)?;
                let values: Vec<u16> = (0..n).map(|_| u.arbitrary()).collect::<Result<_>>()?;
                let before = image(&m);
                let r = m.write(addr, &values);
                if r.is_err() {
                    assert_eq!(before, image(&m), "a refused write changed the map");
                }
                let req = m.request();
                sig.debug(&r)
                    .value(u64::from(req.params.iter().all(|p| p.is_finite())));
            }
            3 => {
                let s = StateView {
                    ack_seq: u.arbitrary()?,
                    ack_code: u.arbitrary()?,
                    reason: u.arbitrary()?,
                    state: u.arbitrary()?,
                    bits: u.arbitrary()?,
                    progress_permille: u.arbitrary()?,
                    error_kind: u.arbitrary()?,
                    error_code: u.arbitrary()?,
                    point: u.arbitrary()?,
                    program: u.arbitrary()?,
                    cycle: u.arbitrary()?,
                };
                m.set_state(&s);
                assert_eq!(m.read(map::ST_ACK_SEQ, 1), Ok(vec![s.ack_seq]));
            }
            4 => {
                let seq: u16 = u.arbitrary()?;
                let mut values = BTreeMap::new();
                for _ in 0..u.int_in_range(0..=8)? {
                    let quantity = if u.ratio(7u8, 8u8)? {
                        u.choose(&slots)?.clone()
                    } else {
                        Quantity::Named(String::from_utf8_lossy(u.bytes(4)?).into_owned())
                    };
                    let key = if u.arbitrary()? {
                        ResultKey::Value(quantity)
                    } else {
                        ResultKey::Uncertainty(quantity)
                    };
                    values.insert(key, result_value(u)?);
                }
                m.set_results(seq, &values);
                assert_eq!(
                    (m.get(map::RES_SEQ_HEAD), m.get(map::RES_SEQ_TAIL)),
                    (seq, seq)
                );
            }
            _ => m.set_gateway_heartbeat(u.arbitrary()?),
        }
    }
    Ok(())
}

fn handshake_ops(u: &mut Unstructured<'_>, sig: &mut Sig) -> Result<()> {
    let start = Instant::now();
    let mut now = start;
    let timeout = if u.arbitrary()? {
        Some(Duration::from_millis(u.int_in_range(1..=5000)?))
    } else {
        None
    };
    let (jobs_tx, jobs) = std::sync::mpsc::channel();
    let mut service = Service::new(jobs_tx);
    let mut plc = PlcRegisters::new(
        RegisterMap::new(map_order(u)?, 10_000.0),
        Handshake::new(timeout, now),
        Ownership::new(Duration::from_secs(10)),
    );
    let ip = IpAddr::V4(Ipv4Addr::LOCALHOST);
    let reg = |plc: &mut PlcRegisters, service: &Service, addr: u16| {
        plc.read(service, addr, 1)
            .expect("a register of the state block")[0]
    };
    while !u.is_empty() {
        now += Duration::from_millis(u.int_in_range(0..=3000)?);
        let was = service.state();
        let was_between = service.between_measurements();
        let refuse = u.arbitrary::<u8>()? % 4 == 0;
        match u.int_in_range(0..=8)? {
            0..=2 => {
                // The PLC writes the request block (code, sequence, ...), or part of it.
                let addr = u.int_in_range(0..=map::REQUEST_LEN)?;
                let n = u.int_in_range(0..=map::REQUEST_LEN)?;
                let mut values: Vec<u16> = (0..n).map(|_| u.arbitrary()).collect::<Result<_>>()?;
                if let Some(code) = values.first_mut().filter(|_| addr == map::REQ_CODE) {
                    if u.ratio(3u8, 4u8)? {
                        *code = u.int_in_range(1..=3)?;
                    }
                }
                let seq_before = reg(&mut plc, &service, map::ST_ACK_SEQ);
                let _ = plc.write(&mut service, 1, ip, addr, &values);
                if let Ok(ToMachine::Start(job)) = jobs.try_recv() {
                    let Origin::Plc { seq } = job.start.origin else {
                        panic!("a PLC write started {:?}", job.start.origin)
                    };
                    assert_ne!(seq, NO_REQUEST, "a request with sequence 0 was taken");
                    assert!(
                        was_between,
                        "a start while busy or starting was not refused"
                    );
                    assert_eq!(
                        reg(&mut plc, &service, map::ST_ACK_SEQ),
                        seq_before,
                        "a start acknowledged before it was prepared"
                    );
                    // Prepared off the lock (the machine thread): taken or refused.
                    let answer = if refuse {
                        Err(Refusal::UnknownProgram)
                    } else {
                        Ok(())
                    };
                    let taken = service.prepared(&job, answer);
                    assert_eq!(taken, !refuse);
                    assert!(service.between_measurements() != taken);
                    assert_eq!(
                        reg(&mut plc, &service, map::ST_ACK_SEQ),
                        seq,
                        "a prepared start not acknowledged"
                    );
                    if taken {
                        assert_eq!(
                            reg(&mut plc, &service, map::RES_SEQ_HEAD),
                            NO_REQUEST,
                            "the last results still match a request after a start"
                        );
                    }
                }
            }
            3 => service.progress(u.arbitrary()?, u.arbitrary()?),
            4 => {
                let outcome = match u.int_in_range(0..=2)? {
                    0 => Outcome::Done,
                    1 => Outcome::Error {
                        kind: u.arbitrary()?,
                        code: u.arbitrary()?,
                    },
                    _ => Outcome::Aborted(
                        AbortReason::from_u8(u.int_in_range(1..=3)?)
                            .unwrap_or(AbortReason::Request),
                    ),
                };
                let origin = service.status().origin;
                service.finish(outcome, u.arbitrary()?, &BTreeMap::new(), None);
                // The result block carries the PLC's start's sequence, else none.
                let seq = match origin {
                    Some(Origin::Plc { seq }) => seq,
                    _ => NO_REQUEST,
                };
                assert_eq!(reg(&mut plc, &service, map::RES_SEQ_TAIL), seq);
            }
            5 => service.set_machine_ok(u.arbitrary()?),
            6 => opc_ua_command(u, &mut service, &mut plc, &jobs, refuse, was_between)?,
            _ => {
                sig.value(u64::from(plc.heartbeat_lost(&service, now)));
            }
        }
        let state = reg(&mut plc, &service, map::ST_STATE);
        assert_eq!(state, service.state() as u16);
        assert!(reg(&mut plc, &service, map::ST_PROGRESS) <= 1000);
        if was == State::Busy && service.state() != State::Busy {
            sig.debug(&(was, service.state()));
        }
        sig.debug(&service.state());
    }
    Ok(())
}

/// OPC UA's methods on the service, by the same rules as the PLC's requests; they leave
/// the PLC's acknowledge alone.
fn opc_ua_command(
    u: &mut Unstructured<'_>,
    service: &mut Service,
    plc: &mut PlcRegisters,
    jobs: &std::sync::mpsc::Receiver<ToMachine>,
    refuse: bool,
    was_between: bool,
) -> Result<()> {
    let cmd = match u.int_in_range(0..=2)? {
        0 => Command::Start {
            program: u.arbitrary()?,
            params: [u.arbitrary()?; START_PARAMS],
            confirm: u.arbitrary()?,
        },
        1 => Command::Abort,
        _ => Command::Acknowledge,
    };
    let ack = plc.read(service, map::ST_ACK_SEQ, 3).unwrap();
    let answer = service.command(cmd, Origin::OpcUa, true, "fuzz");
    if let Ok(Some(pending)) = answer {
        assert!(was_between, "an OPC UA start while busy was not refused");
        let Ok(ToMachine::Start(job)) = jobs.try_recv() else {
            panic!("a start taken but not handed to the machine thread")
        };
        let answer = if refuse {
            Err(Refusal::HistoryUnavailable)
        } else {
            Ok(())
        };
        service.prepared(&job, answer);
        assert_eq!(pending.wait(), answer);
    }
    assert_eq!(plc.read(service, map::ST_ACK_SEQ, 3).unwrap(), ack);
    Ok(())
}
