//! Bringing the drives up before the real-time loop runs: NMT reset, boot-up of every
//! configured node, the configuration written over SDO (cycle period, heartbeat
//! producer 0x1017, the consumer of the master's heartbeat 0x1016:1, cyclic synchronous
//! position mode, the PDO layout of [`super::process_data`]; a spindle drive profile
//! position mode and its orienting speed), then NMT start. Blocking, with a timeout
//! on every answer; any refusal is an error naming the node, the object and the
//! drive's SDO abort code.

use super::process_data::{LAYOUT, SPINDLE_LAYOUT};
use crate::can::{CanFrame, CanTransport};
use crate::canopen::cob_id::{self, CobKind};
use crate::canopen::nmt::{self, NmtCommand};
use crate::canopen::object;
use crate::canopen::pdo::configuration_writes;
use crate::canopen::sdo::{SdoAbortCode, SdoClient, SdoClientEvent, SdoOutcome};
use crate::cia402::mode::ModeOfOperation;
use crate::config::{AxisConfig, CanOpenBusConfig, MachineConfig, SpindleConfig};
use crate::machine::{ErrorKind, MachineError};
use std::time::{Duration, Instant};

/// How long drives get to answer the NMT reset with their boot-up message.
pub const BOOT_TIMEOUT: Duration = Duration::from_secs(3);

/// The NMT reset is sent again after this long without every boot-up: the reset or
/// a boot-up may have been lost on the bus (a reset before configuration is harmless).
const BOOT_REPEAT: Duration = Duration::from_secs(1);

/// Tries of one SDO transfer. Start-up only reads and writes configuration values, so
/// a transfer that timed out or broke on the protocol (a lost or duplicated frame) is
/// safe to repeat; a drive's refusal is not repeated.
const SDO_TRIES: u32 = 3;

fn transport_error(e: crate::can::TransportError) -> MachineError {
    MachineError::new(ErrorKind::Bus, e.to_string())
}

/// The CANopen bus of `cfg`; a machine on another bus is refused.
pub fn canopen_bus(cfg: &MachineConfig) -> Result<&CanOpenBusConfig, MachineError> {
    cfg.canopen_bus().ok_or_else(|| {
        MachineError::new(
            ErrorKind::InvalidRequest,
            format!(
                "{}: bus.kind = \"{}\": the CANopen master drives CANopen machines only",
                cfg.path.display(),
                cfg.bus.kind()
            ),
        )
    })
}

/// Resets communication on all nodes and waits for the boot-up of every configured
/// drive.
pub fn boot<T: CanTransport>(t: &mut T, cfg: &MachineConfig) -> Result<(), MachineError> {
    canopen_bus(cfg)?;
    t.transmit(&nmt::encode(NmtCommand::ResetCommunication, 0))
        .map_err(transport_error)?;
    let mut booted = [false; 128];
    let deadline = Instant::now() + BOOT_TIMEOUT;
    let mut repeat_at = Instant::now() + BOOT_REPEAT;
    let devices = devices(cfg);
    while devices.iter().any(|d| !booted[d.node as usize]) {
        let now = Instant::now();
        if now >= repeat_at && now < deadline {
            t.transmit(&nmt::encode(NmtCommand::ResetCommunication, 0))
                .map_err(transport_error)?;
            repeat_at = now + BOOT_REPEAT;
        }
        if now >= deadline {
            let missing: Vec<String> = devices
                .iter()
                .filter(|d| !booted[d.node as usize])
                .map(|d| format!("node {} ({})", d.node, d.label))
                .collect();
            return Err(MachineError::new(
                ErrorKind::NodeLost,
                format!(
                    "no boot-up within {} s from {}: check the bus wiring, bit rate and node IDs",
                    BOOT_TIMEOUT.as_secs(),
                    missing.join(", ")
                ),
            ));
        }
        let wait = (deadline - now).min(repeat_at.saturating_duration_since(now));
        if let Some(f) = t.receive(wait).map_err(transport_error)? {
            if let CobKind::Heartbeat { node } = cob_id::classify(f.cob_id()) {
                if f.data() == [0] {
                    booted[node as usize] = true;
                }
            }
        }
    }
    Ok(())
}

enum Request<'a> {
    Download(&'a [u8]),
    Upload,
}

/// Runs one SDO transfer to completion, repeated (up to [`SDO_TRIES`]) when it timed
/// out or broke on the protocol. An abort by the drive is the outcome `Aborted`, not
/// an error: the caller decides what it means.
fn sdo_transfer<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    index: u16,
    sub: u8,
    request: Request<'_>,
    timeout: Duration,
) -> Result<SdoOutcome, MachineError> {
    let mut tries = 1;
    loop {
        let outcome = sdo_try(t, dev, index, sub, &request, timeout);
        let again = match &outcome {
            Err(e) => e.kind == ErrorKind::Timeout,
            Ok(SdoOutcome::Aborted(code)) => is_protocol_abort(*code),
            Ok(_) => false,
        };
        if !again || tries >= SDO_TRIES {
            return outcome;
        }
        tries += 1;
    }
}

