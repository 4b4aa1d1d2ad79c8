//! Bringing the drives up before the real-time loop runs: NMT reset, boot-up of every
//! configured node, the configuration written over SDO (cycle period, heartbeat
//! producer 0x1017, the consumer of the master's heartbeat 0x1016:1, cyclic synchronous
//! position mode, the PDO layout of [`super::process_data`]), then
//! NMT start. Blocking, with a timeout on every answer; any refusal is an error naming
//! the node, the object and the drive's SDO abort code.

use super::process_data::LAYOUT;
use crate::can::{CanFrame, CanTransport};
use crate::canopen::cob_id::{self, CobKind};
use crate::canopen::nmt::{self, NmtCommand};
use crate::canopen::object;
use crate::canopen::pdo::configuration_writes;
use crate::canopen::sdo::{SdoAbortCode, SdoClient, SdoClientEvent, SdoOutcome};
use crate::cia402::mode::ModeOfOperation;
use crate::config::{AxisConfig, CanOpenBusConfig, MachineConfig};
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
    while cfg.axes.iter().any(|a| !booted[a.canopen_node() as usize]) {
        let now = Instant::now();
        if now >= repeat_at && now < deadline {
            t.transmit(&nmt::encode(NmtCommand::ResetCommunication, 0))
                .map_err(transport_error)?;
            repeat_at = now + BOOT_REPEAT;
        }
        if now >= deadline {
            let missing: Vec<String> = cfg
                .axes
                .iter()
                .filter(|a| !booted[a.canopen_node() as usize])
                .map(|a| format!("node {} ({})", a.canopen_node(), a.name))
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
    axis: &AxisConfig,
    index: u16,
    sub: u8,
    request: Request<'_>,
    timeout: Duration,
) -> Result<SdoOutcome, MachineError> {
    let mut tries = 1;
    loop {
        let outcome = sdo_try(t, axis, index, sub, &request, timeout);
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
    axis: &AxisConfig,
    index: u16,
    sub: u8,
    request: &Request<'_>,
    timeout: Duration,
) -> Result<SdoOutcome, MachineError> {
    let mut client = SdoClient::new(axis.canopen_node());
    let first = match *request {
        Request::Download(data) => client.download(index, sub, data),
        Request::Upload => client.upload(index, sub),
    }
    .map_err(|e| {
        MachineError::new(
            ErrorKind::Other,
            format!("SDO 0x{index:04X}:{sub:02X}: {e}"),
        )
        .with_node(axis.canopen_node())
    })?;
    sdo_exchange(t, &mut client, first, axis, index, sub, timeout)
}

fn refused(axis: &AxisConfig, what: String, code: SdoAbortCode) -> MachineError {
    MachineError::new(
        ErrorKind::DriveFault,
        format!(
            "axis {}: {what} refused with SDO abort 0x{:08X} ({code})",
            axis.name, code.0
        ),
    )
    .with_node(axis.canopen_node())
}

/// One SDO download, waiting for the answer.
pub fn sdo_download<T: CanTransport>(
    t: &mut T,
    axis: &AxisConfig,
    index: u16,
    sub: u8,
    data: &[u8],
    timeout: Duration,
) -> Result<(), MachineError> {
    match sdo_transfer(t, axis, index, sub, Request::Download(data), timeout)? {
        SdoOutcome::Aborted(code) => Err(refused(
            axis,
            format!("writing 0x{index:04X}:{sub:02X} = {data:02X?}"),
            code,
        )),
        SdoOutcome::Downloaded | SdoOutcome::Uploaded(_) => Ok(()),
    }
}

/// One SDO upload, waiting for the answer.
pub fn sdo_upload<T: CanTransport>(
    t: &mut T,
    axis: &AxisConfig,
    index: u16,
    sub: u8,
    timeout: Duration,
) -> Result<Vec<u8>, MachineError> {
    match sdo_transfer(t, axis, index, sub, Request::Upload, timeout)? {
        SdoOutcome::Aborted(code) => Err(refused(
            axis,
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
    axis: &AxisConfig,
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
                    "axis {}: no SDO answer for 0x{index:04X}:{sub:02X} within {} ms",
                    axis.name,
                    timeout.as_millis()
                ),
            )
            .with_node(axis.canopen_node()));
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

/// Writes the configuration of every drive (see module doc). Returns what each drive
/// calls itself (0x1008, optional in CiA 301: a drive without it is "unnamed").
pub fn configure<T: CanTransport>(
    t: &mut T,
    cfg: &MachineConfig,
) -> Result<Vec<String>, MachineError> {
    let bus = canopen_bus(cfg)?;
    let timeout = Duration::from_millis(bus.sdo_timeout_ms as u64);
    let mut drives = Vec::new();
    for axis in &cfg.axes {
        let name = match sdo_transfer(
            t,
            axis,
            object::MANUFACTURER_DEVICE_NAME,
            0,
            Request::Upload,
            timeout,
        )? {
            SdoOutcome::Uploaded(v) => String::from_utf8_lossy(&v)
                .trim_end_matches('\0')
                .to_string(),
            _ => "unnamed".to_string(),
        };
        let n = axis.canopen_node();
        drives.push(format!("{} = node {n}: {name}", axis.name));
        sdo_download(
            t,
            axis,
            object::COMMUNICATION_CYCLE_PERIOD,
            0,
            &bus.sync_period_us.to_le_bytes(),
            timeout,
        )?;
        sdo_download(
            t,
            axis,
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
                axis,
                object::CONSUMER_HEARTBEAT_TIME,
                1,
                &consumer.to_le_bytes(),
                timeout,
            )?;
        }
        sdo_download(
            t,
            axis,
            object::MODES_OF_OPERATION,
            0,
            &[ModeOfOperation::CyclicSynchronousPosition as i8 as u8],
            timeout,
        )?;
        for l in &LAYOUT {
            for w in
                configuration_writes(l.direction, l.number, n, &l.mapping(), l.transmission_type)
            {
                let bytes = w.value.to_le_bytes();
                sdo_download(t, axis, w.index, w.sub, &bytes[..w.size as usize], timeout)?;
            }
        }
    }
    t.transmit(&nmt::encode(NmtCommand::Start, 0))
        .map_err(transport_error)?;
    Ok(drives)
}
