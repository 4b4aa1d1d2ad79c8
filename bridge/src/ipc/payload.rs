//! Request and reply payloads between the bridge and the estimator process.
//!
//! Both are `#[repr(C)]`, `ZeroCopySend` and of fixed size: a tagged struct with a `kind`
//! field and a fixed payload area (`run_ids` + `params` in a request, `values` in a reply).
//! A new request kind (e.g. kinematics identification for cycle 451 over many sphere
//! centres) gets a new [`RequestKind`] value and its own encode/decode functions over the
//! same areas; the layout and the iceoryx2 type names stay the same. Changing the layout
//! means bumping the `/1` in the type name, so that old and new processes refuse to
//! connect instead of misreading each other.

use iceoryx2::prelude::*;

/// How many run ids one request can name (e.g. the sphere runs of one 451 measurement).
pub const REQUEST_MAX_RUNS: usize = 64;
/// Number of `f64` request parameters.
pub const REQUEST_PARAMS: usize = 32;
/// Number of `f64` result values in a reply (sphere: 6; identification: parameters,
/// per-run centres and residuals).
pub const REPLY_VALUES: usize = 256;

/// What a request asks for ([`EstimatorRequest::kind`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
#[non_exhaustive]
pub enum RequestKind {
    /// Is the estimator there? Reply: `Ok`, no values.
    Ping = 1,
    /// Fit a sphere to the X/Y/Z positions of the samples of `run_id`.
    FitSphere = 2,
    /// Drop the samples of `run_id`. Reply: `Ok` (`n_points` = samples dropped) or
    /// `UnknownRun`.
    Forget = 3,
    /// Ask the estimator process to exit after replying.
    Shutdown = 4,
    /// Cycle 451: one chunk of an identification input (see
    /// `cycles::kinematics::codec`) for session `run_id`: `params[0]` is the offset of
    /// the chunk (chunks arrive in order), `params[1..n_params]` the values. Reply: `Ok`
    /// with `n_points` = values received so far, or `BadRequest`.
    IdentifyData = 5,
    /// Cycle 451: solve the identification uploaded for session `run_id`, whose input
    /// has `params[0]` values. Reply: `Ok` with the first [`REPLY_VALUES`] values of the
    /// encoded result (an identification error is encoded in it, not a status) and
    /// `n_points` = its full length; `UnknownRun` without such a session; `BadRequest`
    /// for an incomplete or malformed input.
    Identify = 6,
    /// Cycle 451: the values of session `run_id`'s result from offset `params[0]`.
    IdentifyResult = 7,
}

impl RequestKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            1 => Self::Ping,
            2 => Self::FitSphere,
            3 => Self::Forget,
            4 => Self::Shutdown,
            5 => Self::IdentifyData,
            6 => Self::Identify,
            7 => Self::IdentifyResult,
            _ => return None,
        })
    }
}

/// Outcome of a request ([`EstimatorReply::status`]). An error code is an answer from
/// the estimator, not a transport failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
#[non_exhaustive]
pub enum ReplyStatus {
    Ok = 0,
    /// The estimator holds no samples for that run id (never seen, forgotten, or
    /// dropped because more than the maximum number of runs arrived after it).
    UnknownRun = 1,
    /// Not enough samples with valid X/Y/Z for the fit.
    TooFewPoints = 2,
    /// A sample position is NaN or infinite.
    NotFinite = 3,
    /// The points do not determine the shape (e.g. all in one plane).
    Degenerate = 4,
    /// The iterative fit did not converge.
    NoConvergence = 5,
    /// The estimator does not know this request kind (older estimator).
    UnknownRequest = 6,
    /// The request is malformed (e.g. a count larger than its array).
    BadRequest = 7,
    /// A status value this build does not know (newer estimator).
    Unrecognised = u32::MAX,
}

impl ReplyStatus {
    pub fn from_u32(v: u32) -> Self {
        match v {
            0 => Self::Ok,
            1 => Self::UnknownRun,
            2 => Self::TooFewPoints,
            3 => Self::NotFinite,
            4 => Self::Degenerate,
            5 => Self::NoConvergence,
            6 => Self::UnknownRequest,
            7 => Self::BadRequest,
            _ => Self::Unrecognised,
        }
    }

    pub fn is_ok(self) -> bool {
        self == Self::Ok
    }

