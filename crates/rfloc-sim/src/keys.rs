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
/// for collisions, the UHF reader model, goals, exploration and navigation steps, and the model
/// mismatch.
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
    "mismatch.*",
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
/// (walls), the XBee model, sweep steps and cadence, sweeps at the start, waypoints and switching
/// distance, model mismatch.
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
    "params.start_sweeps",
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
];

/// The allowed values of a numeric scenario key: from `low` to `high` (`low` itself excluded
/// when `open_low`), in `unit`. Wide enough for any experiment the models describe; what they
/// keep out is what no robot or radio has (negative noise, a NaN, a million particles).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub low: f64,
    pub high: f64,
    pub open_low: bool,
    pub unit: &'static str,
}

impl Range {
    const fn closed(low: f64, high: f64, unit: &'static str) -> Self {
        Self {
            low,
            high,
            open_low: false,
            unit,
        }
    }

    const fn positive(high: f64, unit: &'static str) -> Self {
        Self {
            low: 0.0,
            high,
            open_low: true,
            unit,
        }
    }

    /// True when `v` is a finite number in the range.
    #[must_use]
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite() && v <= self.high && (v > self.low || (!self.open_low && v == self.low))
    }

    /// What the error says, e.g. `must be a number above 0 and at most 5 m`.
    #[must_use]
    pub fn requirement(&self) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        if self.open_low {
            format!(
                "must be a number above {} and at most {}{unit}",
                self.low, self.high
            )
        } else {
            format!("must be a number from {} to {}{unit}", self.low, self.high)
        }
    }
}

