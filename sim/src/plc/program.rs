//! The simulated PLC's program: the mailbox (see `hal::modbus::mailbox`) on top of
//! the simulated physics ([`crate::world::World`]). Once per PLC cycle it takes a new
//! command, moves the axes along the same interpolation the CANopen master uses
//! (`hal::motion::Profile`, setpoints rounded to the axis increments, the encoder
//! following one cycle later), latches the probe edge at the exact fraction of the
//! cycle as a drive's touch probe does, stops on the latch, and publishes status and
//! latch ring. No I/O: the server reads and writes its registers.

use super::knobs::Knobs;
use crate::machine::{EMCY_PROBE_COLLISION, PROBE_OVERTRAVEL_MM};
use crate::scenario::Scenario;
use crate::world::World;
use hal::axis::{AxisPositions, MAX_AXES};
use hal::modbus::config::{CaptureKind, ModbusBusConfig};
use hal::modbus::mailbox::{
    bits, CommandBlock, CommandCode, LatchSlot, Layout, ResultCode, Scale, StatusBlock,
    COMMAND_LEN, SLOT_LEN,
};
use hal::motion::{AxisLimits, Profile};
use hal::Axis;
use tokio_modbus::ExceptionCode;

#[derive(Clone, Copy, Debug)]
enum Activity {
    Idle,
    Moving {
        profile: Profile,
        t: f64,
    },
    Probing {
        profile: Profile,
        t: f64,
    },
    Stopping {
        profile: Profile,
        t: f64,
        then: ResultCode,
    },
    /// Orient spindle: turning to `to_deg`, done after `cycles_left` more cycles.
    Orienting {
        to_deg: f64,
        cycles_left: u32,
    },
}

/// How fast the simulated spindle turns to an oriented stop, deg/s (180° in 0.1 s).
const SPINDLE_ORIENT_DEG_PER_S: f64 = 1800.0;

/// The PLC: registers, motion, probe.
pub struct PlcProgram {
    layout: Layout,
    scale: Scale,
    capture: CaptureKind,
    world: World,
    /// Encoder increments per unit of each axis (the drives' resolution).
    increments: [f64; MAX_AXES],
    min: [f64; MAX_AXES],
    max: [f64; MAX_AXES],
    mask: u8,
    limits: AxisLimits,
    cycle_s: f64,
    cycle_us: u64,
    time_us: u64,
    setpoint: [f64; MAX_AXES],
    actual_inc: [i64; MAX_AXES],
    activity: Activity,
    command: [u16; COMMAND_LEN as usize],
    status: StatusBlock,
    ring: Vec<u16>,
    command_sequence: u16,
    armed: bool,
    fault: Option<u16>,
    /// The program has command 5, orient spindle (`[bus] spindle_orientation`).
    orientable_spindle: bool,
    latch_log: Option<std::sync::Arc<crate::machine::LatchLog>>,
    motion_watch: Option<crate::machine::MotionWatch>,
    pub knobs: Knobs,
}

impl PlcProgram {
    /// The PLC of `scenario`'s machine with the axes at the simulator's home position,
    /// its mailbox where `bus` says.
    pub fn new(scenario: &Scenario, bus: &ModbusBusConfig) -> Self {
        let cfg = &scenario.machine;
        let home = crate::machine::SimMachine::start_positions(scenario);
        let mut increments = [1.0; MAX_AXES];
        let mut min = [0.0; MAX_AXES];
        let mut max = [0.0; MAX_AXES];
        let limits = AxisLimits::of(cfg);
        let mut setpoint = [0.0; MAX_AXES];
        let mut actual_inc = [0; MAX_AXES];
        for a in &cfg.axes {
            let i = a.name.index();
            increments[i] = a.increments_per_unit;
            min[i] = a.min;
            max[i] = a.max;
            setpoint[i] = home.get(a.name).unwrap_or(0.0);
            actual_inc[i] = (setpoint[i] * a.increments_per_unit).round() as i64;
        }
        let layout = bus.layout();
        let mut p = Self {
            layout,
            scale: Scale {
                per_mm: bus.counts_per_mm,
                per_deg: bus.counts_per_deg,
            },
            capture: bus.capture,
            world: World::new(scenario),
            increments,
            min,
            max,
            mask: cfg.axis_mask(),
            limits,
            cycle_s: bus.plc_cycle_us as f64 * 1e-6,
            cycle_us: bus.plc_cycle_us as u64,
            time_us: 0,
            setpoint,
            actual_inc,
            activity: Activity::Idle,
            command: [0; COMMAND_LEN as usize],
            status: StatusBlock::default(),
            ring: vec![0; layout.ring_len() as usize],
            command_sequence: 0,
            armed: false,
            fault: None,
            orientable_spindle: bus.spindle_orientation,
            latch_log: None,
            motion_watch: None,
            knobs: Knobs::default(),
        };
        let here = p.actual();
        p.world.reset(&here);
        p.publish();
        p
    }

