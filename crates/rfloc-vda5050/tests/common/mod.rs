//! Helpers shared by the integration tests: schema validators, sample messages, generators.
#![allow(dead_code, clippy::unwrap_used)] // shared helpers outside #[test] fns

use std::f64::consts::PI;

use proptest::prelude::*;
use rfloc_vda5050::messages::*;
use rfloc_vda5050::{FactsheetContent, Timestamp, VehicleConfig};
use serde_json::Value;

pub const MANUFACTURER: &str = "rfloc";
pub const SERIAL: &str = "robot-7";

/// A validator for `schemas/{name}.schema`, with `format` (date-time) checked.
pub fn validator(name: &str) -> jsonschema::Validator {
    let path = format!("{}/schemas/{name}.schema", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    let schema: Value = serde_json::from_str(&text).unwrap();
    jsonschema::options()
        .should_validate_formats(true)
        .build(&schema)
        .unwrap()
}

/// Panics with every schema error if `instance` does not validate against schema `name`.
pub fn assert_valid(name: &str, instance: &Value) {
    let v = validator(name);
    let errors: Vec<String> = v
        .iter_errors(instance)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect();
    assert!(
        errors.is_empty(),
        "{name} schema errors: {errors:#?}\n{instance:#}"
    );
}

pub fn t(ms: u64) -> Timestamp {
    Timestamp::from_unix_millis(1_700_000_000_000 + ms).unwrap()
}

pub fn header(id: u32) -> Header {
    Header {
        header_id: id,
        timestamp: "2024-01-01T12:00:00.000Z".to_owned(),
        version: "2.1.0".to_owned(),
        manufacturer: MANUFACTURER.to_owned(),
        serial_number: SERIAL.to_owned(),
    }
}

pub fn config() -> VehicleConfig {
    VehicleConfig::new(MANUFACTURER, SERIAL)
}

pub fn pos(x: f64, y: f64) -> NodePosition {
    NodePosition {
        x,
        y,
        theta: None,
        allowed_deviation_xy: None,
        allowed_deviation_theta: None,
        map_id: "hall".to_owned(),
        map_description: None,
    }
}

pub fn node(id: &str, seq: u32, released: bool, x: f64, y: f64) -> Node {
    Node {
        node_id: id.to_owned(),
        sequence_id: seq,
        node_description: None,
        released,
        node_position: Some(pos(x, y)),
        actions: Vec::new(),
    }
}

pub fn edge(id: &str, seq: u32, released: bool, from: &str, to: &str) -> Edge {
    Edge {
        edge_id: id.to_owned(),
        sequence_id: seq,
        edge_description: None,
        released,
        start_node_id: from.to_owned(),
        end_node_id: to.to_owned(),
        max_speed: None,
        max_height: None,
        min_height: None,
        orientation: None,
        orientation_type: None,
        direction: None,
        rotation_allowed: None,
        max_rotation_speed: None,
        trajectory: None,
        length: None,
        corridor: None,
        actions: Vec::new(),
    }
}

/// An order along the x axis: node i at (i, 0) with sequenceId `first_seq + 2 i`, edges between;
/// the first `released` nodes are the base.
pub fn line_order(
    order_id: &str,
    update: u32,
    ids: &[&str],
    first_seq: u32,
    first_x: f64,
    released: usize,
) -> Order {
    let mut nodes = Vec::new();
    let mut edges = Vec::new();
    for (i, id) in ids.iter().enumerate() {
        let i32_ = u32::try_from(i).unwrap();
        nodes.push(node(
            id,
            first_seq + 2 * i32_,
            i < released,
            first_x + i as f64,
            0.0,
        ));
        if i + 1 < ids.len() {
            edges.push(edge(
                &format!("e{}{}", id, ids[i + 1]),
                first_seq + 2 * i32_ + 1,
                i + 1 < released,
                id,
                ids[i + 1],
            ));
        }
    }
    Order {
        header: header(update),
        order_id: order_id.to_owned(),
        order_update_id: update,
        zone_set_id: None,
        nodes,
        edges,
    }
}

pub fn action(id: &str, kind: &str, blocking: BlockingType) -> Action {
    Action {
        action_type: kind.to_owned(),
        action_id: id.to_owned(),
        action_description: None,
        blocking_type: blocking,
        action_parameters: None,
    }
}

pub fn instant(id: u32, actions: Vec<Action>) -> InstantActions {
    InstantActions {
        header: header(id),
        actions,
    }
}

pub fn factsheet_content() -> FactsheetContent {
    FactsheetContent {
        type_specification: TypeSpecification {
            series_name: "rfloc-p3".to_owned(),
            series_description: Some("research platform".to_owned()),
            agv_kinematic: AgvKinematic::Diff,
            agv_class: AgvClass::Carrier,
            max_load_mass: 20.0,
            localization_types: vec![LocalizationType::Natural, LocalizationType::Reflector],
            navigation_types: vec![NavigationType::Autonomous],
        },
        physical_parameters: PhysicalParameters {
            speed_min: 0.05,
            speed_max: 1.2,
            angular_speed_min: None,
            angular_speed_max: Some(2.0),
            acceleration_max: 0.5,
            deceleration_max: 1.0,
            height_min: 0.25,
            height_max: 0.25,
            width: 0.5,
            length: 0.6,
        },
        protocol_limits: ProtocolLimits {
            max_string_lens: MaxStringLens {
                id_len: Some(64),
                ..MaxStringLens::default()
            },
            max_array_lens: MaxArrayLens {
                order_nodes: Some(100),
                order_edges: Some(99),
                state_information: Some(10),
                ..MaxArrayLens::default()
            },
            timing: Timing {
                min_order_interval: 0.5,
                min_state_interval: 0.2,
                default_state_interval: Some(30.0),
                visualization_interval: Some(0.1),
            },
        },
        protocol_features: ProtocolFeatures {
            optional_parameters: vec![OptionalParameter {
                parameter: "order.nodes.nodePosition".to_owned(),
                support: Support::Required,
                description: None,
            }],
            agv_actions: Vec::new(),
        },
        agv_geometry: AgvGeometry {
            wheel_definitions: Some(vec![WheelDefinition {
                wheel_type: WheelType::Drive,
                is_active_driven: true,
                is_active_steered: false,
                position: WheelPosition {
                    x: 0.0,
                    y: 0.2,
                    theta: None,
                },
                diameter: 0.2,
                width: 0.05,
                center_displacement: None,
                constraints: None,
            }]),
            envelopes2d: Some(vec![Envelope2d {
                set: "default".to_owned(),
                polygon_points: vec![
                    PolygonPoint { x: 0.3, y: 0.25 },
                    PolygonPoint { x: -0.3, y: 0.25 },
                    PolygonPoint { x: -0.3, y: -0.25 },
                ],
                description: None,
            }]),
            envelopes3d: None,
        },
        load_specification: LoadSpecification::default(),
        vehicle_config: Some(VehicleConfigInfo {
            versions: Some(vec![VersionInfo {
                key: "softwareVersion".to_owned(),
                value: "0.1.0".to_owned(),
            }]),
            network: None,
        }),
    }
}

// ------------------------------------------------------------------ generators

pub fn id_string() -> impl Strategy<Value = String> {
    "[A-Za-z0-9_.:-]{1,8}"
}

pub fn text() -> impl Strategy<Value = String> {
    "[ -~äöüπ]{0,12}"
}

pub fn coord() -> impl Strategy<Value = f64> {
    -1.0e4..1.0e4f64
}

pub fn angle() -> impl Strategy<Value = f64> {
    -PI..=PI
}

pub fn timestamp_text() -> impl Strategy<Value = String> {
    (0u64..4_000_000_000_000).prop_map(|ms| Timestamp::from_unix_millis(ms).unwrap().to_iso8601())
}

pub fn any_header() -> impl Strategy<Value = Header> {
    (any::<u32>(), timestamp_text(), id_string(), id_string()).prop_map(|(id, ts, m, s)| Header {
        header_id: id,
        timestamp: ts,
        version: "2.1.0".to_owned(),
        manufacturer: m,
        serial_number: s,
    })
}

pub fn node_position() -> impl Strategy<Value = NodePosition> {
    (
        coord(),
        coord(),
        proptest::option::of(angle()),
        proptest::option::of(0.0..5.0f64),
        proptest::option::of(0.0..=PI),
        id_string(),
        proptest::option::of(text()),
    )
        .prop_map(|(x, y, theta, dxy, dth, map_id, desc)| NodePosition {
            x,
            y,
            theta,
            allowed_deviation_xy: dxy,
            allowed_deviation_theta: dth,
            map_id,
            map_description: desc,
        })
}

pub fn param_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<bool>().prop_map(Value::from),
        (-1.0e6..1.0e6f64).prop_map(Value::from),
        text().prop_map(Value::from),
        proptest::collection::vec(text(), 0..3).prop_map(Value::from),
    ]
}

