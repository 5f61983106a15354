//! What the robot tells a fleet manager it is: the `factsheet` content.

use rfloc_vda5050::messages::{
    AgvClass, AgvGeometry, AgvKinematic, Envelope2d, LoadSpecification, LocalizationType,
    MaxArrayLens, MaxStringLens, NavigationType, OptionalParameter, PhysicalParameters,
    PolygonPoint, ProtocolFeatures, ProtocolLimits, Support, Timing, TypeSpecification,
    VehicleConfigInfo, VersionInfo, WheelDefinition, WheelPosition, WheelType,
};
use rfloc_vda5050::FactsheetContent;

use crate::config::{EstimatorConfig, FleetConfig};

/// A Pioneer P3-DX class base: length, width, height (m), wheel diameter and track (m).
const LENGTH_M: f64 = 0.455;
const WIDTH_M: f64 = 0.381;
const HEIGHT_M: f64 = 0.237;
const WHEEL_DIAMETER_M: f64 = 0.195;
const TRACK_M: f64 = 0.33;

/// The speed the pipeline drives at most, m/s.
fn speed_max(estimator: &EstimatorConfig) -> f64 {
    match estimator {
        EstimatorConfig::Ekfslam(e) => e.max_speed_mps,
        EstimatorConfig::Emitter(e) => e.drive_speed_mps,
        // The seed's Table 4 forward action, as the goal drive scales it.
        EstimatorConfig::Snapshot(s) if s.drive_duration_s > 0.0 => {
            (2.5 * s.action_duration_s / s.drive_duration_s).min(1.2)
        }
        _ => 0.5,
    }
}

fn localization_types(estimator: &EstimatorConfig) -> Vec<LocalizationType> {
    match estimator {
        EstimatorConfig::Hfgrid(_) | EstimatorConfig::Snapshot(_) => vec![LocalizationType::Rfid],
        // Radio beacons and a radio emitter: fixed references the robot measures.
        EstimatorConfig::Ekfslam(_) => vec![LocalizationType::Reflector],
        EstimatorConfig::Emitter(_) | EstimatorConfig::Odometry => {
            vec![LocalizationType::Natural]
        }
    }
}

/// The factsheet content of a robot running `estimator` (its `agvActions` are filled in from
/// the vehicle's supported actions by the caller).
#[must_use]
pub fn content(fleet: &FleetConfig, estimator: &EstimatorConfig, drives: bool) -> FactsheetContent {
    let half_l = LENGTH_M / 2.0;
    let half_w = WIDTH_M / 2.0;
    let node_position = OptionalParameter {
        parameter: "order.nodes.nodePosition".to_owned(),
        support: Support::Required,
        description: Some("the robot drives to node positions only".to_owned()),
    };
    FactsheetContent {
        type_specification: TypeSpecification {
            series_name: format!("rfloc {}", estimator.name()),
            series_description: Some(if drives {
                format!(
                    "Pioneer-class base localised by rfloc's {} pipeline; drives to node positions",
                    estimator.name()
                )
            } else {
                format!(
                    "Pioneer-class base localised by rfloc's {} pipeline; cannot drive orders",
                    estimator.name()
                )
            }),
            agv_kinematic: AgvKinematic::Diff,
            agv_class: AgvClass::Carrier,
            max_load_mass: 0.0,
            localization_types: localization_types(estimator),
            navigation_types: vec![NavigationType::Autonomous],
        },
        physical_parameters: PhysicalParameters {
            speed_min: 0.05,
            speed_max: speed_max(estimator),
            angular_speed_min: None,
            angular_speed_max: Some(0.8),
            acceleration_max: 0.3,
            deceleration_max: 0.3,
            height_min: HEIGHT_M,
            height_max: HEIGHT_M,
            width: WIDTH_M,
            length: LENGTH_M,
        },
        protocol_limits: ProtocolLimits {
            max_string_lens: MaxStringLens::default(),
            max_array_lens: MaxArrayLens::default(),
            timing: Timing {
                min_order_interval: 0.5,
                min_state_interval: 0.1,
                default_state_interval: Some(fleet.state_interval_s),
                visualization_interval: (fleet.visualization_hz > 0.0)
                    .then(|| 1.0 / fleet.visualization_hz),
            },
        },
        protocol_features: ProtocolFeatures {
            optional_parameters: vec![node_position],
            agv_actions: Vec::new(),
        },
        agv_geometry: AgvGeometry {
            wheel_definitions: Some(
                [1.0, -1.0]
                    .iter()
                    .map(|side| WheelDefinition {
                        wheel_type: WheelType::Drive,
                        is_active_driven: true,
                        is_active_steered: false,
                        position: WheelPosition {
                            x: 0.0,
                            y: side * TRACK_M / 2.0,
                            theta: None,
                        },
                        diameter: WHEEL_DIAMETER_M,
                        width: 0.05,
                        center_displacement: None,
                        constraints: None,
                    })
                    .collect(),
            ),
            envelopes2d: Some(vec![Envelope2d {
                set: "base".to_owned(),
                polygon_points: vec![
                    PolygonPoint {
                        x: half_l,
                        y: half_w,
                    },
                    PolygonPoint {
                        x: -half_l,
                        y: half_w,
                    },
                    PolygonPoint {
                        x: -half_l,
                        y: -half_w,
                    },
                    PolygonPoint {
                        x: half_l,
                        y: -half_w,
                    },
                ],
                description: None,
            }]),
            envelopes3d: None,
        },
        load_specification: LoadSpecification::default(),
        vehicle_config: Some(VehicleConfigInfo {
            versions: Some(vec![
                VersionInfo {
                    key: "rfloc".to_owned(),
                    value: env!("CARGO_PKG_VERSION").to_owned(),
                },
                VersionInfo {
                    key: "pipeline".to_owned(),
                    value: estimator.name().to_owned(),
                },
            ]),
            network: None,
        }),
    }
}
