//! The simulated PLC's command 5, orient spindle, through its registers only (as the
//! mailbox table in docs/modbus.md gives it): done after the turn's time at 1800°/s,
//! the stylus turned with the spindle; rejected without the function or with an angle
//! out of range; already deflected with the probe in contact; a stop halts the turn.

mod common;

use common::scenario;
use hal::modbus::mailbox::{CommandBlock, CommandCode, ResultCode, StatusBlock, COMMAND_LEN};
use hal::modbus::ModbusBusConfig;
use probebridge_sim::plc::PlcProgram;

const STYLUS: &str = "[probe]\nball_radius = 3.0\noffset = [0.003, -0.002]\n";

struct Plc {
    p: PlcProgram,
    bus: ModbusBusConfig,
    seq: u16,
}

impl Plc {
    fn new(body: &str, orientable: bool) -> Self {
        let sc = scenario("table-ac", body);
        let mut bus = ModbusBusConfig::tcp("127.0.0.1:0");
        bus.plc_cycle_us = 1000;
        bus.spindle_orientation = orientable;
        Self {
            p: PlcProgram::new(&sc, &bus),
            bus,
            seq: 0,
        }
    }

    fn status(&self) -> StatusBlock {
        let o = self.bus.word_order;
        let r = self
            .p
            .read(self.bus.status_base, hal::modbus::mailbox::STATUS_LEN)
            .unwrap();
        StatusBlock::decode(o, &r).unwrap()
    }

    /// Writes command `code` with `targets[0] = milli` (one FC16, the sequence last).
    fn command(&mut self, code: u16, milli: i32) -> u16 {
        self.seq += 1;
        let mut targets = [0; hal::axis::MAX_AXES];
        targets[0] = milli;
        let block = CommandBlock {
            command: code,
            axis_mask: 0,
            feed_milli: 0,
            targets,
            probe_edge: 0,
            latch_ack: self.status().latch_ack,
            heartbeat: self.seq,
            sequence: self.seq,
        };
        let regs: [u16; COMMAND_LEN as usize] = block.encode(self.bus.word_order);
        self.p.write(self.bus.command_base, &regs).unwrap();
        self.seq
    }

    /// PLC cycles until `seq` is done; how many, and the result.
    fn until_done(&mut self, seq: u16) -> (u32, ResultCode) {
        for n in 1..=10_000 {
            self.p.step();
            let s = self.status();
            if s.done == seq {
                return (n, ResultCode::from_u16(s.result).unwrap());
            }
        }
        panic!("command {seq} not done in 10 000 cycles");
    }
}

#[test]
fn orient_turns_the_spindle_in_the_time_of_the_turn_and_reports_ok() {
    let mut plc = Plc::new(STYLUS, true);
    let seq = plc.command(CommandCode::OrientSpindle as u16, 180_000);
    let (cycles, result) = plc.until_done(seq);
    assert_eq!(result, ResultCode::Ok);
    // 180° at 1800°/s is 100 ms: 100 cycles of 1 ms.
    assert_eq!(cycles, 100);
    assert_eq!(plc.p.spindle_deg(), 180.0);
    // Back the short way round: 270° -> 0° is 90°, 50 cycles.
    let seq = plc.command(CommandCode::OrientSpindle as u16, 270_000);
    plc.until_done(seq);
    let seq = plc.command(CommandCode::OrientSpindle as u16, 0);
    assert_eq!(plc.until_done(seq), (50, ResultCode::Ok));
    assert_eq!(plc.p.spindle_deg(), 0.0);
}

#[test]
fn without_the_function_or_with_an_angle_out_of_range_it_is_rejected_and_nothing_turns() {
    let mut plc = Plc::new(STYLUS, false);
    let seq = plc.command(CommandCode::OrientSpindle as u16, 90_000);
    assert_eq!(plc.until_done(seq), (1, ResultCode::Rejected));
    assert_eq!(plc.p.spindle_deg(), 0.0);

    let mut plc = Plc::new(STYLUS, true);
    for bad in [360_000, -1] {
        let seq = plc.command(CommandCode::OrientSpindle as u16, bad);
        assert_eq!(plc.until_done(seq), (1, ResultCode::Rejected), "{bad}");
    }
    assert_eq!(plc.p.spindle_deg(), 0.0);
}

#[test]
fn a_stop_halts_the_turn_and_the_spindle_is_not_oriented() {
    let mut plc = Plc::new(STYLUS, true);
    let seq = plc.command(CommandCode::OrientSpindle as u16, 180_000);
    for _ in 0..10 {
        plc.p.step();
    }
    assert_ne!(plc.status().done, seq, "still turning");
    let stop = plc.command(CommandCode::Stop as u16, 0);
    assert_eq!(plc.until_done(stop).1, ResultCode::Stopped);
    assert_eq!(plc.p.spindle_deg(), 0.0, "not oriented to 180°");
}

#[test]
fn with_the_probe_deflected_it_answers_already_deflected() {
    // A plane through the stylus at the PLC's home position: the probe is in contact.
    let home = {
        let plc = Plc::new(STYLUS, true);
        plc.p.actual().xyz()
    };
    let plane = format!(
        "{STYLUS}[[plane]]\npoint = [0.0, 0.0, {}]\nnormal = [0.0, 0.0, 1.0]\n",
        home[2] - 2.9
    );
    let mut plc = Plc::new(&plane, true);
    let seq = plc.command(CommandCode::OrientSpindle as u16, 180_000);
    assert_eq!(plc.until_done(seq), (1, ResultCode::AlreadyDeflected));
    assert_eq!(plc.p.spindle_deg(), 0.0);
}
