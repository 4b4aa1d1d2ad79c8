//! CANopen (CiA 301) protocol core: frames in, frames out, no I/O.
//!
//! Every module encodes and decodes one CiA 301 service on [`CanFrame`] values; the
//! stateful parts (SDO client/server, heartbeat consumer, SYNC producer) take time as
//! `now_ns` arguments and never block. The master and the simulated drive share this
//! code, so both sides agree on every byte.

pub mod cob_id;
pub mod emcy;
pub mod heartbeat;
pub mod nmt;
pub mod object;
pub mod pdo;
pub mod sdo;
pub mod sync;

pub use cob_id::{classify, CobKind};
pub use emcy::Emcy;
pub use heartbeat::{HeartbeatConsumer, HeartbeatEvent};
pub use nmt::{NmtCommand, NmtState};
pub use pdo::{MapEntry, PdoDirection, PdoMapping, PdoMappingError, SdoWrite};
pub use sdo::{
    ObjectDictionary, SdoAbortCode, SdoClient, SdoClientEvent, SdoError, SdoOutcome, SdoServer,
};

use crate::can::CanFrame;

/// Why a frame is not the CANopen message it was decoded as.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The identifier does not belong to this service.
    #[error("{service}: COB-ID {cob_id:#05X} does not belong to this service")]
    WrongCobId { service: &'static str, cob_id: u16 },
    /// The data length is not one the standard allows for this service.
    #[error("{service}: {found} data bytes, expected {}", expected_len(*min, *max))]
    WrongLength {
        service: &'static str,
        found: usize,
        min: usize,
        max: usize,
    },
    /// A remote (RTR) frame where a data frame was expected.
    #[error("{service}: remote frame, expected a data frame")]
    RemoteFrame { service: &'static str },
    /// The command specifier / command byte is not one the standard defines.
    #[error("{service}: unknown command specifier {value:#04X}")]
    UnknownCommandSpecifier { service: &'static str, value: u8 },
    /// A field holds a value the standard does not allow.
    #[error("{service}: {field} = {value:#X} is not allowed")]
    InvalidValue {
        service: &'static str,
        field: &'static str,
        value: u32,
    },
}

fn expected_len(min: usize, max: usize) -> String {
    if min == max {
        format!("{min}")
    } else {
        format!("{min}..={max}")
    }
}

/// A node-ID outside 1..=127.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("node-ID {0} is outside 1..=127")]
pub struct InvalidNodeId(pub u8);

/// Checks a node-ID (CiA 301: 1..=127; 0 is only the NMT broadcast address).
pub const fn check_node_id(node: u8) -> Result<u8, InvalidNodeId> {
    if node >= 1 && node <= 127 {
        Ok(node)
    } else {
        Err(InvalidNodeId(node))
    }
}

/// Builds a frame whose identifier and length are valid by construction (a function
/// code plus a `u8` node-ID never exceeds 0x7FF; callers pass at most 8 bytes).
pub(crate) fn frame(cob_id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new(cob_id, data).expect("COB-ID <= 0x7FF and <= 8 data bytes by construction")
}

/// Rejects remote frames and lengths outside `min..=max`.
pub(crate) fn check_data(
    service: &'static str,
    f: &CanFrame,
    min: usize,
    max: usize,
) -> Result<(), DecodeError> {
    if f.is_rtr() {
        return Err(DecodeError::RemoteFrame { service });
    }
    let found = f.data().len();
    if found < min || found > max {
        return Err(DecodeError::WrongLength {
            service,
            found,
            min,
            max,
        });
    }
    Ok(())
}