pub fn blocking() -> impl Strategy<Value = BlockingType> {
    prop_oneof![
        Just(BlockingType::None),
        Just(BlockingType::Soft),
        Just(BlockingType::Hard)
    ]
}

/// Actions with ids unique by construction: `prefix` + index.
pub fn actions(prefix: String) -> impl Strategy<Value = Vec<Action>> {
    proptest::collection::vec(
        (
            id_string(),
            proptest::option::of(text()),
            blocking(),
            proptest::option::of(proptest::collection::vec(
                (id_string(), param_value()),
                0..3,
            )),
        ),
        0..3,
    )
    .prop_map(move |v| {
        v.into_iter()
            .enumerate()
            .map(|(i, (kind, desc, b, params))| Action {
                action_type: kind,
                action_id: format!("{prefix}{i}"),
                action_description: desc,
                blocking_type: b,
                action_parameters: params.map(|ps| {
                    ps.into_iter()
                        .map(|(key, value)| ActionParameter { key, value })
                        .collect()
                }),
            })
            .collect()
    })
}

pub fn trajectory() -> impl Strategy<Value = Trajectory> {
    (
        1u32..4,
        proptest::collection::vec(0.0..=1.0f64, 0..6),
        proptest::collection::vec((coord(), coord(), proptest::option::of(0.0..10.0f64)), 0..4),
    )
        .prop_map(|(degree, knots, cps)| Trajectory {
            degree,
            knot_vector: knots,
            control_points: cps
                .into_iter()
                .map(|(x, y, weight)| ControlPoint { x, y, weight })
                .collect(),
        })
}

