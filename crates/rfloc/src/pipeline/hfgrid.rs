//! HF floor-grid pipeline (filled in when the estimator lands).

use rfloc_pose::PoseEstimate;

use crate::config::HfGridSettings;
use crate::events::DeviceEvent;
use crate::pipeline::Pipeline;

/// Initial pose from a 360° turn over the tag grid, then tracking.
#[derive(Debug)]
pub struct HfGridPipeline {
    _settings: HfGridSettings,
}

impl HfGridPipeline {
    #[must_use]
    pub fn new(settings: &HfGridSettings) -> Self {
        Self {
            _settings: settings.clone(),
        }
    }
}

impl Pipeline for HfGridPipeline {
    fn name(&self) -> &'static str {
        "hfgrid"
    }

    fn handle(&mut self, _event: &DeviceEvent) -> Option<PoseEstimate> {
        None
    }
}
