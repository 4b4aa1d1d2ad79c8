//! Modbus exceptions and transport failures as [`ErrorKind`]s. An exception is the
//! device's answer (data, as tokio-modbus returns it) until the machine decides it
//! fails the command; then it is mapped here.

use crate::machine::ErrorKind;
use tokio_modbus::ExceptionCode;

/// The kind of failure an exception answer means for the command that got it.
pub const fn exception_kind(e: ExceptionCode) -> ErrorKind {
    match e {
        ExceptionCode::IllegalDataAddress | ExceptionCode::IllegalDataValue => {
            ErrorKind::InvalidRequest
        }
        ExceptionCode::IllegalFunction => ErrorKind::InvalidRequest,
        ExceptionCode::GatewayTargetDevice => ErrorKind::NodeLost,
        ExceptionCode::GatewayPathUnavailable => ErrorKind::Bus,
        ExceptionCode::ServerDeviceBusy | ExceptionCode::Acknowledge => ErrorKind::Timeout,
        ExceptionCode::ServerDeviceFailure => ErrorKind::DriveFault,
        ExceptionCode::MemoryParityError | ExceptionCode::Custom(_) => ErrorKind::Other,
    }
}

/// The exception's code and name, for the operator.
pub fn describe(e: ExceptionCode) -> String {
    let name = match e {
        ExceptionCode::IllegalFunction => "illegal function",
        ExceptionCode::IllegalDataAddress => "illegal data address",
        ExceptionCode::IllegalDataValue => "illegal data value",
        ExceptionCode::ServerDeviceFailure => "server device failure",
        ExceptionCode::Acknowledge => "acknowledge",
        ExceptionCode::ServerDeviceBusy => "server device busy",
        ExceptionCode::MemoryParityError => "memory parity error",
        ExceptionCode::GatewayPathUnavailable => "gateway path unavailable",
        ExceptionCode::GatewayTargetDevice => "gateway target device failed to respond",
        ExceptionCode::Custom(_) => "exception",
    };
    format!("Modbus exception 0x{:02X} ({name})", u8::from(e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_as_the_issue_asks() {
        assert_eq!(
            exception_kind(ExceptionCode::IllegalDataAddress),
            ErrorKind::InvalidRequest
        );
        assert_eq!(
            exception_kind(ExceptionCode::IllegalDataValue),
            ErrorKind::InvalidRequest
        );
        assert_eq!(
            exception_kind(ExceptionCode::GatewayTargetDevice),
            ErrorKind::NodeLost
        );
        assert_eq!(
            describe(ExceptionCode::ServerDeviceBusy),
            "Modbus exception 0x06 (server device busy)"
        );
    }
}