/// Orders that satisfy every structural rule: numbering, joins, base before horizon, unique
/// action ids, ranges.
pub fn valid_order() -> impl Strategy<Value = Order> {
    (
        any_header(),
        id_string(),
        any::<u32>(),
        proptest::option::of(id_string()),
        proptest::collection::vec(id_string(), 1..6),
        0u32..1000,
        any::<prop::sample::Index>(),
    )
        .prop_flat_map(|(header, order_id, update, zone, ids, start, cut)| {
            let n = ids.len();
            let released = 1 + cut.index(n);
            let nodes = ids
                .iter()
                .enumerate()
                .map(|(i, id)| {
                    let id = id.clone();
                    (
                        proptest::option::of(text()),
                        node_position(),
                        actions(format!("n{i}-")),
                    )
                        .prop_map(move |(desc, p, acts)| Node {
                            node_id: id.clone(),
                            sequence_id: 2 * (start + i as u32),
                            node_description: desc,
                            released: i < released,
                            node_position: Some(p),
                            actions: acts,
                        })
                })
                .collect::<Vec<_>>();
            let edges = (0..n.saturating_sub(1))
                .map(|i| {
                    let from = ids[i].clone();
                    let to = ids[i + 1].clone();
                    (
                        id_string(),
                        proptest::option::of(0.0..3.0f64),
                        proptest::option::of(angle()),
                        proptest::option::of(prop_oneof![
                            Just(OrientationType::Global),
                            Just(OrientationType::Tangential)
                        ]),
                        proptest::option::of(any::<bool>()),
                        proptest::option::of(trajectory()),
                        proptest::option::of((0.0..2.0f64, 0.0..2.0f64)),
                        actions(format!("e{i}-")),
                    )
                        .prop_map(
                            move |(eid, speed, orient, otype, rot, traj, corr, acts)| {
                                let mut e = edge(
                                    &eid,
                                    2 * (start + i as u32) + 1,
                                    i + 1 < released,
                                    &from,
                                    &to,
                                );
                                e.max_speed = speed;
                                e.orientation = orient;
                                e.orientation_type = otype;
                                e.rotation_allowed = rot;
                                e.trajectory = traj;
                                e.corridor = corr.map(|(l, r)| Corridor {
                                    left_width: l,
                                    right_width: r,
                                    corridor_ref_point: Some(CorridorRefPoint::Kinematiccenter),
                                });
                                e.actions = acts;
                                e
                            },
                        )
                })
                .collect::<Vec<_>>();
            (nodes, edges).prop_map(move |(nodes, edges)| Order {
                header: header.clone(),
                order_id: order_id.clone(),
                order_update_id: update,
                zone_set_id: zone.clone(),
                nodes,
                edges,
            })
        })
}

