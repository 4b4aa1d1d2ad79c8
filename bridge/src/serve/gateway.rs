//! What the faces and the machine thread share, behind one mutex: the measurement
//! service every face reaches the machine through, and the PLC face's registers drawn
//! from it. Nothing does I/O under the lock: a start is prepared on the machine thread
//! ([`super::prepare`]), and the OPC UA face waits for its answer after releasing it.

use super::plc_registers::{PlcRegisters, WriteRefusal};
use super::service::Service;
use std::net::IpAddr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

pub struct Gateway {
    /// The rules, the runs and the results every face shows.
    pub service: Service,
    plc: PlcRegisters,
}

pub type Shared = Arc<Mutex<Gateway>>;

pub fn lock(shared: &Shared) -> MutexGuard<'_, Gateway> {
    shared.lock().unwrap_or_else(|e| e.into_inner())
}

impl Gateway {
    pub fn new(service: Service, plc: PlcRegisters) -> Self {
        let mut g = Self { service, plc };
        g.plc.sync(&g.service, Instant::now());
        g
    }

    /// The PLC face reads holding registers.
    pub fn plc_read(
        &mut self,
        addr: u16,
        count: u16,
    ) -> Result<Vec<u16>, super::register_map::MapException> {
        self.plc.read(&self.service, addr, count)
    }

    /// The PLC face's connection `conn` from `ip` writes holding registers.
    pub fn plc_write(
        &mut self,
        conn: u64,
        ip: IpAddr,
        addr: u16,
        values: &[u16],
    ) -> Result<(), WriteRefusal> {
        self.plc.write(&mut self.service, conn, ip, addr, values)
    }

    /// The PLC face's connection `conn` sent a request (any).
    pub fn plc_heard(&mut self, conn: u64) {
        self.plc.heard(conn);
    }

    /// The address of the PLC face's connection that owns the request block.
    pub fn plc_owner_ip(&self) -> Option<IpAddr> {
        self.plc.owner_ip()
    }

    pub fn plc_disconnected(&mut self, conn: u64) {
        self.plc.disconnected(conn);
    }

    /// The periodic tick: the service's (gateway heartbeat, "not yet recorded"), and
    /// the PLC's heartbeat supervision of a run the PLC started.
    pub fn tick(&mut self, now: Instant) {
        self.service.tick();
        if self.plc.heartbeat_lost(&self.service, now) && self.service.abort_reason().is_none() {
            tracing::warn!("PLC heartbeat stale while busy: aborting the motion");
            self.service
                .request_abort(super::outcome::AbortReason::PlcHeartbeat);
        }
    }
}
