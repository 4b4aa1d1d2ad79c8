//! Interpolation: the setpoint of each SYNC for moves and probing moves, the stop
//! (braking along the path) and settling in position.

use super::probing::ProbeRequest;
use super::{Activity, RtLoop};
use crate::cia402::statusword::Statusword;
use crate::contact_sample::SampleSink;
use crate::machine::ErrorKind;
use crate::master::command::{Detail, Reply, RtError};
use crate::motion::Profile;

impl<S: SampleSink> RtLoop<S> {
    /// Stop: brake along the path of `profile` from its state at `t`, then answer
    /// `then`.
    pub(super) fn begin_stop(&mut self, profile: Profile, t: f64, then: Reply) {
        self.activity = Activity::Stopping {
            profile: profile.stop_at(t, &self.limits),
            t: 0.0,
            then,
        };
    }

    /// Brakes a positioning move and fails it with `err`, without marking the machine
    /// faulted (nothing is broken: the operator retracts and goes on).
    pub(super) fn abort_motion(&mut self, err: RtError) {
        if let Activity::Moving { profile, t } = self.activity {
            self.begin_stop(profile, t, Reply::Error(err));
        }
    }

    /// The axis furthest from its setpoint beyond the window, if any. A drive that is
    /// faulted, silent or the source of the fault cannot follow and is not waited for.
    pub(super) fn settled(&self) -> Option<(u8, f64)> {
        let culprit = self.fault.and_then(|f| f.node);
        let mut worst: Option<(u8, f64)> = None;
        for d in &self.drives {
            if d.silent || d.statusword & Statusword::FAULT != 0 || Some(d.node) == culprit {
                continue;
            }
            let e = (d.actual() - self.setpoint[d.axis.index()]).abs();
            if e > self.cfg.in_position_window && worst.is_none_or(|w| e > w.1) {
                worst = Some((d.axis.index() as u8, e));
            }
        }
        worst
    }

    /// Interpolation: advances the current activity by one period (the setpoint of
    /// this SYNC, or the next step of enabling, arming or settling).
    pub fn interpolate(&mut self) {
        let dt = self.cfg.period_ns as f64 * 1e-9;
        // Waits are timed on the supervised clock (see `RtLoop::supervised_ns`).
        let now = self.supervised_ns;
        match self.activity {
            Activity::Enabling { since_ns } => self.enable(now, since_ns),
            Activity::Idle | Activity::Shutdown => {}
            Activity::Moving { profile, t } => {
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.activity = if profile.is_done(t) {
                    Activity::Settling {
                        since_ns: now,
                        then: Reply::Done {
                            positions: profile.end(),
                        },
                    }
                } else {
                    Activity::Moving { profile, t }
                };
            }
            Activity::Arming {
                stage,
                since_ns,
                request,
            } => self.arm(stage, since_ns, request, now),
            Activity::Probing {
                profile,
                t,
                request,
            } => self.probe(profile, t, request),
            Activity::Stopping { profile, t, then } => {
                let t = t + dt;
                self.setpoint = profile.position(t);
                self.activity = if profile.is_done(t) {
                    // Answer only when the axes have come to rest, errors included.
                    Activity::Settling {
                        since_ns: now,
                        then,
                    }
                } else {
                    Activity::Stopping { profile, t, then }
                };
            }
            Activity::Settling { since_ns, then } => self.settle(since_ns, then, now),
            Activity::Orienting { stage, since_ns } => self.orient(stage, since_ns, now),
        }
    }

    /// The probing move, one period on from `t`; at the end of the path with the axes
    /// there and no contact, the move fails as not triggered.
    pub(super) fn probe(&mut self, profile: Profile, t: f64, request: ProbeRequest) {
        if profile.is_done(t) && self.settled().is_none() {
            // End of the path reached and the axes are there: no contact.
            self.disarm_all();
            self.reply = Some(Reply::Error(RtError::new(
                ErrorKind::NotTriggered,
                Detail::NotTriggered {
                    distance: request.max_distance,
                },
            )));
            self.activity = Activity::Idle;
            return;
        }
        let t = t + self.cfg.period_ns as f64 * 1e-9;
        self.setpoint = profile.position(t);
        self.activity = Activity::Probing {
            profile,
            t,
            request,
        };
    }

    /// Waiting for the axes to reach their setpoints, then answering `then` (a stop
    /// for a contact answers once every moving axis's latch is in).
    pub(super) fn settle(&mut self, since_ns: u64, then: Reply, now: u64) {
        if let Some(c) = self.contact {
            if now - since_ns > self.cfg.settle_timeout_ns {
                let node = self
                    .drives
                    .iter()
                    .find(|d| c.request.moves(d.axis) && d.latch_inc.is_none())
                    .map_or(0, |d| d.node);
                self.contact = None;
                self.disarm_all();
                // The contact is not used: the cycle may probe again (see ErrorKind::ContactLost).
                let err = RtError::new(ErrorKind::ContactLost, Detail::LatchLost).node(node);
                self.reply = Some(Reply::Error(err));
                self.activity = Activity::Idle;
            }
            return;
        }
        match self.settled() {
            None => {
                self.reply = Some(match then {
                    Reply::Done { .. } => Reply::Done {
                        positions: self.actual_positions(),
                    },
                    other => other,
                });
                self.activity = Activity::Idle;
            }
            Some((axis, error)) if now - since_ns > self.cfg.settle_timeout_ns => {
                let err = match then {
                    // The original fault says more than the axis that then lagged.
                    Reply::Error(e) => e,
                    _ => RtError::new(ErrorKind::Timeout, Detail::NotInPosition { axis, error }),
                };
                self.reply = Some(Reply::Error(err));
                self.activity = Activity::Idle;
            }
            Some(_) => {}
        }
    }
}
