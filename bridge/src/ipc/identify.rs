//! Cycle 451 in the estimator process: its sphere fits and its ISO 230-7
//! identification over the request service.
//!
//! - Spheres: each sphere measurement of the cycle is its own run (the cycle calls
//!   `Machine::set_run` before probing), so the estimator fits the contacts it received
//!   over iceoryx2 for that run ([`RequestKind::FitSphere`]).
//! - Identification: the input (sphere centres and angles, the chain, the active errors,
//!   the mode; `cycles::kinematics::codec`) goes up in chunks of [`CHUNK`] values
//!   ([`RequestKind::IdentifyData`]); [`RequestKind::Identify`] solves it with the same
//!   `cycles` maths and answers with the first [`REPLY_VALUES`] values of the encoded
//!   result; [`RequestKind::IdentifyResult`] fetches the rest.
//!
//! [`IpcEstimator`] is the cycle's side ([`cycles::kinematics::Estimator`]);
//! `IdentifySessions` is the estimator's.

use core::time::Duration;
use std::io::Write;
use std::time::Instant;

use cycles::geometry::SphereFit;
use cycles::kinematics::codec::{decode_input, decode_result, encode_input, encode_result};
use cycles::kinematics::{
    identify, Estimator, EstimatorError, IdentificationError, IdentificationInput,
    IdentificationResult,
};
use hal::Contact;
use nalgebra::Vector3;

use super::{
    ContactPublisher, EstimatorChild, EstimatorClient, EstimatorReply, EstimatorRequest, IpcError,
    ReplyStatus, RequestKind, REPLY_VALUES, REQUEST_PARAMS,
};

/// Values of input per [`RequestKind::IdentifyData`] request (`params[0]` is the offset).
pub const CHUNK: usize = REQUEST_PARAMS - 1;
/// Longest identification input the estimator accepts, values.
pub const MAX_INPUT: usize = 1 << 16;
/// Identification sessions the estimator keeps at once (the oldest goes first).
pub const MAX_SESSIONS: usize = 8;

struct Session {
    id: u64,
    input: Vec<f64>,
    result: Option<Vec<f64>>,
}

/// The estimator's identification sessions.
#[derive(Default)]
pub struct IdentifySessions {
    sessions: Vec<Session>,
}

fn count(v: f64, max: usize) -> Option<usize> {
    (v >= 0.0 && v.fract() == 0.0 && v <= max as f64).then_some(v as usize)
}

impl IdentifySessions {
    fn session(&mut self, id: u64) -> Option<&mut Session> {
        self.sessions.iter_mut().find(|s| s.id == id)
    }

    /// Answers the three identification request kinds (others: `UnknownRequest`).
    pub fn answer(&mut self, request: &EstimatorRequest, log: &mut dyn Write) -> EstimatorReply {
        let bad = |why: &str, log: &mut dyn Write| {
            let _ = writeln!(
                log,
                "estimator: identification session {}: {why}",
                request.run_id
            );
            EstimatorReply::new(request, ReplyStatus::BadRequest)
        };
        let Some(params) = request.params().filter(|p| !p.is_empty()) else {
            return bad("no parameters", log);
        };
        match request.request_kind() {
            Some(RequestKind::IdentifyData) => {
                let Some(offset) = count(params[0], MAX_INPUT) else {
                    return bad("bad offset", log);
                };
                if self.session(request.run_id).is_none() {
                    if offset != 0 {
                        return bad("data for an unknown session", log);
                    }
                    if self.sessions.len() >= MAX_SESSIONS {
                        self.sessions.remove(0);
                    }
                    self.sessions.push(Session {
                        id: request.run_id,
                        input: Vec::new(),
                        result: None,
                    });
                }
                let s = self.session(request.run_id).expect("just made");
                let data = &params[1..];
                if offset != s.input.len() || offset + data.len() > MAX_INPUT {
                    return bad("chunk out of order or too long", log);
                }
                s.input.extend_from_slice(data);
                s.result = None;
                let mut reply = EstimatorReply::new(request, ReplyStatus::Ok);
                reply.n_points = s.input.len() as u64;
                reply
            }
            Some(RequestKind::Identify) => {
                let Some(s) = self.session(request.run_id) else {
                    return EstimatorReply::new(request, ReplyStatus::UnknownRun);
                };
                if count(params[0], MAX_INPUT) != Some(s.input.len()) {
                    return bad("the input is incomplete", log);
                }
                let input = match decode_input(&s.input) {
                    Ok(i) => i,
                    Err(e) => return bad(&e.to_string(), log),
                };
                let t0 = Instant::now();
                let result = identify(&input);
                let _ = match &result {
                    Ok(r) => writeln!(
                        log,
                        "estimator: identification {} (mode {}, {} axes): objective {:.3e} -> {:.3e} mm^2 in {} iterations, {:.1} ms",
                        request.run_id,
                        input.mode.q406(),
                        input.axes.len(),
                        r.objective_before,
                        r.objective_after,
                        r.iterations,
                        t0.elapsed().as_secs_f64() * 1e3
                    ),
                    Err(e) => writeln!(log, "estimator: identification {}: {e}", request.run_id),
                };
                let encoded = encode_result(&result);
                s.input = Vec::new();
                s.result = Some(encoded);
                self.result_chunk(request, 0)
            }
            Some(RequestKind::IdentifyResult) => match count(params[0], MAX_INPUT) {
                Some(offset) => self.result_chunk(request, offset),
                None => bad("bad offset", log),
            },
            _ => EstimatorReply::new(request, ReplyStatus::UnknownRequest),
        }
    }

