//! Reader times (`YYYY/MM/DD hh:mm:ss[.mmm]`, or epoch milliseconds from `${MSEC1}`).

/// A time printed by the reader.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum ReaderTime {
    /// Local wall time; the date is absent when the format printed only `%t`.
    Clock {
        date: Option<(u16, u8, u8)>,
        seconds_of_day: f64,
    },
    /// Milliseconds since the Unix epoch (`${MSEC1}`/`${MSEC2}`).
    EpochMillis(u64),
}

impl ReaderTime {
    /// Parses `hh:mm:ss[.fff]`.
    #[must_use]
    pub fn parse_time(t: &str) -> Option<f64> {
        let mut it = t.trim().split(':');
        let h: u32 = it.next()?.trim().parse().ok()?;
        let m: u32 = it.next()?.trim().parse().ok()?;
        let s: f64 = it.next()?.trim().parse().ok()?;
        if it.next().is_some() || h > 23 || m > 59 || !(0.0..61.0).contains(&s) {
            return None;
        }
        Some(f64::from(h * 3600 + m * 60) + s)
    }

    /// Parses `YYYY/MM/DD` (non-padded parts accepted).
    #[must_use]
    pub fn parse_date(d: &str) -> Option<(u16, u8, u8)> {
        let mut it = d.trim().split('/');
        let y = it.next()?.trim().parse().ok()?;
        let m = it.next()?.trim().parse().ok()?;
        let dd = it.next()?.trim().parse().ok()?;
        if it.next().is_some() || !(1..=12).contains(&m) || !(1..=31).contains(&dd) {
            return None;
        }
        Some((y, m, dd))
    }

    /// Parses `YYYY/MM/DD hh:mm:ss[.fff]` or `hh:mm:ss[.fff]`.
    #[must_use]
    pub fn parse(text: &str) -> Option<Self> {
        let t = text.trim();
        match t.split_once(' ') {
            Some((d, tm)) => Some(Self::Clock {
                date: Some(Self::parse_date(d)?),
                seconds_of_day: Self::parse_time(tm)?,
            }),
            None => Some(Self::Clock {
                date: None,
                seconds_of_day: Self::parse_time(t)?,
            }),
        }
    }
}

impl std::fmt::Display for ReaderTime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReaderTime::Clock {
                date,
                seconds_of_day,
            } => {
                if let Some((y, m, d)) = date {
                    write!(f, "{y:04}/{m:02}/{d:02} ")?;
                }
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let ms = (seconds_of_day.max(0.0) * 1000.0).round() as u64;
                let (h, m, s, frac) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60, ms % 1000);
                if frac == 0 {
                    write!(f, "{h:02}:{m:02}:{s:02}")
                } else {
                    write!(f, "{h:02}:{m:02}:{s:02}.{frac:03}")
                }
            }
            ReaderTime::EpochMillis(ms) => write!(f, "{ms}ms"),
        }
    }
}

/// Converts Unix seconds to (year, month, day, hour, minute, second) in UTC
/// (days-from-civil inverse, proleptic Gregorian calendar).
#[must_use]
pub fn civil_from_unix(secs: u64) -> (i64, u32, u32, u32, u32, u32) {
    let days = i64::try_from(secs / 86_400).unwrap_or(0);
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    (
        y,
        m as u32,
        d as u32,
        (rem / 3600) as u32,
        ((rem / 60) % 60) as u32,
        (rem % 60) as u32,
    )
}

/// `YYYY/MM/DD hh:mm:ss` for Unix seconds (UTC), the format `set Time` takes.
#[must_use]
pub fn format_reader_time(secs: u64) -> String {
    let (y, mo, d, h, mi, s) = civil_from_unix(secs);
    format!("{y:04}/{mo:02}/{d:02} {h:02}:{mi:02}:{s:02}")
}

/// Unix seconds of a UTC civil time (inverse of [`civil_from_unix`]); `None` before 1970.
#[must_use]
pub fn unix_from_civil(y: i64, m: u32, d: u32, seconds_of_day: f64) -> Option<f64> {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = i64::from((m + 9) % 12);
    let doy = (153 * mp + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    if days < 0 {
        return None;
    }
    #[allow(clippy::cast_precision_loss)]
    Some(days as f64 * 86_400.0 + seconds_of_day)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_reader_times() {
        // §3.2 real ALR-9900 line: `Disc:2015/04/25 21:11:26.082`.
        let t = ReaderTime::parse("2015/04/25 21:11:26.082").unwrap();
        let ReaderTime::Clock {
            date,
            seconds_of_day,
        } = t
        else {
            panic!()
        };
        assert_eq!(date, Some((2015, 4, 25)));
        assert!((seconds_of_day - 76286.082).abs() < 1e-9);
        // Older firmware: `2002/6/3 9:23:01`.
        assert!(ReaderTime::parse("2002/6/3 9:23:01").is_some());
        assert_eq!(
            ReaderTime::parse("10:00:05"),
            Some(ReaderTime::Clock {
                date: None,
                seconds_of_day: 36005.0
            })
        );
        assert_eq!(ReaderTime::parse("25:00:00"), None);
        assert_eq!(ReaderTime::parse("2015/13/25 21:11:26"), None);
    }

    #[test]
    fn civil_dates() {
        assert_eq!(format_reader_time(0), "1970/01/01 00:00:00");
        // 2026-11-21T10:00:01Z
        assert_eq!(format_reader_time(1_795_255_201), "2026/11/21 10:00:01");
        assert_eq!(format_reader_time(951_782_400), "2000/02/29 00:00:00");
        assert_eq!(
            unix_from_civil(2026, 11, 21, 36001.0),
            Some(1_795_255_201.0)
        );
        assert_eq!(unix_from_civil(2000, 2, 29, 0.0), Some(951_782_400.0));
    }
}
