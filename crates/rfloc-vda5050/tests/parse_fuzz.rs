//! Parsing the input topics: malformed JSON, wrong version, missing fields and random bytes
//! give a VDA 5050 `validationError`, never a panic.
#![allow(clippy::unwrap_used)] // helpers and proptest bodies outside #[test] fns

mod common;

use common::*;
use proptest::prelude::*;
use rfloc_vda5050::{parse_instant_actions, parse_order, ErrorKind, PoseReport, Vehicle};
use serde_json::{json, Value};

fn order_json() -> Value {
    serde_json::to_value(line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 2)).unwrap()
}

#[test]
#[allow(clippy::approx_constant)] // π as a master control rounds it is the point
fn malformed_inputs_are_validation_errors() {
    let kind = |bytes: &[u8]| parse_order(bytes).unwrap_err().kind;
    assert_eq!(kind(b""), ErrorKind::Validation);
    assert_eq!(kind(b"null"), ErrorKind::Validation);
    assert_eq!(kind(b"[1,2]"), ErrorKind::Validation);
    assert_eq!(kind(b"{\"orderId\": \"o1\""), ErrorKind::Validation);
    for field in [
        "headerId",
        "timestamp",
        "version",
        "orderId",
        "nodes",
        "edges",
    ] {
        let mut o = order_json();
        o.as_object_mut().unwrap().remove(field);
        let e = parse_order(&serde_json::to_vec(&o).unwrap()).unwrap_err();
        assert_eq!(e.kind, ErrorKind::Validation, "{field}");
        assert!(e.description.contains(field), "{field}: {}", e.description);
    }
    let mut o = order_json();
    o["nodes"][0].as_object_mut().unwrap().remove("actions");
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    let mut o = order_json();
    o["orderUpdateId"] = json!(-1);
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    let mut o = order_json();
    o["nodes"][1]["actions"] =
        json!([{"actionType": "x", "actionId": "1", "blockingType": "SOMETIMES"}]);
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    for version in ["1.1.0", "3.0.0", "", "two"] {
        let mut o = order_json();
        o["version"] = json!(version);
        assert_eq!(
            kind(&serde_json::to_vec(&o).unwrap()),
            ErrorKind::Validation,
            "{version}"
        );
    }
    let mut o = order_json();
    o["timestamp"] = json!("15.04.2017 11:40");
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    // Duplicate action ids across nodes.
    let mut o = order_json();
    o["nodes"][0]["actions"] =
        json!([{"actionType": "x", "actionId": "1", "blockingType": "NONE"}]);
    o["nodes"][1]["actions"] =
        json!([{"actionType": "y", "actionId": "1", "blockingType": "NONE"}]);
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    // Odd node sequence id.
    let mut o = order_json();
    o["nodes"][0]["sequenceId"] = json!(1);
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    // π as master controls round it (3.14159265359 > f64 π) is accepted; beyond it is not.
    let mut o = order_json();
    o["nodes"][0]["nodePosition"]["theta"] = json!(3.14159265359);
    o["nodes"][0]["nodePosition"]["allowedDeviationTheta"] = json!(3.14159265359);
    assert!(parse_order(&serde_json::to_vec(&o).unwrap()).is_ok());
    o["nodes"][0]["nodePosition"]["theta"] = json!(-3.1416);
    assert_eq!(
        kind(&serde_json::to_vec(&o).unwrap()),
        ErrorKind::Validation
    );
    // The unchanged order parses.
    assert!(parse_order(&serde_json::to_vec(&order_json()).unwrap()).is_ok());

    let ia = |v: Value| parse_instant_actions(&serde_json::to_vec(&v).unwrap());
    let good = json!({"headerId": 1, "timestamp": "2024-01-01T00:00:00.00Z", "version": "2.1.0",
        "manufacturer": "rfloc", "serialNumber": "robot-7",
        "actions": [{"actionType": "startPause", "actionId": "p", "blockingType": "HARD"}]});
    assert!(ia(good.clone()).is_ok());
    let mut bad = good.clone();
    bad.as_object_mut().unwrap().remove("actions");
    assert_eq!(ia(bad).unwrap_err().kind, ErrorKind::Validation);
    let mut bad = good.clone();
    bad["actions"][0]
        .as_object_mut()
        .unwrap()
        .remove("blockingType");
    assert_eq!(ia(bad).unwrap_err().kind, ErrorKind::Validation);
    let mut bad = good;
    bad["version"] = json!("3.0.0");
    assert_eq!(ia(bad).unwrap_err().kind, ErrorKind::Validation);
}

fn vehicle() -> Vehicle {
    let mut v = Vehicle::new(config());
    v.update_pose(
        PoseReport {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            map_id: "hall".to_owned(),
            position_initialized: true,
            localization_score: None,
            deviation_range: None,
            velocity: Default::default(),
        },
        t(0),
    )
    .unwrap();
    v
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        if let Err(e) = parse_order(&bytes) {
            prop_assert_eq!(e.kind, ErrorKind::Validation);
        }
        if let Err(e) = parse_instant_actions(&bytes) {
            prop_assert_eq!(e.kind, ErrorKind::Validation);
        }
        let mut v = vehicle();
        let _ = v.handle_order_bytes(&bytes, t(1));
        let _ = v.handle_instant_actions_bytes(&bytes, t(2));
        let _ = v.state(t(3));
    }

    /// A valid order with bytes overwritten, cut short or spliced: never a panic, and any
    /// rejection is a validationError that the vehicle reports.
    #[test]
    fn mutated_orders_never_panic(
        order in valid_order(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        cut in any::<prop::sample::Index>(),
        truncate in any::<bool>(),
    ) {
        let mut bytes = serde_json::to_vec(&order).unwrap();
        for (i, b) in edits {
            let n = bytes.len();
            bytes[i.index(n)] = b;
        }
        if truncate {
            let n = bytes.len();
            bytes.truncate(cut.index(n));
        }
        if let Err(e) = parse_order(&bytes) {
            prop_assert_eq!(e.kind, ErrorKind::Validation);
            let mut v = vehicle();
            prop_assert!(v.handle_order_bytes(&bytes, t(1)).is_err());
            let s = v.state(t(2));
            prop_assert_eq!(s.errors[0].error_type.as_str(), "validationError");
        }
    }

    /// Arbitrary JSON values in place of fields of a valid order.
    #[test]
    fn wrong_field_types_never_panic(
        field in prop_oneof![Just("orderId"), Just("orderUpdateId"), Just("nodes"), Just("edges"), Just("headerId"), Just("version")],
        value in prop_oneof![
            Just(Value::Null),
            any::<bool>().prop_map(Value::from),
            any::<i64>().prop_map(Value::from),
            any::<f64>().prop_map(|f| serde_json::Number::from_f64(f).map_or(Value::Null, Value::Number)),
            "[ -~]{0,10}".prop_map(Value::from),
            Just(json!([{}])),
            Just(json!({"x": 1})),
        ],
    ) {
        let mut o = order_json();
        o[field] = value;
        let bytes = serde_json::to_vec(&o).unwrap();
        if let Err(e) = parse_order(&bytes) {
            prop_assert_eq!(e.kind, ErrorKind::Validation);
        }
    }
}
