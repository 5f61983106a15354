//! A distance scan from a `GD` reply, and the sensor geometry that turns steps into angles.

use crate::encoding::decode;
use crate::error::ScipError;
use crate::reply::Reply;

/// Step geometry and range limits of a URG sensor (the `PP` parameters). The defaults are the
/// URG-04LX's: 1024 steps per turn, front at step 384, steps 44–725 measured (240°), 20 mm to
/// 5600 mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UrgGeometry {
    /// `ARES`: steps per full turn.
    pub steps_per_rev: u16,
    /// `AFRT`: the step straight ahead.
    pub front_step: u16,
    /// `AMIN`, `AMAX`: first and last measured step.
    pub first_step: u16,
    pub last_step: u16,
    /// `DMIN`, `DMAX`: shortest and longest valid range, mm. Values below `DMIN` are error
    /// codes (no echo, low intensity, …).
    pub min_mm: u32,
    pub max_mm: u32,
}

impl Default for UrgGeometry {
    fn default() -> Self {
        Self {
            steps_per_rev: 1024,
            front_step: 384,
            first_step: 44,
            last_step: 725,
            min_mm: 20,
            max_mm: 5600,
        }
    }
}

impl UrgGeometry {
    /// The angle of `step` from straight ahead, radians, counter-clockwise positive.
    #[must_use]
    pub fn angle(&self, step: f64) -> f64 {
        (step - f64::from(self.front_step)) * std::f64::consts::TAU
            / f64::from(self.steps_per_rev.max(1))
    }
}

/// One scan: the range of each (clustered) step, mm, as the sensor reported it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scan {
    pub start_step: u16,
    pub end_step: u16,
    pub cluster: u8,
    /// The sensor's time stamp of the scan's first step, ms (24-bit counter).
    pub timestamp_ms: u32,
    /// One value per cluster; below the geometry's `min_mm` it is an error code.
    pub ranges_mm: Vec<u32>,
}

impl Scan {
    /// The scan a successful `GD` reply carries.
    ///
    /// # Errors
    /// A reply of another kind, an error status, an echo whose fields are not numbers, data
    /// that is not a whole number of three-character values, or a count that does not match
    /// the requested steps.
    pub fn from_reply(reply: &Reply) -> Result<Self, ScipError> {
        let echo = &reply.echo;
        let field = |range: std::ops::Range<usize>| -> Option<u16> {
            std::str::from_utf8(echo.get(range)?).ok()?.parse().ok()
        };
        // Three characters per value for GD and MD, two for GS and MS.
        let width = match echo.get(..2) {
            Some(b"GD" | b"MD") => 3,
            Some(b"GS" | b"MS") => 2,
            _ => 0,
        };
        let (Some(start), Some(end), Some(cluster)) = (
            (width > 0).then(|| field(2..6)).flatten(),
            field(6..10),
            field(10..12),
        ) else {
            return Err(ScipError::Malformed {
                why: "not a GD, GS, MD or MS echo",
                bytes: echo.clone(),
            });
        };
        if !reply.ok() {
            return Err(ScipError::Status {
                echo: echo.clone(),
                status: reply.status,
            });
        }
        let cluster = u8::try_from(cluster.max(1)).unwrap_or(1);
        if !reply.data.len().is_multiple_of(width) || end < start {
            return Err(ScipError::Malformed {
                why: "data is not whole values of the echo's width",
                bytes: reply.data.clone(),
            });
        }
        let ranges_mm = reply
            .data
            .chunks(width)
            .map(|c| decode(c).ok_or_else(|| ScipError::Encoding { chars: c.to_vec() }))
            .collect::<Result<Vec<u32>, _>>()?;
        let expected = usize::from(end - start) / usize::from(cluster) + 1;
        if ranges_mm.len() != expected {
            return Err(ScipError::Malformed {
                why: "value count does not match the requested steps",
                bytes: reply.data.clone(),
            });
        }
        Ok(Self {
            start_step: start,
            end_step: end,
            cluster,
            timestamp_ms: reply.timestamp_ms.unwrap_or(0),
            ranges_mm,
        })
    }

    /// Each value's angle (the middle of its cluster) and range in metres; `None` for an error
    /// code or a value beyond the geometry's limits.
    pub fn beams<'a>(
        &'a self,
        geometry: &'a UrgGeometry,
    ) -> impl Iterator<Item = (f64, Option<f64>)> + 'a {
        let c = f64::from(self.cluster);
        self.ranges_mm.iter().enumerate().map(move |(i, &mm)| {
            let step = f64::from(self.start_step) + i as f64 * c + (c - 1.0) / 2.0;
            let valid = (geometry.min_mm..=geometry.max_mm).contains(&mm);
            (geometry.angle(step), valid.then(|| f64::from(mm) / 1000.0))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reply(echo: &[u8], data: &[u8]) -> Reply {
        Reply {
            echo: echo.to_vec(),
            status: *b"00",
            timestamp_ms: Some(5),
            data: data.to_vec(),
            lines: Vec::new(),
        }
    }

    #[test]
    fn a_gd_reply_becomes_ranges_and_angles() {
        // Steps 383..385 around the front: 5432 mm, 1234 mm, error code 1.
        let scan = Scan::from_reply(&reply(b"GD0383038501", b"1Dh0CB001")).unwrap();
        assert_eq!(scan.ranges_mm, vec![5432, 1234, 1]);
        let g = UrgGeometry::default();
        let beams: Vec<_> = scan.beams(&g).collect();
        assert!((beams[1].0).abs() < 1e-12, "step 384 is straight ahead");
        assert!(
            (beams[0].0 + std::f64::consts::TAU / 1024.0).abs() < 1e-12,
            "383 to the right"
        );
        assert_eq!(
            (beams[0].1, beams[1].1, beams[2].1),
            (Some(5.432), Some(1.234), None)
        );
    }

    #[test]
    fn the_urg_04lx_field_spans_240_degrees() {
        let g = UrgGeometry::default();
        let span = g.angle(f64::from(g.last_step)) - g.angle(f64::from(g.first_step));
        // 681 steps of 360°/1024.
        assert!(
            (span.to_degrees() - 239.414).abs() < 0.001,
            "{}",
            span.to_degrees()
        );
    }

    #[test]
    fn counts_statuses_and_echoes_are_checked() {
        assert!(
            Scan::from_reply(&reply(b"GD0383038501", b"1Dh0CB")).is_err(),
            "two of three"
        );
        assert!(
            Scan::from_reply(&reply(b"GD0383038501", b"1Dh0CB00")).is_err(),
            "ragged"
        );
        assert!(Scan::from_reply(&reply(b"BM", b"")).is_err());
        let mut r = reply(b"GD0383038501", b"");
        r.status = *b"10";
        assert!(matches!(
            Scan::from_reply(&r),
            Err(ScipError::Status { .. })
        ));
        // Cluster 2 over steps 383..386: two values.
        let s = Scan::from_reply(&reply(b"GD0383038602", b"1Dh0CB")).unwrap();
        assert_eq!(s.ranges_mm.len(), 2);
    }
}
