//! Every message the crate produces validates against the 2.1.0 JSON schemas in `schemas/`; the
//! schemas themselves are well-formed and reject broken messages; byte-exact known answers;
//! random valid messages survive serialize → validate → deserialize unchanged.
#![allow(clippy::unwrap_used)] // helpers and proptest bodies outside #[test] fns

mod common;

use common::*;
use proptest::prelude::*;
use rfloc_vda5050::messages::*;
use rfloc_vda5050::{parse_order, PoseReport, Vehicle};
use serde_json::{json, Value};

const SCHEMAS: [&str; 6] = [
    "order",
    "instantActions",
    "state",
    "visualization",
    "connection",
    "factsheet",
];

#[test]
fn schemas_are_valid_json_schemas() {
    for name in SCHEMAS {
        let path = format!("{}/schemas/{name}.schema", env!("CARGO_MANIFEST_DIR"));
        let schema: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        assert!(jsonschema::meta::is_valid(&schema), "{name}");
        assert_eq!(
            schema["$schema"], "https://json-schema.org/draft/2020-12/schema",
            "{name}"
        );
        let _ = validator(name);
    }
}

/// A vehicle driven through an order with actions, instant actions, errors and a pause, so that
/// the messages it produces carry most optional fields.
fn busy_vehicle() -> Vehicle {
    let mut cfg = config();
    cfg.order_action_types = vec!["beep".to_owned()];
    let mut v = Vehicle::new(cfg);
    let cov = [[0.01, 0.0, 0.0], [0.0, 0.0025, 0.0], [0.0, 0.0, 0.01]];
    v.update_pose(
        PoseReport::from_estimate(0.0, 0.0, 0.0, &cov, "hall", Velocity::default()),
        t(0),
    )
    .unwrap();
    let mut o = line_order("o1", 0, &["a", "b", "c", "d"], 0, 0.0, 3);
    o.nodes[1].actions = vec![action("beep-1", "beep", BlockingType::None)];
    v.accept_order(o, t(1)).unwrap();
    v.accept_instant_actions(
        &instant(
            1,
            vec![
                action("ia-1", "startPause", BlockingType::Hard),
                action("ia-2", "fly", BlockingType::None),
            ],
        ),
        t(2),
    )
    .unwrap();
    v.add_error(Error {
        error_type: "sensorStale".to_owned(),
        error_references: Some(vec![Reference::new("sensor", "urg0")]),
        error_description: Some("no scan for 2 s".to_owned()),
        error_hint: Some("check the cable".to_owned()),
        error_level: ErrorLevel::Warning,
    });
    v.set_loads(Some(Vec::new()));
    v.set_information(Some(vec![Info {
        info_type: "estimator".to_owned(),
        info_references: None,
        info_description: Some("ekf".to_owned()),
        info_level: InfoLevel::Info,
    }]));
    v.set_battery_state(BatteryState {
        battery_charge: 81.5,
        battery_voltage: Some(25.2),
        battery_health: Some(97),
        charging: false,
        reach: Some(12_000),
    });
    v
}

#[test]
fn vehicle_state_validates() {
    let mut v = Vehicle::new(config());
    let fresh = serde_json::to_value(v.state(t(0))).unwrap();
    assert_valid("state", &fresh);
    let mut v2 = busy_vehicle();
    let busy = serde_json::to_value(v2.state(t(5))).unwrap();
    assert_valid("state", &busy);
    // The busy state carries what it was driven through.
    assert_eq!(busy["nodeStates"].as_array().unwrap().len(), 3);
    assert_eq!(busy["errors"].as_array().unwrap().len(), 2);
    assert_eq!(busy["paused"], true);
    assert_eq!(busy["agvPosition"]["localizationScore"], 0.5);
    // A rejection goes into the state too and still validates.
    let _ = v.accept_order(line_order("x", 0, &["a"], 0, 50.0, 1), t(6));
    let rejected = serde_json::to_value(v.state(t(7))).unwrap();
    assert_valid("state", &rejected);
    assert_eq!(rejected["errors"][0]["errorType"], "noRouteError");
}