    /// Records the wall-clock instant of every latch into `log` (benchmarks).
    pub fn set_latch_log(&mut self, log: std::sync::Arc<crate::machine::LatchLog>) {
        self.latch_log = Some(log);
    }

    /// Calls `watch` with the actual positions after every PLC cycle that moves.
    pub fn set_motion_watch(&mut self, watch: crate::machine::MotionWatch) {
        self.motion_watch = Some(watch);
    }

    pub fn layout(&self) -> Layout {
        self.layout
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    /// The PLC cycle, ns.
    pub fn cycle_ns(&self) -> u64 {
        self.cycle_us * 1000
    }

    /// PLC time, µs.
    pub fn time_us(&self) -> u64 {
        self.time_us
    }

    pub fn is_busy(&self) -> bool {
        !matches!(self.activity, Activity::Idle)
            || self.command[hal::modbus::mailbox::cmd::SEQUENCE] != self.command_sequence
    }

    /// Where the spindle stands (its last oriented stop), deg.
    pub fn spindle_deg(&self) -> f64 {
        self.world.spindle_deg()
    }

    /// Encoder positions.
    pub fn actual(&self) -> AxisPositions {
        let mut p = [0.0; MAX_AXES];
        for (i, v) in p.iter_mut().enumerate() {
            *v = self.actual_inc[i] as f64 / self.increments[i];
        }
        AxisPositions::from_raw(p, self.mask)
    }

    /// FC3: any registers inside one block.
    pub fn read(&self, addr: u16, count: u16) -> Result<Vec<u16>, ExceptionCode> {
        let l = &self.layout;
        let status = self.status.encode(l.word_order);
        let blocks: [(u16, &[u16]); 3] = [
            (l.command_base, &self.command),
            (l.status_base, &status),
            (l.ring_base, &self.ring),
        ];
        for (base, regs) in blocks {
            let (start, end) = (addr as usize, addr as usize + count as usize);
            if start >= base as usize && end <= base as usize + regs.len() {
                return Ok(regs[start - base as usize..end - base as usize].to_vec());
            }
        }
        Err(ExceptionCode::IllegalDataAddress)
    }

    /// FC6/FC16: only the command block is writable.
    pub fn write(&mut self, addr: u16, values: &[u16]) -> Result<(), ExceptionCode> {
        let base = self.layout.command_base as usize;
        let start = addr as usize;
        if start < base || start + values.len() > base + COMMAND_LEN as usize {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        self.command[start - base..start - base + values.len()].copy_from_slice(values);
        // The acknowledge is taken at once (a PLC copies it in its next cycle; on the
        // virtual clock, time stands still while nothing moves).
        let ack = hal::modbus::mailbox::cmd::LATCH_ACK;
        self.status.latch_ack = self.command[ack];
        Ok(())
    }

    /// One PLC cycle.
    pub fn step(&mut self) {
        self.time_us += self.cycle_us;
        let block = CommandBlock::decode(self.layout.word_order, &self.command);
        self.status.latch_ack = block.latch_ack;
        if block.sequence != self.command_sequence {
            self.command_sequence = block.sequence;
            self.status.acked = block.sequence;
            self.start(&block);
        }
        let moving = !matches!(self.activity, Activity::Idle);
        self.advance();
        if let (true, Some(watch)) = (moving, &self.motion_watch) {
            watch(&self.actual());
        }
        self.publish();
    }

    fn finish(&mut self, result: ResultCode) {
        self.status.result = result as u16;
        self.status.done = self.command_sequence;
        self.armed = false;
        self.activity = Activity::Idle;
    }

    fn start(&mut self, block: &CommandBlock) {
        if !matches!(self.activity, Activity::Idle) {
            // A new command while moving: brake first, then refuse nothing silently.
            self.brake(ResultCode::Stopped);
        }
        let Some(code) = CommandCode::from_u16(block.command) else {
            return self.finish(ResultCode::Rejected);
        };
        match code {
            CommandCode::None => self.finish(ResultCode::Ok),
            CommandCode::Stop => {
                if matches!(self.activity, Activity::Idle) {
                    self.finish(ResultCode::Stopped);
                }
            }
            CommandCode::AcknowledgeFault => {
                self.fault = None;
                self.finish(ResultCode::Ok);
            }
            CommandCode::Move | CommandCode::Probe => self.start_motion(code, block),
            CommandCode::OrientSpindle => self.start_orient(block),
        }
    }

    /// Command 5: refused without an orientable spindle, with a fault, with an angle
    /// out of 0..360°, and with the stylus deflected (turning would drag it).
    fn start_orient(&mut self, block: &CommandBlock) {
        if !self.orientable_spindle || self.knobs.no_orient_spindle {
            return self.finish(ResultCode::Rejected);
        }
        if self.fault.is_some() {
            return self.finish(ResultCode::Fault);
        }
        let milli = block.targets[0];
        if !(0..360_000).contains(&milli) {
            return self.finish(ResultCode::Rejected);
        }
        if self.world.deflected(&self.actual()) {
            return self.finish(ResultCode::AlreadyDeflected);
        }
        let to_deg = milli as f64 / 1000.0;
        let turn = (to_deg - self.world.spindle_deg()).rem_euclid(360.0);
        let turn = turn.min(360.0 - turn);
        let cycles = (turn / (SPINDLE_ORIENT_DEG_PER_S * self.cycle_s))
            .ceil()
            .max(1.0);
        self.activity = Activity::Orienting {
            to_deg,
            cycles_left: cycles as u32,
        };
    }

    fn start_motion(&mut self, code: CommandCode, block: &CommandBlock) {
        if self.fault.is_some() {
            return self.finish(ResultCode::Fault);
        }
        let feed = block.feed_milli as f64 / 1000.0;
        if feed <= 0.0 {
            return self.finish(ResultCode::Rejected);
        }
        let mut to = self.setpoint;
        for a in Axis::ALL {
            let i = a.index();
            if block.axis_mask & (1 << i) != 0 && self.mask & (1 << i) != 0 {
                to[i] = self.scale.from_counts(a, block.targets[i]);
                if to[i] < self.min[i] || to[i] > self.max[i] {
                    return self.finish(ResultCode::Limit);
                }
            }
        }
        let profile = Profile::line(self.setpoint, to, feed, &self.limits);
        if code == CommandCode::Probe {
            if block.probe_edge != 1 {
                return self.finish(ResultCode::Rejected);
            }
            if self.world.deflected(&self.actual()) {
                return self.finish(ResultCode::AlreadyDeflected);
            }
            // Re-armed only once the bridge has acknowledged every latch.
            self.armed = self.status.latch_ack == self.status.latch_count;
            self.activity = Activity::Probing { profile, t: 0.0 };
        } else {
            self.activity = Activity::Moving { profile, t: 0.0 };
        }
    }

    fn brake(&mut self, then: ResultCode) {
        if let Activity::Orienting { .. } = self.activity {
            // The spindle halts where it is: not oriented (the world keeps the angle
            // it was at; the bridge, told "stopped", assumes none).
            self.activity = Activity::Idle;
            return;
        }
        if let Activity::Moving { profile, t } | Activity::Probing { profile, t } = self.activity {
            self.armed = false;
            self.activity = Activity::Stopping {
                profile: profile.stop_at(t, &self.limits),
                t: 0.0,
                then,
            };
        }
    }

    /// Moves the encoders to the setpoint over one cycle; the probe edge, if any.
    fn follow(&mut self) -> (AxisPositions, AxisPositions, [i64; MAX_AXES], Option<f64>) {
        let from_inc = self.actual_inc;
        let from = self.actual();
        for i in 0..MAX_AXES {
            if self.mask & (1 << i) != 0 {
                self.actual_inc[i] = (self.setpoint[i] * self.increments[i]).round() as i64;
            }
        }
        let to = self.actual();
        let edge = self.world.step(&from, &to);
        (from, to, from_inc, edge)
    }

    fn advance(&mut self) {
        let dt = self.cycle_s;
        match self.activity {
            Activity::Idle => {}
            Activity::Moving { profile, t } | Activity::Probing { profile, t } => {
                let probing = matches!(self.activity, Activity::Probing { .. });
                if probing && profile.is_done(t) {
                    return self.finish(ResultCode::NotTriggered);
                }
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.activity = if probing {
                    Activity::Probing { profile, t }
                } else {
                    Activity::Moving { profile, t }
                };
                let (_, to, from_inc, edge) = self.follow();
                if self.world.penetration(&to) > PROBE_OVERTRAVEL_MM {
                    self.fault = Some(EMCY_PROBE_COLLISION);
                    return self.brake(ResultCode::Fault);
                }
                match edge {
                    Some(frac) if probing && self.armed => {
                        self.latch(from_inc, frac);
                        self.brake(ResultCode::Contact);
                    }
                    Some(_) if !probing => self.brake(ResultCode::Collision),
                    _ if !probing && profile.is_done(t) => self.finish(ResultCode::Ok),
                    _ => {}
                }
            }
            Activity::Stopping { profile, t, then } => {
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.follow();
                if profile.is_done(t) {
                    self.finish(then);
                } else {
                    self.activity = Activity::Stopping { profile, t, then };
                }
            }
            Activity::Orienting {
                to_deg,
                cycles_left,
            } => {
                if cycles_left <= 1 {
                    self.world.orient_spindle(to_deg);
                    self.finish(ResultCode::Ok);
                } else {
                    self.activity = Activity::Orienting {
                        to_deg,
                        cycles_left: cycles_left - 1,
                    };
                }
            }
        }
    }

    /// Stores contact(s) in the ring: the position at the edge (hardware latch), or
    /// at the end of the cycle that saw the input (PLC cycle / poll capture).
    fn latch(&mut self, from_inc: [i64; MAX_AXES], frac: f64) {
        let capture = self.knobs.capture.unwrap_or(self.capture);
        let mut counts = [0i32; MAX_AXES];
        let mut at_us = self.time_us;
        for a in Axis::ALL {
            let i = a.index();
            if self.mask & (1 << i) == 0 {
                continue;
            }
            let inc = match capture {
                CaptureKind::HwLatch => {
                    let from = from_inc[i] as f64;
                    (from + frac * (self.actual_inc[i] as f64 - from)).round()
                }
                CaptureKind::PlcCycle | CaptureKind::Poll => self.actual_inc[i] as f64,
            };
            let v = inc / self.increments[i];
            counts[i] = self.scale.to_counts(a, v).unwrap_or(0);
        }
        if capture == CaptureKind::HwLatch {
            at_us = self.time_us - self.cycle_us + (frac * self.cycle_us as f64) as u64;
        }
        if let Some(log) = &self.latch_log {
            log.record(hal::clock::monotonic_ns());
        }
        self.store(counts, at_us);
        if std::mem::take(&mut self.knobs.bounce) {
            self.store(counts, at_us + 50);
        }
        for k in 0..std::mem::take(&mut self.knobs.extra_latches) {
            self.store(counts, at_us + 100 + k as u64);
        }
    }

    fn store(&mut self, positions: [i32; MAX_AXES], at_us: u64) {
        let n = self.status.latch_count.wrapping_add(1);
        let slot = LatchSlot {
            sequence_head: n,
            command_sequence: self.command_sequence,
            axis_mask: self.mask as u16,
            positions,
            latch_time_us: at_us as u32,
            sequence_tail: n,
        };
        let at = (n % self.layout.ring_slots) as usize * SLOT_LEN as usize;
        self.ring[at..at + SLOT_LEN as usize].copy_from_slice(&slot.encode(self.layout.word_order));
        self.status.latch_count = n;
    }

    fn publish(&mut self) {
        let s = &mut self.status;
        s.sequence = s.sequence.wrapping_add(1);
        let idle = matches!(self.activity, Activity::Idle);
        let mut b = 0;
        if self.fault.is_none() {
            b |= bits::READY;
        } else {
            b |= bits::FAULT;
        }
        if !idle {
            b |= bits::BUSY;
        } else {
            b |= bits::IN_POSITION;
        }
        let here = {
            let mut p = [0.0; MAX_AXES];
            for (i, v) in p.iter_mut().enumerate() {
                *v = self.actual_inc[i] as f64 / self.increments[i];
            }
            AxisPositions::from_raw(p, self.mask)
        };
        if self.world.deflected(&here) {
            b |= bits::DEFLECTED;
        }
        if self.armed {
            b |= bits::ARMED;
        }
        s.bits = b;
        s.fault_code = self.fault.unwrap_or(0);
        for a in Axis::ALL {
            let i = a.index();
            s.actual[i] = here
                .get(a)
                .and_then(|v| self.scale.to_counts(a, v))
                .unwrap_or(0);
        }
        s.plc_time_us = self.time_us as u32;
    }
}
