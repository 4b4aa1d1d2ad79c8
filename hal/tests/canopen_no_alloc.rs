//! The per-cycle codec paths allocate nothing: a counting global allocator watches
//! PDO packing, SYNC, heartbeat supervision, EMCY/NMT decoding, the CiA 402 state
//! machine and a whole segmented SDO exchange.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use probebridge_hal::can::CanFrame;
use probebridge_hal::canopen::heartbeat::{self, HeartbeatConsumer};
use probebridge_hal::canopen::pdo::{MapEntry, PdoMapping};
use probebridge_hal::canopen::sdo::{
    ObjectDictionary, SdoAbortCode, SdoClient, SdoClientEvent, SdoServer,
};
use probebridge_hal::canopen::sync::SyncProducer;
use probebridge_hal::canopen::{nmt, Emcy, NmtCommand, NmtState};
use probebridge_hal::cia402::State;

struct Counting;

thread_local! {
    // Per thread: the test harness allocates on its own threads meanwhile.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> usize {
    ALLOCATIONS.with(|c| c.get())
}

struct ArrayOd {
    value: [u8; 64],
    len: usize,
}

impl ObjectDictionary for ArrayOd {
    fn read(&mut self, _: u16, _: u8, buf: &mut [u8]) -> Result<usize, SdoAbortCode> {
        buf[..self.len].copy_from_slice(&self.value[..self.len]);
        Ok(self.len)
    }
    fn write(&mut self, _: u16, _: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
        self.value[..data.len()].copy_from_slice(data);
        self.len = data.len();
        Ok(())
    }
}

#[test]
fn codec_paths_do_not_allocate() {
    let mapping = PdoMapping::from_entries(&[
        MapEntry::new(0x6041, 0, 16),
        MapEntry::new(0x6064, 0, 32),
        MapEntry::new(0x60B9, 0, 16),
    ])
    .unwrap();
    let mut hb = HeartbeatConsumer::new();
    hb.watch(3, 100).unwrap();
    let mut sync = SyncProducer::new(0);
    let mut client = SdoClient::new(3);
    let mut server = SdoServer::new(3);
    let mut od = ArrayOd {
        value: [0; 64],
        len: 0,
    };
    let data = [0x5Au8; 40];

    // The counter does see allocations on this thread.
    let probe = allocations();
    drop(std::hint::black_box(Box::new(1u8)));
    assert_eq!(allocations(), probe + 1);

    let before = allocations();
    let mut state = State::SwitchOnDisabled;
    let mut cw = 0u16;
    for t in 0..50u64 {
        let _ = sync.next_frame();
        let (d, n) = mapping.pack(&[0x0237, t, 0x0003]);
        let v = mapping.unpack(&d[..n]).unwrap();
        assert_eq!(v[1], t);
        hb.on_frame(&heartbeat::encode(3, NmtState::Operational), t);
        let _ = hb.check(t);
        let f = CanFrame::new(0x083, &[0x11, 0x86, 0x21, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(Emcy::decode(&f).unwrap().error_code, 0x8611);
        assert!(nmt::decode(&nmt::encode(NmtCommand::Start, 3)).is_ok());
        let next = state.next_controlword(cw).unwrap_or(cw);
        state = state.on_controlword(next, cw, false);
        cw = next;
    }
    for len in [2usize, 40] {
        let mut req = client.download(0x2000, 1, &data[..len]).unwrap();
        while let Some(resp) = server.on_frame(&req, &mut od) {
            match client.on_frame(&resp) {
                SdoClientEvent::Transmit(next) => req = next,
                _ => break,
            }
        }
        let mut req = client.upload(0x2000, 1).unwrap();
        while let Some(resp) = server.on_frame(&req, &mut od) {
            match client.on_frame(&resp) {
                SdoClientEvent::Transmit(next) => req = next,
                _ => break,
            }
        }
    }
    let after = allocations();
    assert_eq!(state, State::OperationEnabled);
    assert_eq!(&od.value[..40], &data[..]);
    assert_eq!(after - before, 0, "allocations on the codec paths");
}
