//! Measurement time: a run's clock reads seconds since its origin, an instant in UTC. Pose
//! stream `stamp`s are Unix seconds of the measurement, `time`s the same instant in ISO 8601.
//! A recording writes the origin into every capture's `started` header with nanosecond
//! precision, so a replay computes the very same stamps.

use std::time::SystemTime;

use time::format_description::well_known::Rfc3339;
use time::OffsetDateTime;

/// The instant a run's clock reads zero, in nanoseconds since the Unix epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeOrigin {
    unix_ns: i128,
}

/// Nanoseconds in a second.
const NS: i128 = 1_000_000_000;

impl TimeOrigin {
    /// Now.
    #[must_use]
    pub fn now() -> Self {
        Self::from_system(SystemTime::now())
    }

    /// A system time.
    #[must_use]
    pub fn from_system(t: SystemTime) -> Self {
        let unix_ns = OffsetDateTime::from(t).unix_timestamp_nanos();
        Self { unix_ns }
    }

    /// From nanoseconds since the Unix epoch.
    #[must_use]
    pub fn from_unix_ns(unix_ns: i128) -> Self {
        Self { unix_ns }
    }

    /// Nanoseconds since the Unix epoch.
    #[must_use]
    pub fn unix_ns(self) -> i128 {
        self.unix_ns
    }

    /// Parses an RFC 3339 time such as a capture's `started` header.
    pub fn parse_rfc3339(text: &str) -> Result<Self, time::error::Parse> {
        let t = OffsetDateTime::parse(text.trim(), &Rfc3339)?;
        Ok(Self {
            unix_ns: t.unix_timestamp_nanos(),
        })
    }

    /// RFC 3339 in UTC with every nanosecond (`2026-12-02T07:30:00.123456789Z`).
    #[must_use]
    pub fn rfc3339(self) -> String {
        let secs = self.unix_ns.div_euclid(NS);
        let nanos = self.unix_ns.rem_euclid(NS);
        let Ok(t) = i64::try_from(secs)
            .map_err(|_| ())
            .and_then(|s| OffsetDateTime::from_unix_timestamp(s).map_err(|_| ()))
        else {
            return "1970-01-01T00:00:00.000000000Z".into();
        };
        let base = t
            .replace_nanosecond(0)
            .ok()
            .and_then(|t| t.format(&Rfc3339).ok())
            .unwrap_or_default();
        format!("{}.{nanos:09}Z", base.trim_end_matches('Z'))
    }

    /// Unix seconds of the instant `t` seconds of run clock after the origin.
    #[must_use]
    pub fn stamp(self, t: f64) -> f64 {
        let secs = self.unix_ns.div_euclid(NS);
        let frac = self.unix_ns.rem_euclid(NS);
        #[allow(clippy::cast_precision_loss)]
        let (secs, frac) = (secs as f64, frac as f64 * 1e-9);
        secs + (frac + t)
    }

    /// ISO 8601 (UTC, milliseconds, truncated) of the instant `t` seconds after the origin.
    #[must_use]
    pub fn iso8601(self, t: f64) -> String {
        let offset_ns = if t.is_finite() {
            #[allow(clippy::cast_possible_truncation)]
            let ns = (t * 1e9).round() as i128;
            ns
        } else {
            0
        };
        iso8601_unix_ns(self.unix_ns + offset_ns)
    }
}

/// A duration of `secs` seconds that cannot panic: not-a-number and negative values are zero,
/// and values are capped at 30 years (a wait that long is forever; an `Instant` plus it still
/// fits). The daemon's checks keep configured values far inside this; it is the last guard.
#[must_use]
pub fn seconds(secs: f64) -> std::time::Duration {
    const CAP_S: f64 = 30.0 * 365.25 * 86_400.0;
    if secs.is_nan() || secs <= 0.0 {
        return std::time::Duration::ZERO;
    }
    std::time::Duration::from_secs_f64(secs.min(CAP_S))
}

/// ISO 8601 (UTC, milliseconds) of a system time: the time of a status change.
#[must_use]
pub fn iso8601(t: SystemTime) -> String {
    iso8601_unix_ns(OffsetDateTime::from(t).unix_timestamp_nanos())
}

fn iso8601_unix_ns(unix_ns: i128) -> String {
    let ms = unix_ns.div_euclid(1_000_000);
    let secs = ms.div_euclid(1000);
    let millis = ms.rem_euclid(1000);
    let text = i64::try_from(secs)
        .ok()
        .and_then(|s| OffsetDateTime::from_unix_timestamp(s).ok())
        .and_then(|t| t.format(&Rfc3339).ok())
        .unwrap_or_else(|| "1970-01-01T00:00:00Z".into());
    format!("{}.{millis:03}Z", text.trim_end_matches('Z'))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn origin_round_trips_through_its_header_text() {
        let o = TimeOrigin::from_unix_ns(1_764_660_600_123_456_789);
        assert_eq!(o.rfc3339(), "2025-12-02T07:30:00.123456789Z");
        assert_eq!(TimeOrigin::parse_rfc3339(&o.rfc3339()).unwrap(), o);
        // Old captures carry whole seconds.
        let whole = TimeOrigin::parse_rfc3339("2026-11-21T10:00:00Z").unwrap();
        assert_eq!(whole.unix_ns(), 1_795_255_200 * NS);
        assert_eq!(whole.iso8601(14.776_625), "2026-11-21T10:00:14.776Z");
        assert!((whole.stamp(14.776_625) - 1_795_255_214.776_625).abs() < 1e-6);
        assert!(TimeOrigin::parse_rfc3339("yesterday").is_err());
    }

    #[test]
    fn seconds_never_panic() {
        assert_eq!(seconds(f64::NAN), std::time::Duration::ZERO);
        assert_eq!(seconds(-1.0), std::time::Duration::ZERO);
        assert_eq!(seconds(1.5), std::time::Duration::from_millis(1500));
        let far = seconds(1e300);
        assert!(far > std::time::Duration::from_secs(900_000_000));
        let _ = std::time::Instant::now() + seconds(f64::INFINITY);
    }

    #[test]
    fn times_before_the_origin_and_far_ones_format() {
        let o = TimeOrigin::from_unix_ns(0);
        assert_eq!(o.iso8601(-0.5), "1969-12-31T23:59:59.500Z");
        assert_eq!(o.iso8601(f64::NAN), "1970-01-01T00:00:00.000Z");
    }
}
