//! Runs a sweep: turn the antenna, probe RSSI at each stop, estimate.

use rfloc_stepper::AntennaRotator;
use serde::{Deserialize, Serialize};
use tracing::{debug, info_span, warn, Instrument};

use crate::estimate::{estimate_sweep, EstimatorConfig, SweepReport};
use crate::planner::{PlanError, SweepPlanConfig, SweepPlanner};
use crate::probe::RssiProbe;
use crate::sweep::{Sweep, SweepSample};

/// Settings of a scan (one `[bearing]` table).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanConfig {
    /// Stops.
    pub plan: SweepPlanConfig,
    /// Probe rounds per stop.
    pub probes_per_stop: u32,
    /// Failed probe rounds tolerated per sweep before the sweep is abandoned.
    pub max_probe_failures: u32,
    /// Estimation.
    pub estimator: EstimatorConfig,
}

impl Default for ScanConfig {
    fn default() -> Self {
        Self {
            plan: SweepPlanConfig::default(),
            probes_per_stop: 1,
            max_probe_failures: 3,
            estimator: EstimatorConfig::default(),
        }
    }
}

/// Why a sweep was abandoned.
#[derive(Debug, thiserror::Error)]
pub enum ScanError<RE, PE>
where
    RE: std::error::Error + 'static,
    PE: std::error::Error + 'static,
{
    /// The antenna could not be moved.
    #[error("rotator: {0}")]
    Rotator(#[source] RE),
    /// Too many probe rounds failed; the last error.
    #[error("RSSI probe failed {failures} times: {last}")]
    Probe {
        /// Failed rounds in this sweep.
        failures: u32,
        /// The last failure.
        #[source]
        last: PE,
    },
}

/// A finished sweep and what was estimated from it.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanResult {
    /// The raw sweep (reached antenna angles, headings, readings).
    pub sweep: Sweep,
    /// Per-beacon estimates.
    pub report: SweepReport,
    /// Probe rounds that failed but were tolerated.
    pub probe_failures: u32,
}

/// Turns the antenna through a sweep and probes RSSI at every stop.
#[derive(Debug)]
pub struct ScanRunner<R, P> {
    rotator: R,
    probe: P,
    planner: SweepPlanner,
    config: ScanConfig,
}

impl<R: AntennaRotator, P: RssiProbe> ScanRunner<R, P> {
    /// A runner whose first sweep is ascending.
    pub fn new(rotator: R, probe: P, config: ScanConfig) -> Result<Self, PlanError> {
        Ok(Self {
            rotator,
            probe,
            planner: SweepPlanner::new(config.plan)?,
            config,
        })
    }

    /// The rotator (e.g. to home it).
    pub fn rotator_mut(&mut self) -> &mut R {
        &mut self.rotator
    }

    /// The probe.
    pub fn probe_mut(&mut self) -> &mut P {
        &mut self.probe
    }

    /// Gives back the rotator and the probe.
    pub fn into_parts(self) -> (R, P) {
        (self.rotator, self.probe)
    }

    /// Runs one sweep. `heading` is called once per stop, after the antenna has stopped, and
    /// returns the robot heading in radians at that moment.
    pub async fn scan<H: FnMut() -> f64>(
        &mut self,
        mut heading: H,
    ) -> Result<ScanResult, ScanError<R::Error, P::Error>> {
        let stops = self.planner.next_sweep();
        let span = info_span!("bearing_scan", stops = stops.len());
        async move {
            let mut sweep = Sweep::default();
            let mut failures = 0u32;
            for target in stops {
                let reached = self
                    .rotator
                    .move_to(target)
                    .await
                    .map_err(ScanError::Rotator)?;
                let heading_rad = heading();
                let mut readings = Vec::new();
                for _ in 0..self.config.probes_per_stop.max(1) {
                    match self.probe.rssi_all().await {
                        Ok(r) => readings.extend(r),
                        Err(e) => {
                            failures += 1;
                            warn!(error = %e, failures, "RSSI probe failed");
                            if failures > self.config.max_probe_failures {
                                return Err(ScanError::Probe { failures, last: e });
                            }
                        }
                    }
                }
                debug!(target, reached, heard = readings.len(), "stop");
                sweep.samples.push(SweepSample {
                    antenna_rad: reached,
                    heading_rad,
                    readings,
                });
            }
            let report = estimate_sweep(&sweep, &self.config.estimator);
            Ok(ScanResult {
                sweep,
                report,
                probe_failures: failures,
            })
        }
        .instrument(span)
        .await
    }
}