    fn result_chunk(&mut self, request: &EstimatorRequest, offset: usize) -> EstimatorReply {
        let Some(i) = self
            .sessions
            .iter()
            .position(|s| s.id == request.run_id && s.result.is_some())
        else {
            return EstimatorReply::new(request, ReplyStatus::UnknownRun);
        };
        let result = self.sessions[i].result.as_ref().expect("checked");
        let total = result.len();
        if offset > total {
            return EstimatorReply::new(request, ReplyStatus::BadRequest);
        }
        let n = (total - offset).min(REPLY_VALUES);
        let mut reply = EstimatorReply::new(request, ReplyStatus::Ok);
        reply.values[..n].copy_from_slice(&result[offset..offset + n]);
        reply.n_values = n as u32;
        reply.n_points = total as u64;
        if offset + n >= total {
            self.sessions.remove(i);
        }
        reply
    }
}

impl EstimatorClient {
    /// Cycle 451's identification solved by the estimator process. The outer error is a
    /// transport failure; the inner one the identification's own answer.
    pub fn identify(
        &self,
        input: &IdentificationInput,
        timeout: Duration,
    ) -> Result<Result<IdentificationResult, IdentificationError>, IpcError> {
        let session = hal::clock::monotonic_ns();
        let data = encode_input(input);
        if data.len() > MAX_INPUT {
            return Err(IpcError::Process(format!(
                "identification input of {} values is longer than {MAX_INPUT}",
                data.len()
            )));
        }
        let refused = |what: &str, r: &EstimatorReply| {
            IpcError::Process(format!(
                "the estimator refused {what} of identification {session}: {}",
                r.reply_status()
            ))
        };
        for (k, chunk) in data.chunks(CHUNK).enumerate() {
            let mut params = Vec::with_capacity(chunk.len() + 1);
            params.push((k * CHUNK) as f64);
            params.extend_from_slice(chunk);
            let r = self.request(
                EstimatorRequest::with_params(RequestKind::IdentifyData, session, &params),
                timeout,
            )?;
            if !r.reply_status().is_ok() {
                return Err(refused("a chunk", &r));
            }
        }
        let mut r = self.request(
            EstimatorRequest::with_params(RequestKind::Identify, session, &[data.len() as f64]),
            timeout,
        )?;
        let mut out = Vec::new();
        loop {
            if !r.reply_status().is_ok() {
                return Err(refused("the result", &r));
            }
            out.extend_from_slice(r.values());
            let total = r.n_points as usize;
            if out.len() >= total || r.n_values == 0 {
                break;
            }
            r = self.request(
                EstimatorRequest::with_params(
                    RequestKind::IdentifyResult,
                    session,
                    &[out.len() as f64],
                ),
                timeout,
            )?;
        }
        decode_result(&out).map_err(|e| IpcError::Process(e.to_string()))
    }
}

/// The estimator process a cycle talks to.
enum Source<'a> {
    /// Serving already (a daemon, another bridge's): used as it is.
    Client(&'a EstimatorClient),
    /// Started by this bridge: started again when it dies.
    Child(&'a mut EstimatorChild),
}

/// The cycle's estimator when the estimator process is there: spheres and
/// identification over iceoryx2.
///
/// An estimator this bridge started ([`IpcEstimator::restartable`]) that dies during a
/// request is started again once per request, and the request repeated: the bridge
/// still holds everything the request needs (the contacts of the sphere, sent again;
/// the whole identification input). A second death in the same request fails it. An
/// estimator that is not ours is not restarted: its death fails the request.
pub struct IpcEstimator<'a> {
    source: Source<'a>,
    /// Longest wait for one answer; a sphere fit also waits this long for the last
    /// samples of its run to arrive.
    pub timeout: Duration,
    /// Restarts so far (each one said on stderr).
    pub restarts: u32,
    /// Sends contacts again to a restarted estimator; kept, so the samples stay
    /// readable until the estimator has taken them.
    resend: Option<ContactPublisher>,
}

