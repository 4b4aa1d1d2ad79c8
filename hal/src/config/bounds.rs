//! The plausible ranges of the machine values, as docs/configuration.md names
//! them: a value outside is a typing error (a unit slip, a stray exponent) and is
//! refused with the file, the key and the range before anything moves.

/// The slowest feed any move is given (mm/min, deg/min): below it a move would take
/// so long that it looks like a hang.
pub const MIN_FEED: f64 = 1.0;
/// `max_feed`, mm/min (deg/min): from the slowest feed any move is given to 200 m/min.
pub const MAX_FEED: (f64, f64) = (MIN_FEED, 200_000.0);
/// `max_acceleration`, mm/s^2 (deg/s^2): below 10 a move barely starts (hours for
/// a rapid traverse); 100 000 is about 10 g.
pub const MAX_ACCELERATION: (f64, f64) = (10.0, 100_000.0);
/// `hirth`, deg: 0 (none) up to an eighth of a turn.
pub const HIRTH: (f64, f64) = (0.0, 45.0);
/// Every coordinate of a `kinematics.pivot`, mm either side of the origin.
pub const PIVOT_MM: f64 = 10_000.0;
/// `bus.sdo_timeout_ms`.
pub const SDO_TIMEOUT_MS: (u16, u16) = (10, 10_000);
