//! COB-IDs of the CiA 301 predefined connection set: function code (bits 10-7) plus
//! node-ID (bits 6-0).

pub const NMT: u16 = 0x000;
pub const SYNC: u16 = 0x080;
pub const EMCY_BASE: u16 = 0x080;
pub const TIME: u16 = 0x100;
pub const TPDO_BASE: [u16; 4] = [0x180, 0x280, 0x380, 0x480];
pub const RPDO_BASE: [u16; 4] = [0x200, 0x300, 0x400, 0x500];
pub const SDO_RESPONSE_BASE: u16 = 0x580;
pub const SDO_REQUEST_BASE: u16 = 0x600;
pub const HEARTBEAT_BASE: u16 = 0x700;

/// What a COB-ID means in the predefined connection set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CobKind {
    Nmt,
    Sync,
    Emcy {
        node: u8,
    },
    Tpdo {
        num: u8,
        node: u8,
    },
    Rpdo {
        num: u8,
        node: u8,
    },
    /// Server to client (0x580 + node).
    SdoResponse {
        node: u8,
    },
    /// Client to server (0x600 + node).
    SdoRequest {
        node: u8,
    },
    /// Heartbeat, boot-up or node guarding (0x700 + node).
    Heartbeat {
        node: u8,
    },
    /// TIME, LSS, the restricted ranges, node-ID 0 under a per-node function code.
    Other,
}

/// Classifies an 11-bit identifier by the predefined connection set.
pub const fn classify(cob_id: u16) -> CobKind {
    if cob_id > 0x7FF {
        return CobKind::Other;
    }
    let node = (cob_id & 0x7F) as u8;
    match (cob_id & 0x780, node) {
        (0x000, 0) => CobKind::Nmt,
        (0x080, 0) => CobKind::Sync,
        // Function codes below are per node; node-ID 0 there is not a node.
        (_, 0) => CobKind::Other,
        (0x080, _) => CobKind::Emcy { node },
        (0x180, _) => CobKind::Tpdo { num: 1, node },
        (0x200, _) => CobKind::Rpdo { num: 1, node },
        (0x280, _) => CobKind::Tpdo { num: 2, node },
        (0x300, _) => CobKind::Rpdo { num: 2, node },
        (0x380, _) => CobKind::Tpdo { num: 3, node },
        (0x400, _) => CobKind::Rpdo { num: 3, node },
        (0x480, _) => CobKind::Tpdo { num: 4, node },
        (0x500, _) => CobKind::Rpdo { num: 4, node },
        (0x580, _) => CobKind::SdoResponse { node },
        (0x600, _) => CobKind::SdoRequest { node },
        (0x700, _) => CobKind::Heartbeat { node },
        _ => CobKind::Other,
    }
}

/// COB-ID of TPDO `num` of `node`.
///
/// # Panics
/// If `num` is not 1..=4 (the predefined connection set has four PDOs a direction;
/// callers pass literals).
pub const fn tpdo_cob(num: u8, node: u8) -> u16 {
    assert!(num >= 1 && num <= 4, "PDO number must be 1..=4");
    TPDO_BASE[(num - 1) as usize] + node as u16
}

/// COB-ID of RPDO `num` of `node`.
///
/// # Panics
/// If `num` is not 1..=4.
pub const fn rpdo_cob(num: u8, node: u8) -> u16 {
    assert!(num >= 1 && num <= 4, "PDO number must be 1..=4");
    RPDO_BASE[(num - 1) as usize] + node as u16
}

pub const fn emcy_cob(node: u8) -> u16 {
    EMCY_BASE + node as u16
}

/// Server to client (the answers of node `node`).
pub const fn sdo_response_cob(node: u8) -> u16 {
    SDO_RESPONSE_BASE + node as u16
}

/// Client to server (requests to node `node`).
pub const fn sdo_request_cob(node: u8) -> u16 {
    SDO_REQUEST_BASE + node as u16
}

pub const fn heartbeat_cob(node: u8) -> u16 {
    HEARTBEAT_BASE + node as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classifies_predefined_set() {
        assert_eq!(classify(0x000), CobKind::Nmt);
        assert_eq!(classify(0x080), CobKind::Sync);
        assert_eq!(classify(0x085), CobKind::Emcy { node: 5 });
        assert_eq!(classify(0x100), CobKind::Other);
        assert_eq!(classify(0x183), CobKind::Tpdo { num: 1, node: 3 });
        assert_eq!(classify(0x4FF), CobKind::Tpdo { num: 4, node: 127 });
        assert_eq!(classify(0x203), CobKind::Rpdo { num: 1, node: 3 });
        assert_eq!(classify(0x503), CobKind::Rpdo { num: 4, node: 3 });
        assert_eq!(classify(0x585), CobKind::SdoResponse { node: 5 });
        assert_eq!(classify(0x605), CobKind::SdoRequest { node: 5 });
        assert_eq!(classify(0x705), CobKind::Heartbeat { node: 5 });
        assert_eq!(classify(0x180), CobKind::Other);
        assert_eq!(classify(0x700), CobKind::Other);
        // LSS (0x7E4/0x7E5) sits in the restricted range, not a heartbeat.
        assert_eq!(classify(0x7E5), CobKind::Other);
        assert_eq!(classify(0x001), CobKind::Other);
    }

    #[test]
    fn constructors_invert_classify() {
        for num in 1..=4 {
            for node in [1u8, 64, 127] {
                let t = tpdo_cob(num, node);
                let r = rpdo_cob(num, node);
                assert_eq!(classify(t), CobKind::Tpdo { num, node });
                assert_eq!(classify(r), CobKind::Rpdo { num, node });
            }
        }
        assert_eq!(tpdo_cob(1, 3), 0x183);
        assert_eq!(rpdo_cob(4, 3), 0x503);
        assert_eq!(classify(emcy_cob(9)), CobKind::Emcy { node: 9 });
        assert_eq!(
            classify(sdo_request_cob(9)),
            CobKind::SdoRequest { node: 9 }
        );
        assert_eq!(
            classify(sdo_response_cob(9)),
            CobKind::SdoResponse { node: 9 }
        );
        assert_eq!(classify(heartbeat_cob(9)), CobKind::Heartbeat { node: 9 });
    }
}