/// How one try of a request failed.
enum Failure {
    /// The estimator process ended (or is gone from the service): a restart may help.
    Died(IpcError),
    Other(EstimatorError),
}

impl<'a> IpcEstimator<'a> {
    /// The estimator serving `client`'s prefix, not restarted when it dies.
    pub fn new(client: &'a EstimatorClient, timeout: Duration) -> Self {
        Self {
            source: Source::Client(client),
            timeout,
            restarts: 0,
            resend: None,
        }
    }

    /// The estimator child this bridge started, restarted when it dies.
    pub fn restartable(child: &'a mut EstimatorChild, timeout: Duration) -> Self {
        Self {
            source: Source::Child(child),
            timeout,
            restarts: 0,
            resend: None,
        }
    }

    fn client(&self) -> &EstimatorClient {
        match &self.source {
            Source::Client(c) => c,
            Source::Child(c) => c.client(),
        }
    }

    fn transport(&self, e: impl core::fmt::Display) -> EstimatorError {
        EstimatorError::Transport {
            estimator: self.name(),
            message: e.to_string(),
        }
    }

    fn failure(&self, e: IpcError) -> Failure {
        match e {
            IpcError::Died { .. } | IpcError::Dropped(_) | IpcError::NoEstimator(_) => {
                Failure::Died(e)
            }
            e => Failure::Other(self.transport(e)),
        }
    }

    /// Runs `request` and, when the estimator died during it, restarts the estimator,
    /// calls `again` (to give the new one what the request needs) and repeats it once.
    fn with_restart<T>(
        &mut self,
        what: &str,
        mut request: impl FnMut(&Self) -> Result<T, Failure>,
        mut again: impl FnMut(&mut Self) -> Result<(), IpcError>,
    ) -> Result<T, EstimatorError> {
        let died = match request(self) {
            Ok(v) => return Ok(v),
            Err(Failure::Other(e)) => return Err(e),
            Err(Failure::Died(e)) => e,
        };
        let Source::Child(child) = &mut self.source else {
            return Err(self.transport(format!(
                "{died}; it was not started by this bridge, so it is not restarted"
            )));
        };
        let old = child.id();
        if let Err(e) = child.restart() {
            return Err(self.transport(format!(
                "{died}; restarting it failed: {e}; nothing was computed from the interrupted {what}"
            )));
        }
        self.restarts += 1;
        tell!(
            "estimator: the estimator process (pid {old}) died during {what}; restarted it (pid {}) and repeating the request",
            self.client_pid()
        );
        let repeated = again(self)
            .map_err(|e| self.failure(e))
            .and_then(|()| request(self));
        match repeated {
            Ok(v) => Ok(v),
            Err(Failure::Other(e)) => Err(e),
            Err(Failure::Died(e)) => Err(self.transport(format!(
                "{e}; it had already been restarted once during this {what}: giving up, nothing was computed from it"
            ))),
        }
    }

    fn client_pid(&self) -> u32 {
        match &self.source {
            Source::Child(c) => c.id(),
            Source::Client(_) => 0,
        }
    }

