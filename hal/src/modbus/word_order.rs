//! Byte and word order of a 32-bit value carried in two 16-bit Modbus registers.
//!
//! Modbus itself only fixes big-endian bytes inside one register; how a PLC splits a
//! 32-bit field over two registers is its own choice. Named by where the bytes of the
//! big-endian value `A B C D` (A most significant) end up in register order:
//! `ABCD` (high word first, Modbus "big endian", Siemens), `CDAB` (low word first,
//! many CODESYS/Beckhoff maps), `BADC` and `DCBA` (bytes swapped in each word).

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum WordOrder {
    #[default]
    ABCD,
    CDAB,
    BADC,
    DCBA,
}

impl WordOrder {
    pub const ALL: [WordOrder; 4] = [
        WordOrder::ABCD,
        WordOrder::CDAB,
        WordOrder::BADC,
        WordOrder::DCBA,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            WordOrder::ABCD => "ABCD",
            WordOrder::CDAB => "CDAB",
            WordOrder::BADC => "BADC",
            WordOrder::DCBA => "DCBA",
        }
    }

    /// The two registers (in address order) carrying `v`.
    pub const fn encode_u32(self, v: u32) -> [u16; 2] {
        let hi = (v >> 16) as u16;
        let lo = v as u16;
        match self {
            WordOrder::ABCD => [hi, lo],
            WordOrder::CDAB => [lo, hi],
            WordOrder::BADC => [hi.swap_bytes(), lo.swap_bytes()],
            WordOrder::DCBA => [lo.swap_bytes(), hi.swap_bytes()],
        }
    }

    /// The value carried by two registers in address order.
    pub const fn decode_u32(self, r: [u16; 2]) -> u32 {
        let (hi, lo) = match self {
            WordOrder::ABCD => (r[0], r[1]),
            WordOrder::CDAB => (r[1], r[0]),
            WordOrder::BADC => (r[0].swap_bytes(), r[1].swap_bytes()),
            WordOrder::DCBA => (r[1].swap_bytes(), r[0].swap_bytes()),
        };
        (hi as u32) << 16 | lo as u32
    }

    pub const fn encode_i32(self, v: i32) -> [u16; 2] {
        self.encode_u32(v as u32)
    }

    pub const fn decode_i32(self, r: [u16; 2]) -> i32 {
        self.decode_u32(r) as i32
    }
}

crate::modbus::named_values::named_values!(WordOrder, "word_order", {
    "ABCD" => WordOrder::ABCD,
    "CDAB" => WordOrder::CDAB,
    "BADC" => WordOrder::BADC,
    "DCBA" => WordOrder::DCBA,
});

impl core::fmt::Display for WordOrder {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_registers_of_0x11223344() {
        let v = 0x1122_3344;
        assert_eq!(WordOrder::ABCD.encode_u32(v), [0x1122, 0x3344]);
        assert_eq!(WordOrder::CDAB.encode_u32(v), [0x3344, 0x1122]);
        assert_eq!(WordOrder::BADC.encode_u32(v), [0x2211, 0x4433]);
        assert_eq!(WordOrder::DCBA.encode_u32(v), [0x4433, 0x2211]);
    }

    #[test]
    fn negative_values_round_trip_in_every_order() {
        for o in WordOrder::ALL {
            for v in [-1, i32::MIN, i32::MAX, -123_456_789, 0, 1] {
                assert_eq!(o.decode_i32(o.encode_i32(v)), v, "{o}");
            }
        }
        // -2 in ABCD: 0xFFFF 0xFFFE.
        assert_eq!(WordOrder::ABCD.encode_i32(-2), [0xFFFF, 0xFFFE]);
    }
}
