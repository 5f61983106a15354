//! Which scenario keys each pipeline's trial acts on. A key written in a scenario file that
//! the chosen pipeline does not use is rejected on load (`file:line: invalid `key``), so a
//! scenario never looks as if it set something it does not.
//!
//! Only keys written in the file are checked: defaults the file leaves alone are not settings.
//! Patterns end in `.*` for "every field of this table".

use crate::scenario::Pipeline;

/// Keys every pipeline uses (scenario header, start, world).
const COMMON: &[&str] = &[
    "name",
    "description",
    "source",
    "seed_reference",
    "pipeline",
    "world_file",
    "world",
    "world.*",
    "duration_s",
    "dt_s",
    "trials",
    "seed",
    "robot.start",
    "robot.start.*",
    "robot.random_start",
    "robot.start_headings_deg",
];

/// Seed 000 (`rfloc-lab` `scenario::snapshot`): Table 4's action noise and limits, the body
/// for collisions, the UHF reader model, goals, exploration and navigation steps.
const SNAPSHOT: &[&str] = &[
    "robot.drive.sigma_v",
    "robot.drive.sigma_omega",
    "robot.drive.max_speed",
    "robot.drive.max_turn_rate",
    "robot.drive.body_radius",
    "sensors.uhf.*",
    "goal.*",
    "params.exploration_steps",
    "params.navigation_steps",
    "params.action_duration_s",
];

/// Seed 001: the body (collisions, avoidance distance), the four receivers' model, the laser's
/// range, noise and mounting (the URG emulator has its own 682 steps over 240°), the filter and
/// grid settings, the goal and the model mismatch.
const EMITTER: &[&str] = &[
    "robot.drive.body_radius",
    "sensors.emitter.*",
    "sensors.scanner.max_range",
    "sensors.scanner.noise_sigma",
    "sensors.scanner.mount_offset",
    "goal.*",
    "params.particles",
    "params.grid_cell_m",
    "params.range_offset_m",
    "params.angle_offset_deg",
    "mismatch.*",
];

/// Seed 002: the turn rate, the HF reader model, readings per turn and the model mismatch.
const HF_INIT: &[&str] = &[
    "robot.drive.max_turn_rate",
    "sensors.hf.*",
    "params.readings_per_turn",
    "mismatch.*",
];

/// Seed 003: odometry error (wheel slip, Table 3.1's σ_v and σ_ω, the axle track that splits
/// the wheel travels, the wheel diameter against the base's 0.195 m calibration), the body
/// (walls), the XBee model, sweep steps, waypoints and switching distance, model mismatch.
const EKF_SLAM: &[&str] = &[
    "robot.drive.sigma_v",
    "robot.drive.sigma_omega",
    "robot.drive.slip_sigma",
    "robot.drive.axle_track",
    "robot.drive.wheel_diameter",
    "robot.drive.body_radius",
    "sensors.xbee.*",
    "params.sweep_steps",
    "params.sweep_every_s",
    "params.waypoint_switch_m",
    "waypoints",
    "mismatch.*",
];

/// Why a key is not used, for the error message (the first matching prefix).
const WHY: &[(&str, &str)] = &[
    (
        "sensors.xbee_range_bearing",
        "no trial draws Table 3.1's range/bearing noise: the ekf-slam trial measures range \
         (RSSI) and bearing from simulated reflector sweeps (`sensors.xbee`)",
    ),
    (
        "params.iterations",
        "no pipeline has an iteration count (the EKF predicts on every odometry tick and \
         updates on every sweep; the trial ends at duration_s or the last waypoint)",
    ),
    (
        "robot.drive.slip_mean",
        "only the ekf-slam trial applies wheel slip, as a zero-mean error (`slip_sigma`)",
    ),
    (
        "sensors.scanner",
        "the emitter trial's laser is the URG emulator (682 steps over 240°); only \
         `max_range`, `noise_sigma` and `mount_offset` act",
    ),
    (
        "mismatch",
        "the seed 000 snapshot trial has no model-mismatch option",
    ),
];