#[test]
fn vehicle_visualization_connection_factsheet_validate() {
    let mut v = busy_vehicle();
    assert_valid(
        "visualization",
        &serde_json::to_value(v.visualization(t(3))).unwrap(),
    );
    let mut empty = Vehicle::new(config());
    assert_valid(
        "visualization",
        &serde_json::to_value(empty.visualization(t(3))).unwrap(),
    );
    for s in [
        ConnectionState::Online,
        ConnectionState::Offline,
        ConnectionState::Connectionbroken,
    ] {
        assert_valid(
            "connection",
            &serde_json::to_value(v.connection(s, t(4))).unwrap(),
        );
    }
    let mut content = factsheet_content();
    content.protocol_features.agv_actions = v.supported_actions();
    let f = serde_json::to_value(v.factsheet(&content, t(5))).unwrap();
    assert_valid("factsheet", &f);
    assert_eq!(
        f["protocolLimits"]["maxArrayLens"]["order.nodes"], 100,
        "dotted keys"
    );
}

#[test]
fn sample_order_and_instant_actions_validate() {
    let mut o = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 2);
    o.nodes[1].actions = vec![Action {
        action_parameters: Some(vec![
            ActionParameter {
                key: "duration".to_owned(),
                value: json!(1.5),
            },
            ActionParameter {
                key: "sides".to_owned(),
                value: json!(["left", "right"]),
            },
        ]),
        ..action("a1", "beep", BlockingType::Soft)
    }];
    assert_valid("order", &serde_json::to_value(&o).unwrap());
    let ia = instant(
        3,
        vec![Action {
            action_parameters: Some(vec![
                ActionParameter {
                    key: "x".to_owned(),
                    value: json!(1.0),
                },
                ActionParameter {
                    key: "mapId".to_owned(),
                    value: json!("hall"),
                },
            ]),
            ..action("i1", "initPosition", BlockingType::Hard)
        }],
    );
    assert_valid("instantActions", &serde_json::to_value(&ia).unwrap());
}

fn invalid(name: &str, instance: &Value) -> bool {
    !validator(name).is_valid(instance)
}

#[test]
fn schemas_reject_broken_messages() {
    let mut v = busy_vehicle();
    let good = serde_json::to_value(v.state(t(9))).unwrap();
    let broken = |f: &dyn Fn(&mut Value)| {
        let mut x = good.clone();
        f(&mut x);
        x
    };
    assert!(invalid(
        "state",
        &broken(&|x| {
            x.as_object_mut().unwrap().remove("driving");
        })
    ));
    assert!(invalid(
        "state",
        &broken(&|x| x["agvPosition"]["localizationScore"] = json!(1.5))
    ));
    assert!(invalid(
        "state",
        &broken(&|x| x["operatingMode"] = json!("automatic"))
    ));
    assert!(invalid(
        "state",
        &broken(&|x| x["timestamp"] = json!("yesterday"))
    ));
    assert!(invalid("state", &broken(&|x| x["headerId"] = json!(-1))));
    assert!(invalid(
        "state",
        &broken(&|x| x["errors"][0]["errorLevel"] = json!("ERROR"))
    ));
    assert!(invalid(
        "state",
        &broken(&|x| x["actionStates"][0]["actionStatus"] = json!("DONE"))
    ));
    assert!(invalid(
        "state",
        &broken(&|x| x["safetyState"]["eStop"] = json!(false))
    ));
    let order = serde_json::to_value(line_order("o", 0, &["a", "b"], 0, 0.0, 2)).unwrap();
    let mut o = order.clone();
    o["nodes"][0]["nodePosition"]["theta"] = json!(4.0);
    assert!(invalid("order", &o));
    let mut o = order.clone();
    o["edges"][0].as_object_mut().unwrap().remove("actions");
    assert!(invalid("order", &o));
    let mut o = order;
    o["nodes"][0]["actions"] =
        json!([{"actionType": "x", "actionId": "1", "blockingType": "MAYBE"}]);
    assert!(invalid("order", &o));
    let c = json!({"headerId": 1, "timestamp": "2024-01-01T00:00:00.000Z", "version": "2.1.0",
        "manufacturer": "m", "serialNumber": "s", "connectionState": "DISCONNECTED"});
    assert!(invalid("connection", &c));
}

#[test]
fn connection_known_bytes() {
    let mut v = Vehicle::new(config());
    let _ = v.connection(ConnectionState::Online, t(0));
    let c = v.connection(
        ConnectionState::Connectionbroken,
        rfloc_vda5050::Timestamp::from_unix_millis(1_492_256_403_120).unwrap(),
    );
    assert_eq!(
        serde_json::to_string(&c).unwrap(),
        r#"{"headerId":1,"timestamp":"2017-04-15T11:40:03.120Z","version":"2.1.0","manufacturer":"rfloc","serialNumber":"robot-7","connectionState":"CONNECTIONBROKEN"}"#
    );
}

