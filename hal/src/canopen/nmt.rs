//! Network management (NMT): the master's node-control commands (COB-ID 0x000, two
//! bytes: command, node-ID with 0 = all nodes) and the NMT states a node reports.

use super::{check_data, cob_id, frame, DecodeError};
use crate::can::CanFrame;

const SERVICE: &str = "NMT";

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum NmtCommand {
    Start = 0x01,
    Stop = 0x02,
    EnterPreOperational = 0x80,
    ResetNode = 0x81,
    ResetCommunication = 0x82,
}

impl TryFrom<u8> for NmtCommand {
    type Error = DecodeError;
    fn try_from(value: u8) -> Result<Self, DecodeError> {
        Ok(match value {
            0x01 => Self::Start,
            0x02 => Self::Stop,
            0x80 => Self::EnterPreOperational,
            0x81 => Self::ResetNode,
            0x82 => Self::ResetCommunication,
            _ => {
                return Err(DecodeError::UnknownCommandSpecifier {
                    service: SERVICE,
                    value,
                })
            }
        })
    }
}

/// NMT state as carried in heartbeat / boot-up frames (bit 7, the node-guarding
/// toggle, removed).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum NmtState {
    BootUp = 0x00,
    Stopped = 0x04,
    Operational = 0x05,
    PreOperational = 0x7F,
}

impl TryFrom<u8> for NmtState {
    type Error = DecodeError;
    /// Ignores bit 7 (node-guarding toggle).
    fn try_from(value: u8) -> Result<Self, DecodeError> {
        Ok(match value & 0x7F {
            0x00 => Self::BootUp,
            0x04 => Self::Stopped,
            0x05 => Self::Operational,
            0x7F => Self::PreOperational,
            v => {
                return Err(DecodeError::InvalidValue {
                    service: "heartbeat",
                    field: "NMT state",
                    value: v.into(),
                })
            }
        })
    }
}

/// The NMT command frame; `node` 0 addresses all nodes.
pub fn encode(cmd: NmtCommand, node: u8) -> CanFrame {
    frame(cob_id::NMT, &[cmd as u8, node])
}

/// Command and addressed node (0 = all).
pub fn decode(f: &CanFrame) -> Result<(NmtCommand, u8), DecodeError> {
    if f.cob_id() != cob_id::NMT {
        return Err(DecodeError::WrongCobId {
            service: SERVICE,
            cob_id: f.cob_id(),
        });
    }
    check_data(SERVICE, f, 2, 2)?;
    let d = f.data();
    if d[1] > 127 {
        return Err(DecodeError::InvalidValue {
            service: SERVICE,
            field: "node-ID",
            value: d[1].into(),
        });
    }
    Ok((NmtCommand::try_from(d[0])?, d[1]))
}

impl NmtState {
    /// The state a node enters on `cmd` (CiA 301 NMT slave state machine). Reset
    /// commands lead through boot-up to pre-operational; the node sends its boot-up
    /// frame on the way.
    pub const fn after(self, cmd: NmtCommand) -> NmtState {
        match cmd {
            NmtCommand::Start => NmtState::Operational,
            NmtCommand::Stop => NmtState::Stopped,
            NmtCommand::EnterPreOperational => NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => NmtState::PreOperational,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        for cmd in [
            NmtCommand::Start,
            NmtCommand::Stop,
            NmtCommand::EnterPreOperational,
            NmtCommand::ResetNode,
            NmtCommand::ResetCommunication,
        ] {
            assert_eq!(decode(&encode(cmd, 7)).unwrap(), (cmd, 7));
        }
    }

    #[test]
    fn rejects_malformed() {
        let f = CanFrame::new(0, &[0x01]).unwrap();
        assert!(matches!(
            decode(&f),
            Err(DecodeError::WrongLength { found: 1, .. })
        ));
        let f = CanFrame::new(0, &[0x03, 1]).unwrap();
        assert!(matches!(
            decode(&f),
            Err(DecodeError::UnknownCommandSpecifier { value: 3, .. })
        ));
        let f = CanFrame::new(0x80, &[0x01, 1]).unwrap();
        assert!(matches!(decode(&f), Err(DecodeError::WrongCobId { .. })));
        assert_eq!(NmtState::try_from(0x85).unwrap(), NmtState::Operational);
        assert!(NmtState::try_from(0x06).is_err());
    }
}
