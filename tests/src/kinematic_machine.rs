//! The simulated machine without its bus: each move arrives at once and exactly, and a
//! probing move stops where the world's probe triggers. The physics is the one the
//! simulated drives step over CANopen (true kinematics with their errors, artefacts,
//! probe with pre-travel and seeded noise); only the servo motion and the bus are left
//! out, so that statistics over hundreds of seeded runs take seconds.

use hal::motion_guard::MotionGuard;
use hal::{Axis, AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use sim::{Scenario, World};

pub struct KinematicMachine {
    world: World,
    guard: MotionGuard,
    at: AxisPositions,
    mask: u8,
    contacts: u64,
}

impl KinematicMachine {
    /// At the scenario's home (X, Y, Z; rotary axes at 0), probe released.
    pub fn open(sc: &Scenario) -> Self {
        let mut at = sc.home.map_or_else(
            || sim::machine::SimMachine::home(&sc.machine),
            AxisPositions::linear,
        );
        let mut mask = 0u8;
        for a in &sc.machine.axes {
            mask |= 1 << a.name.index();
            if at.get(a.name).is_none() {
                at.set(a.name, 0.0);
            }
        }
        let mut world = World::new(sc);
        world.reset(&at);
        Self {
            world,
            guard: MotionGuard::new(&sc.machine),
            at,
            mask,
            contacts: 0,
        }
    }
}

impl Machine for KinematicMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.mask
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        Ok(self.at)
    }

    fn move_to(&mut self, target: &AxisPositions, feed: f64) -> Result<(), MachineError> {
        self.guard.check_move(target, feed)?;
        let to = self.at.merged(target);
        if let Some(f) = self.world.step(&self.at, &to) {
            return Err(MachineError::new(
                ErrorKind::ProbeCollision,
                format!("the probe touched at {:.3} of the move", f),
            ));
        }
        self.at = to;
        Ok(())
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        let d = self.guard.check_probe_request(mv)?;
        if self.world.deflected(&self.at) {
            return Err(MachineError::new(ErrorKind::AlreadyDeflected, ""));
        }
        let from = self.at;
        let mut to = from;
        for (i, axis) in Axis::LINEAR.iter().enumerate() {
            let v = from.get(*axis).unwrap_or(0.0);
            to.set(*axis, v + d[i] * mv.max_distance);
        }
        self.guard.check_target(&to, "probing move")?;
        let Some(f) = self.world.step(&from, &to) else {
            self.at = to;
            return Err(MachineError::new(ErrorKind::NotTriggered, ""));
        };
        let mut contact = from;
        for axis in Axis::LINEAR {
            let (a, b) = (from.get(axis).unwrap_or(0.0), to.get(axis).unwrap_or(0.0));
            contact.set(axis, a + f * (b - a));
        }
        // The axes stop at the contact (the world takes the next step from there).
        self.at = contact;
        self.contacts += 1;
        Ok(Contact {
            positions: contact,
            trigger_ns: 0,
            sequence: self.contacts,
            direction: d,
        })
    }

    fn set_run(&mut self, _run_id: u64) {}

    fn clock_ns(&mut self) -> u64 {
        0
    }
}
