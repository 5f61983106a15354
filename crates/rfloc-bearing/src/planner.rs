//! Antenna stops of successive sweeps.

use serde::{Deserialize, Serialize};

/// Arc and step of a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SweepPlanConfig {
    /// Centre of the arc relative to the robot's forward direction, degrees.
    pub center_deg: f64,
    /// Width of the arc, degrees; 360 for a full turn.
    pub arc_deg: f64,
    /// Angle between stops, degrees (9° in the seed).
    pub step_deg: f64,
}

impl Default for SweepPlanConfig {
    fn default() -> Self {
        Self {
            center_deg: 0.0,
            arc_deg: 360.0,
            step_deg: 9.0,
        }
    }
}

/// Errors of a sweep plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// Step not in (0, arc] or arc not in (0, 360].
    #[error("bad sweep plan: arc {arc_deg}°, step {step_deg}°")]
    Invalid {
        /// Arc, degrees.
        arc_deg: f64,
        /// Step, degrees.
        step_deg: f64,
    },
}

/// Produces the stops of each sweep, reversing direction every other sweep so that cables to
/// the rotating antenna unwind instead of winding up.
#[derive(Debug, Clone)]
pub struct SweepPlanner {
    stops: Vec<f64>,
    forward: bool,
}

impl SweepPlanner {
    /// Builds the stop list.
    ///
    /// Full turn (`arc_deg` ≥ 360): `round(360/step)` stops from `center − 180°` without
    /// repeating the start. Partial arc: `floor(arc/step) + 1` stops centred on `center_deg`.
    pub fn new(config: SweepPlanConfig) -> Result<Self, PlanError> {
        let SweepPlanConfig {
            center_deg,
            arc_deg,
            step_deg,
        } = config;
        let ok = center_deg.is_finite()
            && arc_deg.is_finite()
            && step_deg.is_finite()
            && arc_deg > 0.0
            && arc_deg <= 360.0 + 1e-9
            && step_deg > 0.0
            && step_deg <= arc_deg
            && arc_deg / step_deg <= 100_000.0;
        if !ok {
            return Err(PlanError::Invalid { arc_deg, step_deg });
        }
        let stops: Vec<f64> = if arc_deg >= 360.0 - 1e-9 {
            let n = (360.0 / step_deg).round().max(1.0) as usize;
            let step = 360.0 / n as f64;
            (0..n)
                .map(|i| (center_deg - 180.0 + i as f64 * step).to_radians())
                .collect()
        } else {
            let n = (arc_deg / step_deg + 1e-9).floor() as usize + 1;
            let start = center_deg - (n - 1) as f64 * step_deg / 2.0;
            (0..n)
                .map(|i| (start + i as f64 * step_deg).to_radians())
                .collect()
        };
        Ok(Self {
            stops,
            forward: true,
        })
    }

    /// Stops of the next sweep, radians; ascending and descending sweeps alternate.
    pub fn next_sweep(&mut self) -> Vec<f64> {
        let mut s = self.stops.clone();
        if !self.forward {
            s.reverse();
        }
        self.forward = !self.forward;
        s
    }

    /// Number of stops per sweep.
    #[must_use]
    pub fn stops_per_sweep(&self) -> usize {
        self.stops.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_plan_is_forty_stops_alternating() {
        let mut p = SweepPlanner::new(SweepPlanConfig::default()).unwrap();
        let a = p.next_sweep();
        let b = p.next_sweep();
        let c = p.next_sweep();
        assert_eq!(a.len(), 40);
        assert!((a[0].to_degrees() + 180.0).abs() < 1e-9);
        assert!((a[39].to_degrees() - 171.0).abs() < 1e-9);
        let mut rev = a.clone();
        rev.reverse();
        assert_eq!(b, rev);
        assert_eq!(c, a);
    }

    #[test]
    fn partial_arc_is_centred() {
        let mut p = SweepPlanner::new(SweepPlanConfig {
            center_deg: 90.0,
            arc_deg: 100.0,
            step_deg: 9.0,
        })
        .unwrap();
        let a: Vec<f64> = p.next_sweep().iter().map(|r| r.to_degrees()).collect();
        assert_eq!(a.len(), 12);
        assert!((a[0] - 40.5).abs() < 1e-9 && (a[11] - 139.5).abs() < 1e-9);
    }

    #[test]
    fn rejects_bad_plans() {
        for (arc, step) in [
            (0.0, 9.0),
            (90.0, 0.0),
            (400.0, 9.0),
            (10.0, 20.0),
            (f64::NAN, 1.0),
        ] {
            let c = SweepPlanConfig {
                center_deg: 0.0,
                arc_deg: arc,
                step_deg: step,
            };
            assert!(SweepPlanner::new(c).is_err(), "{arc} {step}");
        }
    }
}
