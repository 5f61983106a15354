//! Time as the caller passes it in: milliseconds since the Unix epoch (UTC).
//!
//! Nothing in this crate reads a clock. The caller converts its clock reading into a
//! [`Timestamp`] and hands it to the functions that need one.

use std::fmt;

/// Milliseconds past 1970-01-01T00:00:00Z of 10000-01-01T00:00:00Z: the first instant that no
/// longer has a four-digit year, which ISO 8601 timestamps of the header cannot show.
const END_OF_YEAR_9999_MS: u64 = 253_402_300_800_000;

/// A UTC instant with millisecond resolution, between 1970-01-01 and the end of year 9999.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Timestamp(u64);

impl Timestamp {
    /// The Unix epoch, 1970-01-01T00:00:00.000Z.
    pub const EPOCH: Timestamp = Timestamp(0);

    /// A timestamp `ms` milliseconds after the Unix epoch; `None` past the end of year 9999.
    pub fn from_unix_millis(ms: u64) -> Option<Timestamp> {
        (ms < END_OF_YEAR_9999_MS).then_some(Timestamp(ms))
    }

    /// Milliseconds since the Unix epoch.
    pub fn unix_millis(self) -> u64 {
        self.0
    }

    /// Milliseconds from `earlier` to `self`, zero if `earlier` is later.
    pub fn millis_since(self, earlier: Timestamp) -> u64 {
        self.0.saturating_sub(earlier.0)
    }

    /// This instant plus `ms` milliseconds, saturating at the last representable millisecond.
    pub fn plus_millis(self, ms: u64) -> Timestamp {
        Timestamp(self.0.saturating_add(ms).min(END_OF_YEAR_9999_MS - 1))
    }

    /// The header's timestamp text: ISO 8601 in UTC with milliseconds, `YYYY-MM-DDTHH:mm:ss.fffZ`.
    pub fn to_iso8601(self) -> String {
        self.to_string()
    }
}

impl fmt::Display for Timestamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ms = self.0 % 1000;
        let secs = self.0 / 1000;
        let days = secs / 86_400;
        let sod = secs % 86_400;
        let (year, month, day) = civil_from_days(days);
        write!(
            f,
            "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{ms:03}Z",
            sod / 3600,
            (sod / 60) % 60,
            sod % 60
        )
    }
}

/// Proleptic Gregorian date of the day `days` after 1970-01-01.
///
/// Counts in 400-year eras (146 097 days each) starting on 0000-03-01, so that the leap day is
/// the last day of each counted year.
fn civil_from_days(days: u64) -> (u64, u64, u64) {
    // Days from 0000-03-01 to 1970-01-01.
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z % 146_097; // day of era, 0..=146096
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365; // year of era, 0..=399
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100); // day of the March-based year
    let mp = (5 * doy + 2) / 153; // month from March = 0
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + u64::from(month <= 2);
    (year, month, day)
}

/// Whether `text` is an RFC 3339 / ISO 8601 date-time with a time zone, as the header's
/// `timestamp` must be (`2017-04-15T11:40:03.12Z`).
pub fn is_valid_timestamp_text(text: &str) -> bool {
    time::OffsetDateTime::parse(text, &time::format_description::well_known::Rfc3339).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_and_known_instants_format_with_milliseconds() {
        assert_eq!(Timestamp::EPOCH.to_iso8601(), "1970-01-01T00:00:00.000Z");
        // 2017-04-15T11:40:03.120Z, the specification's example instant.
        let t = Timestamp::from_unix_millis(1_492_256_403_120).unwrap();
        assert_eq!(t.to_iso8601(), "2017-04-15T11:40:03.120Z");
        // A leap day and the last millisecond of a leap year.
        let t = Timestamp::from_unix_millis(951_782_400_000).unwrap();
        assert_eq!(t.to_iso8601(), "2000-02-29T00:00:00.000Z");
        let t = Timestamp::from_unix_millis(978_307_199_999).unwrap();
        assert_eq!(t.to_iso8601(), "2000-12-31T23:59:59.999Z");
        let last = Timestamp::from_unix_millis(END_OF_YEAR_9999_MS - 1).unwrap();
        assert_eq!(last.to_iso8601(), "9999-12-31T23:59:59.999Z");
        assert!(Timestamp::from_unix_millis(END_OF_YEAR_9999_MS).is_none());
    }

    #[test]
    fn formatting_agrees_with_the_time_crate() {
        for ms in [
            0u64,
            1,
            86_399_999,
            1_700_000_000_123,
            4_102_444_800_000,
            123_456_789_012_345,
        ] {
            let ours = Timestamp::from_unix_millis(ms).unwrap().to_iso8601();
            let parsed =
                time::OffsetDateTime::parse(&ours, &time::format_description::well_known::Rfc3339)
                    .unwrap();
            assert_eq!(
                parsed.unix_timestamp_nanos(),
                i128::from(ms) * 1_000_000,
                "{ours}"
            );
        }
    }

    #[test]
    fn timestamp_text_check() {
        assert!(is_valid_timestamp_text("2017-04-15T11:40:03.12Z"));
        assert!(is_valid_timestamp_text("1991-03-11T11:40:03.123Z"));
        assert!(!is_valid_timestamp_text("2017-04-15 11:40:03"));
        assert!(!is_valid_timestamp_text("yesterday"));
    }

    #[test]
    fn arithmetic_saturates() {
        let t = Timestamp::from_unix_millis(1000).unwrap();
        assert_eq!(t.millis_since(Timestamp::EPOCH), 1000);
        assert_eq!(Timestamp::EPOCH.millis_since(t), 0);
        assert_eq!(
            t.plus_millis(u64::MAX).unix_millis(),
            END_OF_YEAR_9999_MS - 1
        );
    }
}
