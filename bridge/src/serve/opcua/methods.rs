//! The methods of Production: StartProgram, Abort, Acknowledge. Each is a command of
//! the measurement service, by the rules every face follows (one measurement at a
//! time, the same abort flag), and answers with the PLC face's reason: 0 taken, else the reason register's
//! value, and the reason in words. Who may call them the authenticator decides (a
//! user of the users file; StartProgram only with `may_start`).

use super::auth::{ABORT, ACKNOWLEDGE, START_PROGRAM};
use crate::serve::gateway::{lock, Shared};
use crate::serve::measurement::{Command, Origin, START_PARAMS};
use opcua::server::node_manager::memory::SimpleNodeManager;
use opcua::types::{NodeId, StatusCode, Variant, VariantScalarTypeId};

/// Registers the three methods' callbacks.
pub fn register(manager: &SimpleNodeManager, ns: u16, shared: &Shared) {
    for (name, command) in [
        (START_PROGRAM, None),
        (ABORT, Some(Command::Abort)),
        (ACKNOWLEDGE, Some(Command::Acknowledge)),
    ] {
        let shared = shared.clone();
        manager.inner().add_method_callback(
            NodeId::new(ns, format!("Machine.Production.{name}")),
            move |args| {
                let cmd = match command {
                    Some(c) => c,
                    None => start_arguments(args)?,
                };
                // The lock is released before a start is waited for: it is prepared
                // (program, machine state, history row) on the machine thread, while
                // the face's other tasks go on on its other worker.
                let answer = lock(&shared)
                    .service
                    .command(cmd, Origin::OpcUa, true, "OPC UA");
                let answer = match answer {
                    Ok(Some(pending)) => tokio::task::block_in_place(|| pending.wait()),
                    Ok(None) => Ok(()),
                    Err(r) => Err(r),
                };
                Ok(match answer {
                    Ok(()) => vec![Variant::from(0u16), Variant::from("taken")],
                    Err(r) => vec![Variant::from(r as u16), Variant::from(r.describe())],
                })
            },
        );
    }
}

/// StartProgram(Number UInt16, Parameters Float[<=8], Confirm Boolean), as the method's
/// InputArguments declare them. An argument of another data type is refused with
/// BadTypeMismatch (OPC 10000-4 §5.11.2: the stack does not check them against the
/// declaration), more than 8 parameters with BadInvalidArgument: the caller's errors,
/// not refusals of the gateway. Parameters and Confirm may be left out (0, false).
fn start_arguments(args: &[Variant]) -> Result<Command, StatusCode> {
    if args.len() > 3 {
        return Err(StatusCode::BadTooManyArguments);
    }
    let number = match args.first() {
        Some(Variant::UInt16(n)) => *n,
        Some(_) => return Err(StatusCode::BadTypeMismatch),
        None => return Err(StatusCode::BadArgumentsMissing),
    };
    let mut params = [0.0f32; START_PARAMS];
    match args.get(1) {
        None | Some(Variant::Empty) => {}
        Some(Variant::Array(list)) if list.value_type == VariantScalarTypeId::Float => {
            if list.values.len() > START_PARAMS {
                return Err(StatusCode::BadInvalidArgument);
            }
            for (p, x) in params.iter_mut().zip(&list.values) {
                // A non-finite parameter goes through, for the core to refuse it as
                // the PLC face does (reason 7).
                match x {
                    Variant::Float(f) => *p = *f,
                    _ => return Err(StatusCode::BadTypeMismatch),
                }
            }
        }
        Some(_) => return Err(StatusCode::BadTypeMismatch),
    }
    let confirm = match args.get(2) {
        None | Some(Variant::Empty) => false,
        Some(Variant::Boolean(b)) => *b,
        Some(_) => return Err(StatusCode::BadTypeMismatch),
    };
    Ok(Command::Start {
        program: number,
        params,
        confirm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn start_arguments_are_checked() {
        let params = Variant::from(vec![1.5f32, -2.25]);
        let cmd = start_arguments(&[Variant::from(431u16), params, Variant::from(true)]).unwrap();
        let Command::Start {
            program,
            params,
            confirm,
        } = cmd
        else {
            panic!("{cmd:?}")
        };
        assert_eq!(program, 431);
        assert_eq!(&params[..3], &[1.5, -2.25, 0.0]);
        assert!(confirm);
        assert_eq!(
            start_arguments(&[Variant::from(431u16), Variant::from(vec![0.0f32; 9])]),
            Err(StatusCode::BadInvalidArgument)
        );
    }

    #[test]
    fn arguments_of_another_data_type_are_a_type_mismatch() {
        // An Int32 where UInt16 is declared was taken before (issue 36).
        for args in [
            vec![Variant::from(431i32)],
            vec![Variant::from(431.0f64)],
            vec![Variant::from(431u16), Variant::from(vec![1.5f64])],
            vec![Variant::from(431u16), Variant::from(1.5f32)],
            vec![Variant::from(431u16), Variant::Empty, Variant::from(1u8)],
        ] {
            assert_eq!(
                start_arguments(&args),
                Err(StatusCode::BadTypeMismatch),
                "{args:?}"
            );
        }
        assert_eq!(start_arguments(&[]), Err(StatusCode::BadArgumentsMissing));
    }
}