    /// One try: asks until the estimator has all `contacts` of the run.
    fn fit_once(&self, run_id: u64, contacts: &[Contact]) -> Result<SphereFit, Failure> {
        // The samples travel through the forwarder and iceoryx2 while the cycle goes
        // on: ask until the estimator has all of them.
        let deadline = Instant::now() + self.timeout;
        loop {
            let fit = self
                .client()
                .fit_sphere(run_id, self.timeout)
                .map_err(|e| self.failure(e))?;
            let complete = fit.ok && fit.n_points as usize >= contacts.len();
            let waiting = matches!(
                fit.error,
                ReplyStatus::UnknownRun | ReplyStatus::TooFewPoints
            ) || (fit.ok && !complete);
            if complete {
                return Ok(SphereFit {
                    centre: Vector3::from(fit.centre),
                    radius: fit.radius,
                    rms: fit.rms,
                    max_residual: fit.max_residual,
                    iterations: 0,
                });
            }
            if !waiting || Instant::now() >= deadline {
                return Err(Failure::Other(self.transport(format!(
                    "sphere fit of run {run_id}: {} ({} of {} contacts arrived)",
                    if fit.ok {
                        "incomplete".into()
                    } else {
                        fit.error.to_string()
                    },
                    fit.n_points,
                    contacts.len()
                ))));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

/// The contacts of a run as the samples the real-time loop published for them, sent
/// again to a restarted estimator (which lost the first ones).
fn send_again(
    publisher: &mut Option<ContactPublisher>,
    prefix: &str,
    run_id: u64,
    contacts: &[Contact],
) -> Result<(), IpcError> {
    if publisher.is_none() {
        *publisher = Some(ContactPublisher::new(prefix)?);
    }
    let Some(publisher) = publisher.as_mut() else {
        return Ok(());
    };
    for c in contacts {
        let mut s = hal::ContactSample::zeroed();
        s.sequence = c.sequence;
        s.run_id = run_id;
        s.trigger_ns = c.trigger_ns;
        s.positions = c.positions.raw();
        s.axis_mask = u32::from(c.positions.mask());
        s.direction = c.direction;
        s.flags = hal::contact_sample::FLAG_HW_LATCH;
        hal::SampleSink::publish(publisher, &s).map_err(|e| {
            IpcError::Process(format!("sending contact {} again: {e:?}", c.sequence))
        })?;
    }
    Ok(())
}

impl Estimator for IpcEstimator<'_> {
    fn name(&self) -> String {
        format!("estimator process ({})", self.client().names().prefix)
    }

    fn fit_sphere(
        &mut self,
        run_id: u64,
        contacts: &[Contact],
    ) -> Result<SphereFit, EstimatorError> {
        let prefix = self.client().names().prefix.clone();
        self.with_restart(
            &format!("the sphere fit of run {run_id}"),
            |me| me.fit_once(run_id, contacts),
            |me| send_again(&mut me.resend, &prefix, run_id, contacts),
        )
    }

    fn identify(
        &mut self,
        input: &IdentificationInput,
    ) -> Result<IdentificationResult, EstimatorError> {
        let timeout = self.timeout;
        self.with_restart(
            "the identification",
            |me| match me.client().identify(input, timeout) {
                Ok(r) => r.map_err(|e| Failure::Other(EstimatorError::Identification(e))),
                Err(e) => Err(me.failure(e)),
            },
            // The whole input goes up again with the repeated request.
            |_| Ok(()),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cycles::kinematics::model::ChainSpec;
    use cycles::kinematics::{AxisMeasurement, ErrorSet, MeasuredPosition, Mode};
    use hal::Axis;

    fn input(n: usize) -> IdentificationInput {
        let positions = (0..n)
            .map(|k| MeasuredPosition {
                angles: [0.0, 0.0, k as f64 * 10.0],
                centre: [50.0, -30.0, 80.0],
            })
            .collect();
        IdentificationInput {
            chain: ChainSpec {
                table: vec![(Axis::C, [0.0; 3])],
                head: vec![],
            },
            active: ErrorSet::default(),
            mode: Mode::Position,
            axes: vec![AxisMeasurement {
                axis: Axis::C,
                positions,
            }],
        }
    }

    /// The estimator's side alone: chunks in, result out in pieces.
    #[test]
    fn sessions_take_chunks_and_give_the_result_in_pieces() {
        let mut s = IdentifySessions::default();
        let mut log = Vec::new();
        let inp = input(40);
        let data = encode_input(&inp);
        assert!(data.len() > CHUNK);
        for (k, chunk) in data.chunks(CHUNK).enumerate() {
            let mut p = vec![(k * CHUNK) as f64];
            p.extend_from_slice(chunk);
            let r = s.answer(
                &EstimatorRequest::with_params(RequestKind::IdentifyData, 9, &p),
                &mut log,
            );
            assert!(r.reply_status().is_ok());
        }
        // Out of order: refused.
        let r = s.answer(
            &EstimatorRequest::with_params(RequestKind::IdentifyData, 9, &[3.0, 1.0]),
            &mut log,
        );
        assert_eq!(r.reply_status(), ReplyStatus::BadRequest);
        let mut r = s.answer(
            &EstimatorRequest::with_params(RequestKind::Identify, 9, &[data.len() as f64]),
            &mut log,
        );
        let mut out = Vec::new();
        loop {
            assert!(r.reply_status().is_ok(), "{:?}", r.reply_status());
            out.extend_from_slice(r.values());
            if out.len() >= r.n_points as usize {
                break;
            }
            r = s.answer(
                &EstimatorRequest::with_params(RequestKind::IdentifyResult, 9, &[out.len() as f64]),
                &mut log,
            );
        }
        assert!(out.len() > REPLY_VALUES, "the result came in pieces");
        assert_eq!(decode_result(&out).unwrap(), identify(&inp));
        // The session is gone once fetched.
        let r = s.answer(
            &EstimatorRequest::with_params(RequestKind::IdentifyResult, 9, &[0.0]),
            &mut log,
        );
        assert_eq!(r.reply_status(), ReplyStatus::UnknownRun);
    }
}