/// The range of every numeric key a scenario may write (outside `[world]`, which its own schema
/// checks). Arrays (`waypoints`, `robot.start_headings_deg`) hold numbers of their key's range.
const RANGES: &[(&str, Range)] = &[
    ("duration_s", Range::positive(1.0e6, "s")),
    ("dt_s", Range::positive(10.0, "s")),
    ("trials", Range::closed(1.0, 10_000.0, "")),
    ("seed", Range::closed(0.0, 9.3e18, "")),
    ("robot.start.x", Range::closed(-1.0e6, 1.0e6, "m")),
    ("robot.start.y", Range::closed(-1.0e6, 1.0e6, "m")),
    ("robot.start.theta_deg", Range::closed(-3600.0, 3600.0, "°")),
    (
        "robot.start_headings_deg",
        Range::closed(-3600.0, 3600.0, "°"),
    ),
    ("robot.drive.sigma_v", Range::closed(0.0, 10.0, "")),
    ("robot.drive.sigma_omega", Range::closed(0.0, 10.0, "")),
    ("robot.drive.slip_sigma", Range::closed(0.0, 1.0, "")),
    ("robot.drive.slip_mean", Range::closed(-1.0, 1.0, "")),
    ("robot.drive.axle_track", Range::positive(5.0, "m")),
    ("robot.drive.wheel_diameter", Range::positive(2.0, "m")),
    ("robot.drive.body_radius", Range::positive(5.0, "m")),
    ("robot.drive.max_speed", Range::positive(10.0, "m/s")),
    ("robot.drive.max_turn_rate", Range::positive(20.0, "rad/s")),
    ("goal.x", Range::closed(-1.0e6, 1.0e6, "m")),
    ("goal.y", Range::closed(-1.0e6, 1.0e6, "m")),
    ("goal.tolerance_m", Range::positive(100.0, "m")),
    ("waypoints", Range::closed(-1.0e6, 1.0e6, "m")),
    (
        "sensors.uhf.threshold",
        Range::closed(0.0, 1.0e6, "RSS units"),
    ),
    (
        "sensors.uhf.behind_attenuation",
        Range::closed(0.0, 1.0e6, ""),
    ),
    (
        "sensors.uhf.noise_sigma",
        Range::closed(0.0, 1.0e6, "RSS units"),
    ),
    ("sensors.uhf.dropout", Range::closed(0.0, 0.99, "")),
    ("sensors.uhf.antenna_offset", Range::closed(-1.0, 1.0, "m")),
    (
        "sensors.hf.spread_levels",
        Range::closed(0.0, 7.0, "levels"),
    ),
    ("sensors.hf.antenna_offset", Range::closed(0.0, 0.5, "m")),
    ("sensors.hf.miss_probability", Range::closed(0.0, 0.99, "")),
    (
        "sensors.hf.placement_sigma_m",
        Range::closed(0.0, 0.05, "m"),
    ),
    ("sensors.xbee.p_ref_dbm", Range::closed(-150.0, 30.0, "dBm")),
    ("sensors.xbee.eta", Range::closed(0.5, 10.0, "")),
    (
        "sensors.xbee.shadow_sigma_db",
        Range::closed(0.0, 30.0, "dB"),
    ),
    ("sensors.xbee.fast_sigma_db", Range::closed(0.0, 30.0, "dB")),
    (
        "sensors.xbee.sensitivity_dbm",
        Range::closed(-200.0, 0.0, "dBm"),
    ),
    ("sensors.xbee.pattern.exponent", Range::positive(1000.0, "")),
    (
        "sensors.xbee.pattern.back_lobe_db",
        Range::closed(-100.0, 0.0, "dB"),
    ),
    (
        "sensors.emitter.reference_loss_db",
        Range::closed(0.0, 200.0, "dB"),
    ),
    (
        "sensors.emitter.path_loss_exponent",
        Range::closed(0.5, 10.0, ""),
    ),
    (
        "sensors.emitter.multipath_sigma_db",
        Range::closed(0.0, 30.0, "dB"),
    ),
    (
        "sensors.emitter.wall_loss_db",
        Range::closed(0.0, 100.0, "dB"),
    ),
    (
        "sensors.emitter.sensitivity_dbm",
        Range::closed(-200.0, 0.0, "dBm"),
    ),
    (
        "sensors.emitter.spatial_fading_sigma_db",
        Range::closed(0.0, 30.0, "dB"),
    ),
    (
        "sensors.emitter.pattern.exponent",
        Range::positive(1000.0, ""),
    ),
    (
        "sensors.emitter.pattern.back_lobe_db",
        Range::closed(-100.0, 0.0, "dB"),
    ),
    ("sensors.scanner.max_range", Range::positive(100.0, "m")),
    ("sensors.scanner.noise_sigma", Range::closed(0.0, 1.0, "m")),
    (
        "sensors.scanner.mount_offset",
        Range::closed(-2.0, 2.0, "m"),
    ),
    ("params.exploration_steps", Range::closed(1.0, 1.0e7, "")),
    ("params.navigation_steps", Range::closed(1.0, 1.0e7, "")),
    ("params.action_duration_s", Range::positive(60.0, "s")),
    ("params.readings_per_turn", Range::closed(3.0, 360.0, "")),
    ("params.sweep_steps", Range::closed(3.0, 3600.0, "")),
    ("params.sweep_every_s", Range::closed(0.5, 600.0, "s")),
    ("params.start_sweeps", Range::closed(1.0, 1000.0, "")),
    ("params.waypoint_switch_m", Range::closed(0.01, 10.0, "m")),
    ("params.particles", Range::closed(1.0, 100_000.0, "")),
    ("params.grid_cell_m", Range::closed(0.01, 2.0, "m")),
    ("params.range_offset_m", Range::closed(-100.0, 100.0, "m")),
    ("params.angle_offset_deg", Range::closed(-180.0, 180.0, "°")),
    ("mismatch.scale", Range::closed(0.2, 5.0, "")),
];

/// The range of numeric key `key` (a dotted path), if it has one.
#[must_use]
pub fn range_of(key: &str) -> Option<&'static Range> {
    RANGES.iter().find(|(k, _)| *k == key).map(|(_, r)| r)
}

/// Every number written in a scenario table outside `[world]`, with its dotted key: inline
/// tables are walked (a reflector pattern's fields too), arrays give each of their numbers
/// (nested arrays too) under the array's key.
#[must_use]
pub fn numbers(table: &toml::Table) -> Vec<(String, f64)> {
    fn value(path: &str, v: &toml::Value, out: &mut Vec<(String, f64)>) {
        match v {
            #[allow(clippy::cast_precision_loss)]
            toml::Value::Integer(i) => out.push((path.to_string(), *i as f64)),
            toml::Value::Float(f) => out.push((path.to_string(), *f)),
            toml::Value::Array(items) => items.iter().for_each(|i| value(path, i, out)),
            toml::Value::Table(t) => walk(path, t, out),
            _ => {}
        }
    }
    fn walk(prefix: &str, t: &toml::Table, out: &mut Vec<(String, f64)>) {
        for (k, v) in t {
            let path = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            if path != "world" {
                value(&path, v, out);
            }
        }
    }
    let mut out = Vec::new();
    walk("", table, &mut out);
    out
}

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
