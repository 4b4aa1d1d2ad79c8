//! A classic CAN 2.0A data frame (11-bit identifier, up to 8 bytes): all CANopen uses.

use embedded_can::{Frame, Id, StandardId};

#[derive(Clone, Copy, PartialEq, Eq)]
pub struct CanFrame {
    id: u16,
    len: u8,
    rtr: bool,
    data: [u8; 8],
}

impl CanFrame {
    /// A data frame; `None` when the identifier exceeds 11 bits or `data` 8 bytes.
    pub fn new(cob_id: u16, data: &[u8]) -> Option<Self> {
        if cob_id > 0x7FF || data.len() > 8 {
            return None;
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Some(Self {
            id: cob_id,
            len: data.len() as u8,
            rtr: false,
            data: buf,
        })
    }

    /// A remote frame requesting `dlc` bytes.
    pub fn remote(cob_id: u16, dlc: u8) -> Option<Self> {
        if cob_id > 0x7FF || dlc > 8 {
            return None;
        }
        Some(Self {
            id: cob_id,
            len: dlc,
            rtr: true,
            data: [0; 8],
        })
    }

    /// The 11-bit identifier (CANopen COB-ID).
    pub const fn cob_id(&self) -> u16 {
        self.id
    }

    pub fn data(&self) -> &[u8] {
        if self.rtr {
            &[]
        } else {
            &self.data[..self.len as usize]
        }
    }

    pub const fn is_rtr(&self) -> bool {
        self.rtr
    }

    /// Bits on the wire, worst case with bit stuffing (CAN 2.0A: 47 fixed bits,
    /// 8 per data byte, one stuff bit per 4 of the 34 + 8n stuffable bits).
    pub const fn wire_bits_worst_case(data_len: usize) -> u32 {
        let n = data_len as u32;
        47 + 8 * n + (34 + 8 * n - 1) / 4
    }
}

impl core::fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // candump's notation: 181#0102...
        write!(f, "{:03X}#", self.id)?;
        if self.rtr {
            return write!(f, "R{}", self.len);
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

impl Frame for CanFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        match id.into() {
            Id::Standard(s) => CanFrame::new(s.as_raw(), data),
            Id::Extended(_) => None,
        }
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        match id.into() {
            Id::Standard(s) if dlc <= 8 => CanFrame::remote(s.as_raw(), dlc as u8),
            _ => None,
        }
    }

    fn is_extended(&self) -> bool {
        false
    }

    fn is_remote_frame(&self) -> bool {
        self.rtr
    }

    fn id(&self) -> Id {
        // Constructors keep id within 11 bits.
        Id::Standard(StandardId::new(self.id).unwrap_or(StandardId::ZERO))
    }

    fn dlc(&self) -> usize {
        self.len as usize
    }

    fn data(&self) -> &[u8] {
        CanFrame::data(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_out_of_range() {
        assert!(CanFrame::new(0x800, &[]).is_none());
        assert!(CanFrame::new(0x7FF, &[0; 9]).is_none());
        let f = CanFrame::new(0x181, &[1, 2, 3]).unwrap();
        assert_eq!(format!("{f:?}"), "181#010203");
        assert_eq!(Frame::dlc(&f), 3);
    }

    #[test]
    fn wire_bits() {
        assert_eq!(CanFrame::wire_bits_worst_case(8), 135);
        assert_eq!(CanFrame::wire_bits_worst_case(0), 55);
    }
}
