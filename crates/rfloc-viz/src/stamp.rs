//! Measurement times as Unix nanoseconds.

use foxglove::messages::Timestamp;

use crate::VizError;

/// A measurement time, in nanoseconds since the Unix epoch.
///
/// Every message carries its measurement time twice: in the message's own `timestamp` field and
/// as the log time of the MCAP record or WebSocket frame, so that Foxglove's time line and the
/// robot's clock agree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Stamp(u64);

/// The last second a Foxglove `Timestamp` (unsigned 32-bit seconds) can hold, plus one.
const SECONDS_LIMIT: f64 = 4_294_967_296.0;

impl Stamp {
    /// From nanoseconds since the Unix epoch. Times past 2106-02-07 (the end of Foxglove's
    /// 32-bit seconds) are clamped there when written into a message's `timestamp`.
    #[must_use]
    pub const fn from_unix_nanos(nanos: u64) -> Self {
        Self(nanos)
    }

    /// From seconds since the Unix epoch, rounded to the nearest nanosecond (an `f64` holds
    /// present-day times to about 0.2 µs).
    ///
    /// # Errors
    /// [`VizError::InvalidTime`] for a negative, non-finite or too large (after 2106) time.
    pub fn from_unix_secs(secs: f64) -> Result<Self, VizError> {
        if !(0.0..SECONDS_LIMIT).contains(&secs) {
            return Err(VizError::InvalidTime(secs));
        }
        let whole = secs.floor();
        // Both parts are in range: `whole` < 2^32 and the fraction rounds to at most 1e9.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (s, ns) = (whole as u64, ((secs - whole) * 1e9).round() as u64);
        Ok(Self(s * 1_000_000_000 + ns))
    }

    /// Nanoseconds since the Unix epoch.
    #[must_use]
    pub const fn unix_nanos(self) -> u64 {
        self.0
    }

    /// Seconds since the Unix epoch.
    #[must_use]
    #[allow(clippy::cast_precision_loss)]
    pub fn unix_secs(self) -> f64 {
        (self.0 / 1_000_000_000) as f64 + (self.0 % 1_000_000_000) as f64 * 1e-9
    }

    /// The Foxglove `Timestamp` (seconds and nanoseconds) of this time.
    pub(crate) fn timestamp(self) -> Timestamp {
        let (sec, nsec) = (self.0 / 1_000_000_000, self.0 % 1_000_000_000);
        match (u32::try_from(sec), u32::try_from(nsec)) {
            (Ok(sec), Ok(nsec)) => Timestamp::new_checked(sec, nsec).unwrap_or(Timestamp::MAX),
            _ => Timestamp::MAX,
        }
    }
}

impl From<std::time::SystemTime> for Stamp {
    /// A wall-clock time; times before 1970 become the epoch.
    fn from(t: std::time::SystemTime) -> Self {
        let nanos = t
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
            .unwrap_or(0);
        Self(nanos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_round_to_the_nearest_nanosecond() {
        let s = Stamp::from_unix_secs(1_700_000_000.25).unwrap();
        assert_eq!(s.unix_nanos(), 1_700_000_000_250_000_000);
        let t = s.timestamp();
        assert_eq!((t.sec(), t.nsec()), (1_700_000_000, 250_000_000));
        // 0.1 is not exact in binary; rounding (not truncation) gives 100 ms.
        let s = Stamp::from_unix_secs(0.1).unwrap();
        assert_eq!(s.unix_nanos(), 100_000_000);
        assert!((s.unix_secs() - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_fraction_that_rounds_up_carries_into_the_seconds() {
        let s = Stamp::from_unix_secs(12.999_999_999_9).unwrap();
        assert_eq!(s.unix_nanos(), 13_000_000_000);
        let t = s.timestamp();
        assert_eq!((t.sec(), t.nsec()), (13, 0));
    }

    #[test]
    fn bad_seconds_are_refused() {
        for bad in [-1.0, f64::NAN, f64::INFINITY, 5.0e9] {
            assert!(
                matches!(Stamp::from_unix_secs(bad), Err(VizError::InvalidTime(_))),
                "{bad}"
            );
        }
    }

    #[test]
    fn nanoseconds_past_2106_clamp_in_the_message_timestamp() {
        let s = Stamp::from_unix_nanos(u64::MAX);
        assert_eq!(s.timestamp(), Timestamp::MAX);
        assert_eq!(
            s.unix_nanos(),
            u64::MAX,
            "the log time keeps the full value"
        );
    }

    #[test]
    fn system_time_converts() {
        let t = std::time::UNIX_EPOCH + std::time::Duration::from_nanos(1_234_567_890_123);
        assert_eq!(Stamp::from(t).unix_nanos(), 1_234_567_890_123);
    }
}