/// Aborts that say a frame went missing or came twice, not that the drive refuses.
fn is_protocol_abort(code: SdoAbortCode) -> bool {
    [
        SdoAbortCode::TOGGLE_BIT_NOT_ALTERNATED,
        SdoAbortCode::TIMEOUT,
        SdoAbortCode::COMMAND_SPECIFIER_INVALID,
    ]
    .contains(&code)
}

fn sdo_try<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    index: u16,
    sub: u8,
    request: &Request<'_>,
    timeout: Duration,
) -> Result<SdoOutcome, MachineError> {
    let mut client = SdoClient::new(dev.node);
    let first = match *request {
        Request::Download(data) => client.download(index, sub, data),
        Request::Upload => client.upload(index, sub),
    }
    .map_err(|e| {
        MachineError::new(
            ErrorKind::Other,
            format!("SDO 0x{index:04X}:{sub:02X}: {e}"),
        )
        .with_node(dev.node)
    })?;
    sdo_exchange(t, &mut client, first, dev, index, sub, timeout)
}

fn refused(dev: &Device, what: String, code: SdoAbortCode) -> MachineError {
    MachineError::new(
        ErrorKind::DriveFault,
        format!(
            "{}: {what} refused with SDO abort 0x{:08X} ({code})",
            dev.label, code.0
        ),
    )
    .with_node(dev.node)
}

/// One SDO download, waiting for the answer.
pub fn sdo_download<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    index: u16,
    sub: u8,
    data: &[u8],
    timeout: Duration,
) -> Result<(), MachineError> {
    match sdo_transfer(t, dev, index, sub, Request::Download(data), timeout)? {
        SdoOutcome::Aborted(code) => Err(refused(
            dev,
            format!("writing 0x{index:04X}:{sub:02X} = {data:02X?}"),
            code,
        )),
        SdoOutcome::Downloaded | SdoOutcome::Uploaded(_) => Ok(()),
    }
}

/// One SDO upload, waiting for the answer.
pub fn sdo_upload<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    index: u16,
    sub: u8,
    timeout: Duration,
) -> Result<Vec<u8>, MachineError> {
    match sdo_transfer(t, dev, index, sub, Request::Upload, timeout)? {
        SdoOutcome::Aborted(code) => Err(refused(
            dev,
            format!("reading 0x{index:04X}:{sub:02X}"),
            code,
        )),
        SdoOutcome::Uploaded(v) => Ok(v.to_vec()),
        SdoOutcome::Downloaded => Ok(Vec::new()),
    }
}

fn sdo_exchange<T: CanTransport>(
    t: &mut T,
    client: &mut SdoClient,
    first: CanFrame,
    dev: &Device,
    index: u16,
    sub: u8,
    timeout: Duration,
) -> Result<SdoOutcome, MachineError> {
    t.transmit(&first).map_err(transport_error)?;
    let mut deadline = Instant::now() + timeout;
    loop {
        let now = Instant::now();
        if now >= deadline {
            if let Some(abort) = client.abort(SdoAbortCode::TIMEOUT) {
                let _ = t.transmit(&abort);
            }
            return Err(MachineError::new(
                ErrorKind::Timeout,
                format!(
                    "{}: no SDO answer for 0x{index:04X}:{sub:02X} within {} ms",
                    dev.label,
                    timeout.as_millis()
                ),
            )
            .with_node(dev.node));
        }
        let Some(f) = t.receive(deadline - now).map_err(transport_error)? else {
            continue;
        };
        match client.on_frame(&f) {
            SdoClientEvent::Ignored => {}
            SdoClientEvent::Transmit(next) => {
                t.transmit(&next).map_err(transport_error)?;
                deadline = Instant::now() + timeout;
            }
            SdoClientEvent::Done(outcome) => return Ok(outcome),
            SdoClientEvent::Aborting { frame, code } => {
                t.transmit(&frame).map_err(transport_error)?;
                return Ok(SdoOutcome::Aborted(code));
            }
        }
    }
}

/// A node start-up talks to, named for the operator ("axis X", "spindle").
pub struct Device {
    pub node: u8,
    pub label: String,
}

impl Device {
    pub fn axis(a: &AxisConfig) -> Self {
        Self {
            node: a.canopen_node(),
            label: format!("axis {}", a.name),
        }
    }

    pub fn spindle(s: &SpindleConfig) -> Self {
        Self {
            node: s.node,
            label: "spindle".into(),
        }
    }
}

/// Every node start-up brings up: the axes' drives, then the spindle's.
pub fn devices(cfg: &MachineConfig) -> Vec<Device> {
    cfg.axes
        .iter()
        .map(Device::axis)
        .chain(cfg.spindle.as_ref().map(Device::spindle))
        .collect()
}