pub fn references() -> impl Strategy<Value = Option<Vec<Reference>>> {
    proptest::option::of(proptest::collection::vec(
        (id_string(), text()).prop_map(|(k, v)| Reference::new(k, v)),
        0..3,
    ))
}

pub fn agv_position() -> impl Strategy<Value = AgvPosition> {
    (
        coord(),
        coord(),
        angle(),
        id_string(),
        proptest::option::of(text()),
        any::<bool>(),
        proptest::option::of(0.0..=1.0f64),
        proptest::option::of(0.0..100.0f64),
    )
        .prop_map(
            |(x, y, theta, map_id, desc, init, score, dev)| AgvPosition {
                x,
                y,
                theta,
                map_id,
                map_description: desc,
                position_initialized: init,
                localization_score: score,
                deviation_range: dev,
            },
        )
}

pub fn velocity() -> impl Strategy<Value = Velocity> {
    (
        proptest::option::of(-3.0..3.0f64),
        proptest::option::of(-3.0..3.0f64),
        proptest::option::of(-3.0..3.0f64),
    )
        .prop_map(|(vx, vy, omega)| Velocity { vx, vy, omega })
}

pub fn action_status() -> impl Strategy<Value = ActionStatus> {
    prop_oneof![
        Just(ActionStatus::Waiting),
        Just(ActionStatus::Initializing),
        Just(ActionStatus::Running),
        Just(ActionStatus::Paused),
        Just(ActionStatus::Finished),
        Just(ActionStatus::Failed),
    ]
}

