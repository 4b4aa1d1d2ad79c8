//! PDOs as any master maps them: the predefined connection set at power-on, what may
//! be mapped, RPDOs taking effect (at once or at the next SYNC) and TPDOs sent per
//! transmission type, inhibit time and event timer.

use super::{Communication, Objects, SimDrive, DEFAULT_CYCLE_PERIOD_US, DEFAULT_SYNC_COB_ID, PDOS};
use hal::can::CanFrame;
use hal::canopen::cob_id;
use hal::canopen::emcy::code as emcy_code;
use hal::canopen::object as obj;
use hal::canopen::pdo::{
    communication_index, default_cob_id_entry, MapEntry, PdoDirection, PdoParameters,
    COB_ID_INVALID,
};

/// A PDO of the predefined connection set, invalid until a master configures it (an
/// empty PDO has nothing to carry).
fn pdo_at_power_on(direction: PdoDirection, num: u8, node: u8) -> PdoParameters {
    let mut p = PdoParameters::new(direction, num, node).expect("PDO numbers 1..=4");
    let cob = default_cob_id_entry(direction, num, node).expect("PDO numbers 1..=4");
    let index = communication_index(direction, num).expect("PDO numbers 1..=4");
    p.write(index, 1, &(cob | COB_ID_INVALID).to_le_bytes(), |_| true)
        .expect("a valid COB-ID entry");
    p
}

impl Communication {
    pub(super) fn new(node: u8) -> Self {
        Self {
            cycle_period_us: DEFAULT_CYCLE_PERIOD_US,
            heartbeat_ms: 0,
            heartbeat_consumer: 0,
            sync_cob_id: DEFAULT_SYNC_COB_ID,
            emcy_cob_id: u32::from(cob_id::emcy_cob(node)),
            rpdo: core::array::from_fn(|i| pdo_at_power_on(PdoDirection::Rpdo, i as u8 + 1, node)),
            tpdo: core::array::from_fn(|i| pdo_at_power_on(PdoDirection::Tpdo, i as u8 + 1, node)),
        }
    }
}

impl Objects {
    /// Whether `e` can go into a PDO of `direction`: an RPDO carries only what the
    /// master may write, a TPDO any process value; the length must be the object's.
    pub(super) fn mappable(direction: PdoDirection, e: MapEntry) -> bool {
        let writable = matches!(
            e.index,
            obj::CONTROLWORD
                | obj::TARGET_POSITION
                | obj::MODES_OF_OPERATION
                | obj::TOUCH_PROBE_FUNCTION
        );
        Self::object_bits(e.index, e.sub) == Some(e.bits)
            && (direction == PdoDirection::Tpdo || writable)
    }

    pub(super) fn pdo_mut(&mut self, index: u16) -> Option<&mut PdoParameters> {
        let c = &mut self.comm;
        c.rpdo
            .iter_mut()
            .chain(c.tpdo.iter_mut())
            .find(|p| p.handles(index))
    }
}

impl SimDrive {
    /// An RPDO arrived: event-driven data (254, 255) takes effect now, synchronous
    /// data (0..=240) at the next SYNC.
    pub(super) fn on_rpdo(&mut self, i: usize, data: &[u8]) {
        let p = &self.od.comm.rpdo[i];
        let synchronous = p.transmission_type() <= 240;
        let map = p.mapping().clone();
        let Ok(values) = map.unpack(data) else {
            // A PDO of the wrong length: CiA 301 EMCY 0x8210, the data is not used.
            if !self.od.pdo_length_error {
                self.od.pdo_length_error = true;
                self.od.push_emcy(emcy_code::PDO_LENGTH_ERROR);
            }
            return;
        };
        if self.od.pdo_length_error {
            self.od.pdo_length_error = false;
            self.od.push_emcy(emcy_code::NO_ERROR);
        }
        if synchronous {
            let mut d = [0u8; 8];
            let n = data.len().min(8);
            d[..n].copy_from_slice(&data[..n]);
            self.rpdo_at_sync[i] = Some((d, n));
            return;
        }
        for (e, v) in map.entries().iter().zip(values) {
            let _ = self.od.write_mapped(e.index, e.sub, v);
        }
    }

    /// A SYNC arrived (before the step it starts): synchronous RPDO data received
    /// since the last one takes effect.
    pub fn on_sync(&mut self) {
        if self.silent {
            return;
        }
        for i in 0..PDOS {
            let Some((d, n)) = self.rpdo_at_sync[i].take() else {
                continue;
            };
            let map = self.od.comm.rpdo[i].mapping().clone();
            if let Ok(values) = map.unpack(&d[..n]) {
                for (e, v) in map.entries().iter().zip(values) {
                    let _ = self.od.write_mapped(e.index, e.sub, v);
                }
            }
        }
    }

    /// `at_sync`: the synchronous TPDOs of this SYNC; else the event-driven ones that
    /// are due (data changed and the inhibit time over, or the event timer expired).
    /// Returns whether an event-driven TPDO changed but waits out its inhibit time.
    pub(super) fn send_tpdos(&mut self, at_sync: bool, tx: &mut dyn FnMut(&CanFrame)) -> bool {
        let mut held = false;
        for i in 0..PDOS {
            let c = &self.od.comm.tpdo[i];
            if !c.is_enabled() {
                self.tpdo_syncs[i] = 0;
                continue;
            }
            let tt = c.transmission_type();
            let sync = tt <= 240;
            if sync != at_sync || (252..=253).contains(&tt) {
                continue;
            }
            let since_us = self.now_us.saturating_sub(self.sent_at_us[i]);
            let map = c.mapping();
            let mut values = [0u64; 8];
            for (v, e) in values.iter_mut().zip(map.entries()) {
                *v = self.od.mapped_value(e.index, e.sub).unwrap_or(0);
            }
            let (data, len) = map.pack(&values[..map.entries().len()]);
            let changed = self.last_sent[i] != Some((data, len));
            let send = match tt {
                0 => changed,
                1..=240 => {
                    self.tpdo_syncs[i] += 1;
                    let due = self.tpdo_syncs[i] >= tt;
                    if due {
                        self.tpdo_syncs[i] = 0;
                    }
                    due
                }
                _ => {
                    let inhibit_us = u64::from(c.inhibit_time_100us()) * 100;
                    let timer_us = u64::from(c.event_timer_ms()) * 1000;
                    held |= changed && since_us < inhibit_us;
                    (changed && since_us >= inhibit_us) || (timer_us > 0 && since_us >= timer_us)
                }
            };
            if !send {
                continue;
            }
            self.last_sent[i] = Some((data, len));
            self.sent_at_us[i] = self.now_us;
            if let Some(f) = CanFrame::new(c.cob_id(), &data[..len]) {
                tx(&f);
            }
        }
        held
    }
}