    pub fn describe(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::UnknownRun => "the estimator has no samples for this run",
            Self::TooFewPoints => "too few points for the fit",
            Self::NotFinite => "a point is not finite",
            Self::Degenerate => "the points are degenerate (they do not determine the shape)",
            Self::NoConvergence => "the fit did not converge",
            Self::UnknownRequest => "the estimator does not know this request",
            Self::BadRequest => "malformed request",
            Self::Unrecognised => "unrecognised status code",
        }
    }
}

impl core::fmt::Display for ReplyStatus {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.describe())
    }
}

/// A request from the bridge to the estimator (request-response request payload).
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("probebridge::EstimatorRequest/1")]
#[repr(C)]
pub struct EstimatorRequest {
    /// A [`RequestKind`] value.
    pub kind: u32,
    pub flags: u32,
    /// Chosen by the client, echoed in the reply.
    pub request_id: u64,
    /// The run a single-run request is about (`FitSphere`, `Forget`).
    pub run_id: u64,
    /// Number of valid entries in `run_ids` (multi-run requests).
    pub n_run_ids: u32,
    /// Number of valid entries in `params`.
    pub n_params: u32,
    pub run_ids: [u64; REQUEST_MAX_RUNS],
    pub params: [f64; REQUEST_PARAMS],
}

impl EstimatorRequest {
    pub const fn new(kind: RequestKind, run_id: u64) -> Self {
        Self {
            kind: kind as u32,
            flags: 0,
            request_id: 0,
            run_id,
            n_run_ids: 0,
            n_params: 0,
            run_ids: [0; REQUEST_MAX_RUNS],
            params: [0.0; REQUEST_PARAMS],
        }
    }

    pub const fn ping() -> Self {
        Self::new(RequestKind::Ping, 0)
    }

    pub const fn fit_sphere(run_id: u64) -> Self {
        Self::new(RequestKind::FitSphere, run_id)
    }

    pub const fn forget(run_id: u64) -> Self {
        Self::new(RequestKind::Forget, run_id)
    }

    pub const fn shutdown() -> Self {
        Self::new(RequestKind::Shutdown, 0)
    }

    /// A request of `kind` about `run_id` carrying `params` (at most [`REQUEST_PARAMS`]).
    pub fn with_params(kind: RequestKind, run_id: u64, params: &[f64]) -> Self {
        let mut r = Self::new(kind, run_id);
        let n = params.len().min(REQUEST_PARAMS);
        r.params[..n].copy_from_slice(&params[..n]);
        r.n_params = n as u32;
        r
    }

    /// The valid parameters, or `None` if `n_params` is too large.
    pub fn params(&self) -> Option<&[f64]> {
        self.params.get(..self.n_params as usize)
    }

    pub fn request_kind(&self) -> Option<RequestKind> {
        RequestKind::from_u32(self.kind)
    }

    /// The valid run ids of a multi-run request, or `None` if `n_run_ids` is too large.
    pub fn run_ids(&self) -> Option<&[u64]> {
        self.run_ids.get(..self.n_run_ids as usize)
    }
}

/// The estimator's answer (request-response response payload).
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("probebridge::EstimatorReply/1")]
#[repr(C)]
pub struct EstimatorReply {
    /// The [`RequestKind`] value of the request this answers.
    pub kind: u32,
    /// A [`ReplyStatus`] value.
    pub status: u32,
    pub request_id: u64,
    pub run_id: u64,
    /// Number of samples the result is based on (or affected by).
    pub n_points: u64,
    /// Number of valid entries in `values`.
    pub n_values: u32,
    /// Process id of the estimator that answered: the client watches that process, so
    /// its death ends a wait at once instead of after the request timeout.
    pub server_pid: u32,
    pub values: [f64; REPLY_VALUES],
}

impl EstimatorReply {
    pub const fn new(request: &EstimatorRequest, status: ReplyStatus) -> Self {
        Self {
            kind: request.kind,
            status: status as u32,
            request_id: request.request_id,
            run_id: request.run_id,
            n_points: 0,
            n_values: 0,
            server_pid: 0,
            values: [0.0; REPLY_VALUES],
        }
    }

    pub fn reply_status(&self) -> ReplyStatus {
        ReplyStatus::from_u32(self.status)
    }

    pub fn values(&self) -> &[f64] {
        &self.values[..(self.n_values as usize).min(REPLY_VALUES)]
    }
}

/// Index of each sphere value in [`EstimatorReply::values`].
mod sphere_slot {
    pub const CENTRE: usize = 0; // 0, 1, 2
    pub const RADIUS: usize = 3;
    pub const RMS: usize = 4;
    pub const MAX_RESIDUAL: usize = 5;
    pub const COUNT: usize = 6;
}