pub fn any_state() -> impl Strategy<Value = State> {
    let order_part = (
        any_header(),
        proptest::option::of(proptest::collection::vec(
            (
                id_string(),
                id_string(),
                proptest::option::of(text()),
                any::<bool>(),
            )
                .prop_map(|(map_id, map_version, d, on)| MapInfo {
                    map_id,
                    map_version,
                    map_description: d,
                    map_status: if on {
                        MapStatus::Enabled
                    } else {
                        MapStatus::Disabled
                    },
                }),
            0..2,
        )),
        "[A-Za-z0-9_.:-]{0,8}",
        any::<u32>(),
        proptest::option::of(id_string()),
        "[A-Za-z0-9_.:-]{0,8}",
        any::<u32>(),
        proptest::collection::vec(
            (
                id_string(),
                any::<u32>(),
                proptest::option::of(text()),
                any::<bool>(),
                proptest::option::of(node_position()),
            )
                .prop_map(|(node_id, sequence_id, d, released, p)| NodeState {
                    node_id,
                    sequence_id,
                    node_description: d,
                    released,
                    node_position: p,
                }),
            0..4,
        ),
        proptest::collection::vec(
            (
                id_string(),
                any::<u32>(),
                proptest::option::of(text()),
                any::<bool>(),
                proptest::option::of(trajectory()),
            )
                .prop_map(|(edge_id, sequence_id, d, released, tr)| EdgeState {
                    edge_id,
                    sequence_id,
                    edge_description: d,
                    released,
                    trajectory: tr,
                }),
            0..4,
        ),
    );
    let motion = (
        proptest::option::of(agv_position()),
        proptest::option::of(velocity()),
        proptest::option::of(proptest::collection::vec(
            (
                proptest::option::of(id_string()),
                proptest::option::of(id_string()),
                proptest::option::of(0.0..100.0f64),
                proptest::option::of((coord(), coord(), coord(), proptest::option::of(angle()))),
                proptest::option::of((0.0..3.0f64, 0.0..3.0f64, proptest::option::of(0.0..3.0f64))),
            )
                .prop_map(|(load_id, load_type, weight, bb, dims)| Load {
                    load_id,
                    load_type,
                    load_position: None,
                    bounding_box_reference: bb.map(|(x, y, z, theta)| BoundingBoxReference {
                        x,
                        y,
                        z,
                        theta,
                    }),
                    load_dimensions: dims.map(|(length, width, height)| LoadDimensions {
                        length,
                        width,
                        height,
                    }),
                    weight,
                }),
            0..2,
        )),
        any::<bool>(),
        proptest::option::of(any::<bool>()),
        proptest::option::of(any::<bool>()),
        proptest::option::of(0.0..100.0f64),
    );
    let rest = (
        proptest::collection::vec(
            (
                id_string(),
                proptest::option::of(id_string()),
                proptest::option::of(text()),
                action_status(),
                proptest::option::of(text()),
            )
                .prop_map(|(action_id, t, d, s, r)| ActionState {
                    action_id,
                    action_type: t,
                    action_description: d,
                    action_status: s,
                    result_description: r,
                }),
            0..4,
        ),
        (
            0.0..100.0f64,
            proptest::option::of(0.0..60.0f64),
            proptest::option::of(0u8..=100),
            any::<bool>(),
            proptest::option::of(any::<u32>()),
        )
            .prop_map(|(c, v, h, charging, reach)| BatteryState {
                battery_charge: c,
                battery_voltage: v,
                battery_health: h,
                charging,
                reach,
            }),
        prop_oneof![
            Just(OperatingMode::Automatic),
            Just(OperatingMode::Semiautomatic),
            Just(OperatingMode::Manual),
            Just(OperatingMode::Service),
            Just(OperatingMode::Teachin),
        ],
        proptest::collection::vec(
            (
                id_string(),
                references(),
                proptest::option::of(text()),
                proptest::option::of(text()),
                any::<bool>(),
            )
                .prop_map(|(error_type, r, d, h, fatal)| Error {
                    error_type,
                    error_references: r,
                    error_description: d,
                    error_hint: h,
                    error_level: if fatal {
                        ErrorLevel::Fatal
                    } else {
                        ErrorLevel::Warning
                    },
                }),
            0..3,
        ),
        proptest::option::of(proptest::collection::vec(
            (
                id_string(),
                references(),
                proptest::option::of(text()),
                any::<bool>(),
            )
                .prop_map(|(info_type, r, d, debug)| Info {
                    info_type,
                    info_references: r,
                    info_description: d,
                    info_level: if debug {
                        InfoLevel::Debug
                    } else {
                        InfoLevel::Info
                    },
                }),
            0..2,
        )),
        (
            prop_oneof![
                Just(EStop::Autoack),
                Just(EStop::Manual),
                Just(EStop::Remote),
                Just(EStop::None)
            ],
            any::<bool>(),
        )
            .prop_map(|(e_stop, field_violation)| SafetyState {
                e_stop,
                field_violation,
            }),
    );
    (order_part, motion, rest).prop_map(
        |(
            (header, maps, order_id, order_update_id, zone, last, last_seq, nodes, edges),
            (pos, vel, loads, driving, paused, nbr, dist),
            (action_states, battery_state, mode, errors, information, safety_state),
        )| State {
            header,
            maps,
            order_id,
            order_update_id,
            zone_set_id: zone,
            last_node_id: last,
            last_node_sequence_id: last_seq,
            node_states: nodes,
            edge_states: edges,
            agv_position: pos,
            velocity: vel,
            loads,
            driving,
            paused,
            new_base_request: nbr,
            distance_since_last_node: dist,
            action_states,
            battery_state,
            operating_mode: mode,
            errors,
            information,
            safety_state,
        },
    )
}