/// What the drive calls itself (0x1008, optional in CiA 301: a drive without it is
/// "unnamed").
fn device_name<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    timeout: Duration,
) -> Result<String, MachineError> {
    Ok(
        match sdo_transfer(
            t,
            dev,
            object::MANUFACTURER_DEVICE_NAME,
            0,
            Request::Upload,
            timeout,
        )? {
            SdoOutcome::Uploaded(v) => String::from_utf8_lossy(&v)
                .trim_end_matches('\0')
                .to_string(),
            _ => "unnamed".to_string(),
        },
    )
}

/// The communication settings every drive gets: cycle period, heartbeat producer, and
/// the consumer of the master's heartbeat.
fn configure_communication<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    bus: &CanOpenBusConfig,
    timeout: Duration,
) -> Result<(), MachineError> {
    sdo_download(
        t,
        dev,
        object::COMMUNICATION_CYCLE_PERIOD,
        0,
        &bus.sync_period_us.to_le_bytes(),
        timeout,
    )?;
    sdo_download(
        t,
        dev,
        object::PRODUCER_HEARTBEAT_TIME,
        0,
        &bus.heartbeat_producer_ms.to_le_bytes(),
        timeout,
    )?;
    // The drive watches the master's heartbeat (see `RtLoop`), and stops when it
    // is missing; a master without one configures no consumer.
    let consumer = bus.master_heartbeat_consumer_entry();
    if consumer != 0 {
        sdo_download(
            t,
            dev,
            object::CONSUMER_HEARTBEAT_TIME,
            1,
            &consumer.to_le_bytes(),
            timeout,
        )?;
    }
    Ok(())
}

/// Writes the PDOs of `layouts` (a subset of [`LAYOUT`]).
fn configure_pdos<T: CanTransport>(
    t: &mut T,
    dev: &Device,
    layouts: &[super::process_data::PdoLayout],
    timeout: Duration,
) -> Result<(), MachineError> {
    for l in layouts {
        for w in configuration_writes(
            l.direction,
            l.number,
            dev.node,
            &l.mapping(),
            l.transmission_type,
        ) {
            let bytes = w.value.to_le_bytes();
            sdo_download(t, dev, w.index, w.sub, &bytes[..w.size as usize], timeout)?;
        }
    }
    Ok(())
}

/// The spindle's drive: profile position (it must have it, 0x6502 bit 0), the
/// orienting speed and acceleration, and only RPDO1 and TPDO1 (controlword and
/// target, statusword and actual position: it has no probe input to arm).
fn configure_spindle<T: CanTransport>(
    t: &mut T,
    s: &SpindleConfig,
    timeout: Duration,
) -> Result<(), MachineError> {
    let dev = Device::spindle(s);
    let modes = sdo_upload(t, &dev, object::SUPPORTED_DRIVE_MODES, 0, timeout)?;
    let modes = modes
        .get(..4)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if modes & 1 == 0 {
        return Err(MachineError::new(
            ErrorKind::InvalidRequest,
            format!(
                "spindle: the drive of node {} has no profile position mode (0x6502 = 0x{modes:08X}, bit 0 clear): an oriented stop needs it",
                s.node
            ),
        )
        .with_node(s.node));
    }
    sdo_download(
        t,
        &dev,
        object::MODES_OF_OPERATION,
        0,
        &[ModeOfOperation::ProfilePosition as i8 as u8],
        timeout,
    )?;
    for (index, v) in [
        (object::PROFILE_VELOCITY, s.profile_velocity()),
        (object::PROFILE_ACCELERATION, s.profile_acceleration()),
        (object::PROFILE_DECELERATION, s.profile_acceleration()),
    ] {
        sdo_download(t, &dev, index, 0, &v.to_le_bytes(), timeout)?;
    }
    configure_pdos(t, &dev, &SPINDLE_LAYOUT, timeout)
}

/// Writes the configuration of every drive (see module doc). Returns each drive with
/// what it calls itself.
pub fn configure<T: CanTransport>(
    t: &mut T,
    cfg: &MachineConfig,
) -> Result<Vec<String>, MachineError> {
    let bus = canopen_bus(cfg)?;
    let timeout = Duration::from_millis(bus.sdo_timeout_ms as u64);
    let mut drives = Vec::new();
    for axis in &cfg.axes {
        let dev = Device::axis(axis);
        let name = device_name(t, &dev, timeout)?;
        drives.push(format!("{} = node {}: {name}", axis.name, dev.node));
        configure_communication(t, &dev, bus, timeout)?;
        sdo_download(
            t,
            &dev,
            object::MODES_OF_OPERATION,
            0,
            &[ModeOfOperation::CyclicSynchronousPosition as i8 as u8],
            timeout,
        )?;
        configure_pdos(t, &dev, &LAYOUT, timeout)?;
    }
    if let Some(s) = &cfg.spindle {
        let dev = Device::spindle(s);
        let name = device_name(t, &dev, timeout)?;
        drives.push(format!("spindle = node {}: {name}", s.node));
        configure_communication(t, &dev, bus, timeout)?;
        configure_spindle(t, s, timeout)?;
    }
    t.transmit(&nmt::encode(NmtCommand::Start, 0))
        .map_err(transport_error)?;
    Ok(drives)
}
