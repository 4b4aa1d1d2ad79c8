//! A [`Machine`] straight on the simulator's physics ([`sim::World`]), without a bus:
//! a positioning move arrives at once (the world stepped along it, so a contact on
//! the way is a collision), a probing move steps the world along its path until the
//! probe signal rises and reports that point exactly, and the spindle orients. For
//! tests of a cycle's maths with a real probe (lobing, offset, length error): quick
//! for hundreds of contacts. The bus paths are the conformance suite's.

use hal::{Axis, AxisPositions, Contact, ErrorKind, Machine, MachineError, ProbeMove};
use sim::machine::SimMachine;
use sim::{Scenario, World};

/// Length of the pieces a probing move is stepped in, mm (each is solved exactly).
const PROBE_PIECE_MM: f64 = 0.25;

pub struct WorldMachine {
    world: World,
    at: AxisPositions,
    axes: u8,
    contacts: u64,
}

impl WorldMachine {
    /// At the scenario's start position.
    pub fn new(sc: &Scenario) -> Self {
        let mut at = SimMachine::start_positions(sc);
        let mut axes = 0u8;
        for a in &sc.machine.axes {
            axes |= 1 << a.name.index();
            if at.get(a.name).is_none() {
                at.set(a.name, 0.0);
            }
        }
        let mut world = World::new(sc);
        world.reset(&at);
        Self {
            world,
            at,
            axes,
            contacts: 0,
        }
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    fn target(&self, t: &AxisPositions) -> AxisPositions {
        let mut to = self.at;
        for a in Axis::ALL {
            if let Some(v) = t.get(a) {
                to.set(a, v);
            }
        }
        to
    }
}

impl Machine for WorldMachine {
    type Error = MachineError;

    fn axes(&self) -> u8 {
        self.axes
    }

    fn positions(&mut self) -> Result<AxisPositions, MachineError> {
        Ok(self.at)
    }

    fn move_to(&mut self, target: &AxisPositions, _feed: f64) -> Result<(), MachineError> {
        let to = self.target(target);
        if self.world.step(&self.at, &to).is_some() {
            return Err(MachineError::new(
                ErrorKind::ProbeCollision,
                format!("the probe touched while positioning to {:?}", to.xyz()),
            ));
        }
        self.at = to;
        Ok(())
    }

    fn probe(&mut self, mv: &ProbeMove) -> Result<Contact, MachineError> {
        if self.world.deflected(&self.at) {
            return Err(MachineError::new(
                ErrorKind::AlreadyDeflected,
                "the probe is deflected at the start of the probing move",
            ));
        }
        let d = mv.direction;
        let mut gone = 0.0;
        while gone < mv.max_distance {
            let piece = PROBE_PIECE_MM.min(mv.max_distance - gone);
            let from = self.at;
            let mut to = from;
            let xyz = from.xyz();
            for (i, axis) in Axis::LINEAR.into_iter().enumerate() {
                to.set(axis, xyz[i] + d[i] * piece);
            }
            if let Some(f) = self.world.step(&from, &to) {
                let mut at = from;
                for (i, axis) in Axis::LINEAR.into_iter().enumerate() {
                    at.set(axis, xyz[i] + d[i] * piece * f);
                }
                // Stopped at the contact; the signal stays high until the probe moves off.
                self.world.step(&to, &at);
                self.at = at;
                self.contacts += 1;
                return Ok(Contact {
                    positions: at,
                    trigger_ns: 0,
                    sequence: self.contacts,
                    direction: d,
                });
            }
            self.at = to;
            gone += piece;
        }
        Err(MachineError::new(
            ErrorKind::NotTriggered,
            format!("the probe did not trigger within {} mm", mv.max_distance),
        ))
    }

    fn set_run(&mut self, _run_id: u64) {}

    fn clock_ns(&mut self) -> u64 {
        0
    }

    fn orient_spindle(&mut self, angle_deg: f64) -> Result<bool, MachineError> {
        self.world.orient_spindle(angle_deg);
        Ok(true)
    }
}