/// Answer to [`RequestKind::FitSphere`]: the sphere through the ball-centre positions of
/// one run. Its radius is the artefact sphere's radius plus the stylus ball radius (the
/// caller subtracts the ball radius). When `ok` is false, `error` says why and the
/// numbers are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereResult {
    pub run_id: u64,
    pub ok: bool,
    /// Machine X/Y/Z, mm.
    pub centre: [f64; 3],
    pub radius: f64,
    /// RMS of the geometric residuals, mm.
    pub rms: f64,
    /// Largest absolute geometric residual, mm.
    pub max_residual: f64,
    /// Samples the fit used.
    pub n_points: u64,
    pub error: ReplyStatus,
}

impl SphereResult {
    pub fn failed(run_id: u64, n_points: u64, error: ReplyStatus) -> Self {
        Self {
            run_id,
            ok: false,
            centre: [0.0; 3],
            radius: 0.0,
            rms: 0.0,
            max_residual: 0.0,
            n_points,
            error,
        }
    }

    /// Writes this result into a reply to `request`.
    pub fn to_reply(&self, request: &EstimatorRequest) -> EstimatorReply {
        let mut reply = EstimatorReply::new(request, self.error);
        reply.run_id = self.run_id;
        reply.n_points = self.n_points;
        if self.ok {
            let v = &mut reply.values;
            v[sphere_slot::CENTRE..sphere_slot::CENTRE + 3].copy_from_slice(&self.centre);
            v[sphere_slot::RADIUS] = self.radius;
            v[sphere_slot::RMS] = self.rms;
            v[sphere_slot::MAX_RESIDUAL] = self.max_residual;
            reply.n_values = sphere_slot::COUNT as u32;
        }
        reply
    }

    /// Reads a reply to a `FitSphere` request.
    pub fn from_reply(reply: &EstimatorReply) -> Self {
        let status = reply.reply_status();
        if !status.is_ok() || (reply.n_values as usize) < sphere_slot::COUNT {
            let error = if status.is_ok() {
                ReplyStatus::BadRequest
            } else {
                status
            };
            return Self::failed(reply.run_id, reply.n_points, error);
        }
        let v = &reply.values;
        Self {
            run_id: reply.run_id,
            ok: true,
            centre: [
                v[sphere_slot::CENTRE],
                v[sphere_slot::CENTRE + 1],
                v[sphere_slot::CENTRE + 2],
            ],
            radius: v[sphere_slot::RADIUS],
            rms: v[sphere_slot::RMS],
            max_residual: v[sphere_slot::MAX_RESIDUAL],
            n_points: reply.n_points,
            error: ReplyStatus::Ok,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_are_fixed() {
        // Part of the IPC contract: a change here needs a new type name version.
        assert_eq!(
            core::mem::size_of::<EstimatorRequest>(),
            4 + 4 + 8 + 8 + 4 + 4 + 8 * REQUEST_MAX_RUNS + 8 * REQUEST_PARAMS
        );
        assert_eq!(
            core::mem::size_of::<EstimatorReply>(),
            4 + 4 + 8 + 8 + 8 + 4 + 4 + 8 * REPLY_VALUES
        );
        assert_eq!(core::mem::align_of::<EstimatorRequest>(), 8);
        assert_eq!(core::mem::align_of::<EstimatorReply>(), 8);
    }

    #[test]
    fn sphere_result_round_trips_through_a_reply() {
        let req = EstimatorRequest::fit_sphere(7);
        let r = SphereResult {
            run_id: 7,
            ok: true,
            centre: [1.0, -2.0, 3.5],
            radius: 15.0,
            rms: 1e-4,
            max_residual: 3e-4,
            n_points: 25,
            error: ReplyStatus::Ok,
        };
        assert_eq!(SphereResult::from_reply(&r.to_reply(&req)), r);
        let e = SphereResult::failed(7, 2, ReplyStatus::TooFewPoints);
        assert_eq!(SphereResult::from_reply(&e.to_reply(&req)), e);
    }

    #[test]
    fn unknown_codes_are_not_mistaken_for_known_ones() {
        assert_eq!(RequestKind::from_u32(99), None);
        assert_eq!(ReplyStatus::from_u32(99), ReplyStatus::Unrecognised);
        for k in [
            RequestKind::Ping,
            RequestKind::FitSphere,
            RequestKind::Forget,
            RequestKind::Shutdown,
            RequestKind::IdentifyData,
            RequestKind::Identify,
            RequestKind::IdentifyResult,
        ] {
            assert_eq!(RequestKind::from_u32(k as u32), Some(k));
        }
    }
}