/// The keys `pipeline` acts on (beyond [`COMMON`]).
#[must_use]
pub fn acting(pipeline: Pipeline) -> &'static [&'static str] {
    match pipeline {
        Pipeline::Snapshot => SNAPSHOT,
        Pipeline::EmitterPreliminary | Pipeline::EmitterFull => EMITTER,
        Pipeline::HfInit => HF_INIT,
        Pipeline::EkfSlam => EKF_SLAM,
    }
}

fn matches(pattern: &str, key: &str) -> bool {
    match pattern.strip_suffix(".*") {
        Some(prefix) => key
            .strip_prefix(prefix)
            .is_some_and(|rest| rest.starts_with('.')),
        None => pattern == key,
    }
}

/// True when `pipeline` acts on the written key `key` (a dotted path).
#[must_use]
pub fn is_acting(pipeline: Pipeline, key: &str) -> bool {
    COMMON
        .iter()
        .chain(acting(pipeline))
        .any(|p| matches(p, key))
}

/// The explanation for a key `pipeline` does not act on.
#[must_use]
pub fn why_not(pipeline: Pipeline, key: &str) -> String {
    let reason = WHY
        .iter()
        .find(|(prefix, _)| key == *prefix || key.starts_with(&format!("{prefix}.")))
        .map(|(_, why)| format!(": {why}"))
        .unwrap_or_default();
    format!(
        "the {} trial does not use this key{reason}",
        pipeline_name(pipeline)
    )
}

/// The pipeline's name as written in scenario files.
#[must_use]
pub fn pipeline_name(pipeline: Pipeline) -> &'static str {
    match pipeline {
        Pipeline::Snapshot => "snapshot",
        Pipeline::EmitterPreliminary => "emitter-preliminary",
        Pipeline::EmitterFull => "emitter-full",
        Pipeline::HfInit => "hf-init",
        Pipeline::EkfSlam => "ekf-slam",
    }
}

/// Every leaf key written in a scenario table, as dotted paths (`robot.drive.sigma_v`,
/// `sensors.hf.curve`, `waypoints`); inline tables are walked like tables, arrays are leaves.
#[must_use]
pub fn written(table: &toml::Table) -> Vec<String> {
    fn walk(prefix: &str, t: &toml::Table, out: &mut Vec<String>) {
        for (k, v) in t {
            let path = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            match v {
                // The world is validated by its own schema; a reflector pattern is one value.
                toml::Value::Table(inner) if path != "world" && !path.ends_with(".pattern") => {
                    walk(&path, inner, out);
                }
                _ => out.push(path),
            }
        }
    }
    let mut out = Vec::new();
    walk("", table, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_match_whole_segments() {
        assert!(matches("sensors.hf.*", "sensors.hf.curve"));
        assert!(!matches("sensors.hf.*", "sensors.hfx.curve"));
        assert!(!matches("sensors.hf.*", "sensors.hf"));
        assert!(is_acting(Pipeline::EkfSlam, "robot.drive.sigma_v"));
        assert!(!is_acting(Pipeline::EmitterFull, "robot.drive.sigma_v"));
        assert!(!is_acting(Pipeline::EkfSlam, "params.iterations"));
        assert!(why_not(Pipeline::EkfSlam, "params.iterations").contains("iteration count"));
    }

    #[test]
    fn written_keys_walk_inline_tables() {
        let t: toml::Table = toml::from_str(
            "name = \"x\"\n[robot]\nstart = { x = 1.0, y = 2.0 }\ndrive = { sigma_v = 0.1 }\n[world]\narea = { min = [0, 0], max = [1, 1] }\n",
        )
        .unwrap_or_default();
        let w = written(&t);
        assert!(w.contains(&"robot.drive.sigma_v".to_string()), "{w:?}");
        assert!(w.contains(&"robot.start.x".to_string()), "{w:?}");
        assert!(w.contains(&"world".to_string()), "{w:?}");
    }
}