#[test]
fn fresh_state_known_bytes() {
    let mut v = Vehicle::new(config());
    let s = v.state(rfloc_vda5050::Timestamp::from_unix_millis(1_000).unwrap());
    assert_eq!(
        serde_json::to_string(&s).unwrap(),
        concat!(
            r#"{"headerId":0,"timestamp":"1970-01-01T00:00:01.000Z","version":"2.1.0","#,
            r#""manufacturer":"rfloc","serialNumber":"robot-7","orderId":"","orderUpdateId":0,"#,
            r#""lastNodeId":"","lastNodeSequenceId":0,"nodeStates":[],"edgeStates":[],"#,
            r#""driving":false,"paused":false,"actionStates":[],"#,
            r#""batteryState":{"batteryCharge":0.0,"charging":false},"operatingMode":"AUTOMATIC","#,
            r#""errors":[],"safetyState":{"eStop":"NONE","fieldViolation":false}}"#
        )
    );
}

#[test]
fn order_known_bytes_parse() {
    let bytes = br#"{"headerId":7,"timestamp":"2017-04-15T11:40:03.12Z","version":"2.1.0","manufacturer":"rfloc","serialNumber":"robot-7","orderId":"1234","orderUpdateId":0,"nodes":[{"nodeId":"n6","sequenceId":0,"released":true,"nodePosition":{"x":1.0,"y":2.0,"allowedDeviationXY":0.5,"mapId":"hall"},"actions":[]},{"nodeId":"n4","sequenceId":2,"released":false,"nodePosition":{"x":3.0,"y":2.0,"theta":1.5707963267948966,"mapId":"hall"},"actions":[{"actionType":"beep","actionId":"b1","blockingType":"SOFT","actionParameters":[{"key":"duration","value":2}]}]}],"edges":[{"edgeId":"e1","sequenceId":1,"released":false,"startNodeId":"n6","endNodeId":"n4","maxSpeed":0.8,"actions":[]}]}"#;
    let o = parse_order(bytes).unwrap();
    assert_eq!(o.header.header_id, 7);
    assert_eq!(o.order_id, "1234");
    assert_eq!(
        o.nodes[0]
            .node_position
            .as_ref()
            .unwrap()
            .allowed_deviation_xy,
        Some(0.5)
    );
    assert_eq!(o.nodes[1].actions[0].blocking_type, BlockingType::Soft);
    assert_eq!(o.nodes[1].actions[0].parameter("duration"), Some(&json!(2)));
    assert_eq!(o.edges[0].max_speed, Some(0.8));
    // Serialising gives the same bytes back: optional fields left out, names as received.
    assert_eq!(serde_json::to_vec(&o).unwrap(), bytes.to_vec());
    assert_valid("order", &serde_json::from_slice(bytes).unwrap());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn random_states_validate_and_round_trip(state in any_state()) {
        let value = serde_json::to_value(&state).unwrap();
        let v = validator("state");
        prop_assert!(v.is_valid(&value), "{:?}", v.iter_errors(&value).map(|e| e.to_string()).collect::<Vec<_>>());
        let bytes = serde_json::to_vec(&state).unwrap();
        let back: State = serde_json::from_slice(&bytes).unwrap();
        prop_assert_eq!(back, state);
    }

    #[test]
    fn random_orders_validate_parse_and_round_trip(order in valid_order()) {
        let value = serde_json::to_value(&order).unwrap();
        let v = validator("order");
        prop_assert!(v.is_valid(&value), "{:?}", v.iter_errors(&value).map(|e| e.to_string()).collect::<Vec<_>>());
        let bytes = serde_json::to_vec(&order).unwrap();
        let back = parse_order(&bytes).unwrap();
        prop_assert_eq!(back, order);
    }

    #[test]
    fn random_visualizations_validate_and_round_trip(
        header in any_header(),
        pos in proptest::option::of(agv_position()),
        vel in proptest::option::of(velocity()),
    ) {
        let vis = Visualization { header, agv_position: pos, velocity: vel };
        let value = serde_json::to_value(&vis).unwrap();
        prop_assert!(validator("visualization").is_valid(&value));
        let back: Visualization = serde_json::from_value(value).unwrap();
        prop_assert_eq!(back, vis);
    }
}
