//! The vehicle state machine: orders, updates, rejections, driving progress, instant actions,
//! errors and the publishing policy.
#![allow(clippy::unwrap_used)] // helpers and proptest bodies outside #[test] fns

mod common;

use std::f64::consts::PI;

use common::*;
use proptest::prelude::*;
use rfloc_vda5050::messages::*;
use rfloc_vda5050::{ErrorKind, OrderAcceptance, PoseReport, RateLimiter, Vehicle};
use serde_json::json;

fn pose(x: f64, y: f64, theta: f64, speed: f64) -> PoseReport {
    PoseReport {
        x,
        y,
        theta,
        map_id: "hall".to_owned(),
        position_initialized: true,
        localization_score: Some(0.9),
        deviation_range: Some(0.05),
        velocity: Velocity {
            vx: Some(speed),
            vy: Some(0.0),
            omega: Some(0.0),
        },
    }
}

/// A vehicle standing at (x, 0) on map "hall".
fn vehicle_at(x: f64) -> Vehicle {
    let mut v = Vehicle::new(config());
    v.update_pose(pose(x, 0.0, 0.0, 0.0), t(0)).unwrap();
    v
}

fn node_ids(s: &State) -> Vec<(String, bool)> {
    s.node_states
        .iter()
        .map(|n| (n.node_id.clone(), n.released))
        .collect()
}

fn edge_ids(s: &State) -> Vec<String> {
    s.edge_states.iter().map(|e| e.edge_id.clone()).collect()
}

fn status(s: &State, id: &str) -> ActionStatus {
    s.action_states
        .iter()
        .find(|a| a.action_id == id)
        .unwrap()
        .action_status
}

fn error_types(s: &State) -> Vec<String> {
    s.errors.iter().map(|e| e.error_type.clone()).collect()
}

#[test]
fn new_order_is_driven_node_by_node() {
    let mut v = vehicle_at(0.0);
    let o = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 3);
    assert_eq!(v.accept_order(o, t(1)), Ok(OrderAcceptance::New));
    let s = v.state(t(1));
    assert_eq!((s.last_node_id.as_str(), s.last_node_sequence_id), ("a", 0));
    assert_eq!(
        node_ids(&s),
        vec![("b".to_owned(), true), ("c".to_owned(), true)]
    );
    assert_eq!(edge_ids(&s), vec!["eab", "ebc"]);
    let target = v.next_target().unwrap();
    assert_eq!(
        (target.node_id.as_str(), target.x, target.y),
        ("b", 1.0, 0.0)
    );
    assert_eq!(target.edge_id, "eab");
    assert_eq!(target.allowed_deviation_xy, 0.25);

    let p = v.update_pose(pose(0.5, 0.0, 0.0, 0.4), t(2)).unwrap();
    assert!(p.reached.is_empty());
    assert!(v.is_driving());
    let p = v.update_pose(pose(0.8, 0.05, 0.0, 0.4), t(3)).unwrap();
    assert_eq!(p.reached.len(), 1);
    assert_eq!(p.reached[0].node_id, "b");
    assert_eq!(p.target.unwrap().node_id, "c");
    let s = v.state(t(3));
    assert_eq!((s.last_node_id.as_str(), s.last_node_sequence_id), ("b", 2));
    assert_eq!(node_ids(&s), vec![("c".to_owned(), true)]);
    assert_eq!(edge_ids(&s), vec!["ebc"]);
    assert!(s.driving);

    let p = v.update_pose(pose(2.0, -0.1, 0.3, 0.0), t(4)).unwrap();
    assert_eq!(p.reached[0].node_id, "c");
    assert!(p.target.is_none());
    let s = v.state(t(4));
    assert!(s.node_states.is_empty() && s.edge_states.is_empty());
    assert!(!s.driving);
    assert_eq!(s.order_id, "o1");
    assert!(!v.is_executing());
}

#[test]
fn allowed_deviation_and_theta_of_the_node_are_used() {
    let mut v = vehicle_at(0.0);
    let mut o = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 3);
    {
        let b = o.nodes[1].node_position.as_mut().unwrap();
        b.allowed_deviation_xy = Some(0.05);
        let c = o.nodes[2].node_position.as_mut().unwrap();
        c.theta = Some(PI);
        c.allowed_deviation_theta = Some(0.1);
    }
    v.accept_order(o, t(1)).unwrap();
    assert_eq!(v.next_target().unwrap().allowed_deviation_xy, 0.05);
    assert!(v
        .update_pose(pose(0.9, 0.0, 0.0, 0.0), t(2))
        .unwrap()
        .reached
        .is_empty());
    assert_eq!(
        v.update_pose(pose(0.97, 0.0, 0.0, 0.0), t(3))
            .unwrap()
            .reached[0]
            .node_id,
        "b"
    );
    // On c's position but facing the wrong way: not reached.
    assert!(v
        .update_pose(pose(2.0, 0.0, 0.0, 0.0), t(4))
        .unwrap()
        .reached
        .is_empty());
    // -3.1 rad is 0.04 rad from π across the wrap.
    assert_eq!(
        v.update_pose(pose(2.0, 0.0, -3.1, 0.0), t(5))
            .unwrap()
            .reached[0]
            .node_id,
        "c"
    );
}

#[test]
fn horizon_is_not_driven_and_update_extends_the_base() {
    let mut v = vehicle_at(0.0);
    // Base a, b; horizon c, d.
    v.accept_order(line_order("o1", 0, &["a", "b", "c", "d"], 0, 0.0, 2), t(1))
        .unwrap();
    let s = v.state(t(1));
    assert_eq!(
        node_ids(&s),
        vec![
            ("b".to_owned(), true),
            ("c".to_owned(), false),
            ("d".to_owned(), false)
        ]
    );
    v.update_pose(pose(1.0, 0.0, 0.0, 0.0), t(2)).unwrap();
    // Standing on c's spot does not traverse an unreleased node.
    let p = v.update_pose(pose(2.0, 0.0, 0.0, 0.0), t(3)).unwrap();
    assert!(p.reached.is_empty() && p.target.is_none());
    assert!(v.is_executing(), "waiting for an update");
    // Update: stitch at b (sequenceId 2), release c, d, add e in the horizon.
    let mut up = line_order("o1", 1, &["b", "c", "d", "e"], 2, 1.0, 3);
    up.nodes[0].actions = vec![action("ignored", "beep", BlockingType::None)];
    let mut cfg_v = v.clone();
    // The stitching node's actions are not taken over, so an action type the vehicle cannot run
    // there still fails the capability check first: use an update without it below.
    assert!(cfg_v.accept_order(up.clone(), t(4)).is_err());
    up.nodes[0].actions.clear();
    assert_eq!(v.accept_order(up, t(4)), Ok(OrderAcceptance::Updated));
    let s = v.state(t(4));
    assert_eq!(s.order_update_id, 1);
    assert_eq!(
        node_ids(&s),
        vec![
            ("c".to_owned(), true),
            ("d".to_owned(), true),
            ("e".to_owned(), false)
        ]
    );
    assert_eq!(edge_ids(&s), vec!["ebc", "ecd", "ede"]);
    assert_eq!(s.last_node_id, "b");
    let p = v.update_pose(pose(2.0, 0.0, 0.0, 0.0), t(5)).unwrap();
    assert_eq!(p.reached[0].node_id, "c");
    assert_eq!(p.target.unwrap().node_id, "d");
}

#[test]
fn update_while_driving_stitches_at_the_last_base_node() {
    let mut v = vehicle_at(0.0);
    v.accept_order(line_order("o1", 0, &["a", "b", "c", "d"], 0, 0.0, 3), t(1))
        .unwrap();
    // Still before b: an update must start at c (the end of the base), sequenceId 4.
    let wrong = line_order("o1", 1, &["b", "c"], 2, 1.0, 2);
    let e = v.accept_order(wrong, t(2)).unwrap_err();
    assert_eq!(e.kind, ErrorKind::OrderUpdate);
    assert!(e
        .references
        .iter()
        .any(|r| r.reference_key == "orderUpdateId" && r.reference_value == "1"));
    let s = v.state(t(2));
    assert_eq!(s.order_update_id, 0, "the previous order goes on");
    assert_eq!(error_types(&s), vec!["orderUpdateError"]);
    let right = line_order("o1", 1, &["c", "d", "e"], 4, 2.0, 3);
    assert_eq!(v.accept_order(right, t(3)), Ok(OrderAcceptance::Updated));
    let s = v.state(t(3));
    assert!(
        s.errors.is_empty(),
        "rejection cleared by the accepted update"
    );
    assert_eq!(
        node_ids(&s),
        vec![
            ("b".to_owned(), true),
            ("c".to_owned(), true),
            ("d".to_owned(), true),
            ("e".to_owned(), true)
        ]
    );
    assert_eq!(edge_ids(&s), vec!["eab", "ebc", "ecd", "ede"]);
}

#[test]
fn stale_and_duplicate_updates() {
    let mut v = vehicle_at(0.0);
    v.accept_order(line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 2), t(1))
        .unwrap();
    v.accept_order(line_order("o1", 3, &["b", "c"], 2, 1.0, 2), t(2))
        .unwrap();
    let before = v.state(t(3));
    // Same orderUpdateId again: ignored, no error.
    assert_eq!(
        v.accept_order(line_order("o1", 3, &["b", "c"], 2, 1.0, 2), t(4)),
        Ok(OrderAcceptance::Duplicate)
    );
    assert!(!v.publish_due(t(4)), "an ignored duplicate changes nothing");
    // Lower: orderUpdateError, order kept.
    let e = v
        .accept_order(line_order("o1", 2, &["b", "c"], 2, 1.0, 2), t(5))
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::OrderUpdate);
    let after = v.state(t(6));
    assert_eq!(after.order_update_id, 3);
    assert_eq!(after.node_states, before.node_states);
    assert_eq!(error_types(&after), vec!["orderUpdateError"]);
    assert_eq!(after.errors[0].error_level, ErrorLevel::Warning);
}

#[test]
fn update_after_completion_must_start_at_the_last_node() {
    let mut v = vehicle_at(0.0);
    v.accept_order(line_order("o1", 0, &["a", "b"], 0, 0.0, 2), t(1))
        .unwrap();
    v.update_pose(pose(1.0, 0.0, 0.0, 0.0), t(2)).unwrap();
    assert!(!v.is_executing());
    assert_eq!(v.last_node(), ("b", 2));
    // Same node id, other sequence id: not a continuation.
    let e = v
        .accept_order(line_order("o1", 1, &["b", "c"], 4, 1.0, 2), t(3))
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::OrderUpdate);
    assert_eq!(
        v.accept_order(line_order("o1", 1, &["b", "c"], 2, 1.0, 2), t(4)),
        Ok(OrderAcceptance::Updated)
    );
    assert_eq!(v.next_target().unwrap().node_id, "c");
}

#[test]
fn new_orders_while_busy_far_away_or_unlocalised_are_rejected() {
    let mut v = Vehicle::new(config());
    let e = v
        .accept_order(line_order("o1", 0, &["a"], 0, 0.0, 1), t(0))
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::NoRoute, "no position yet");

    let mut v = vehicle_at(0.0);
    let e = v
        .accept_order(line_order("o1", 0, &["a", "b"], 0, 5.0, 2), t(1))
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::NoRoute, "first node out of reach");
    assert!(e.references.iter().any(|r| r.reference_value == "a"));
    assert_eq!(v.order_id(), "");

    let mut far = line_order("o1", 0, &["a", "b"], 0, 0.0, 2);
    far.nodes[1].node_position = None;
    assert_eq!(
        v.accept_order(far, t(2)).unwrap_err().kind,
        ErrorKind::NoRoute
    );

    v.accept_order(line_order("o1", 0, &["a", "b"], 0, 0.0, 2), t(3))
        .unwrap();
    let e = v
        .accept_order(line_order("o2", 0, &["a", "b"], 0, 0.0, 2), t(4))
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Order, "still executing o1");
    assert_eq!(v.order_id(), "o1");

    // Finished: a new order is taken, its own states replace the old ones.
    v.update_pose(pose(1.0, 0.0, 0.0, 0.0), t(5)).unwrap();
    assert_eq!(
        v.accept_order(line_order("o2", 0, &["b", "c"], 0, 1.0, 2), t(6)),
        Ok(OrderAcceptance::New)
    );
    let s = v.state(t(6));
    assert_eq!(s.order_id, "o2");
    assert!(s.errors.is_empty());
}

#[test]
fn malformed_foreign_and_unsupported_orders_are_rejected() {
    let mut v = vehicle_at(0.0);
    let mut other = line_order("o1", 0, &["a", "b"], 0, 0.0, 2);
    other.header.serial_number = "robot-8".to_owned();
    assert_eq!(
        v.accept_order(other, t(1)).unwrap_err().kind,
        ErrorKind::Validation
    );

    let mut missing_edge = line_order("o1", 0, &["a", "b"], 0, 0.0, 2);
    missing_edge.edges.clear();
    assert_eq!(
        v.accept_order(missing_edge, t(1)).unwrap_err().kind,
        ErrorKind::Validation
    );

    let mut released_after_horizon = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 1);
    released_after_horizon.nodes[2].released = true;
    assert_eq!(
        v.accept_order(released_after_horizon, t(1))
            .unwrap_err()
            .kind,
        ErrorKind::Validation
    );

    let mut odd = line_order("o1", 0, &["a", "b"], 0, 0.0, 2);
    odd.edges[0].end_node_id = "z".to_owned();
    assert_eq!(
        v.accept_order(odd, t(1)).unwrap_err().kind,
        ErrorKind::Validation
    );

    let mut act = line_order("o1", 0, &["a", "b"], 0, 0.0, 2);
    act.nodes[1].actions = vec![action("p1", "pick", BlockingType::Hard)];
    let e = v.accept_order(act, t(1)).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Order);
    assert!(e
        .references
        .iter()
        .any(|r| r.reference_key == "actionId" && r.reference_value == "p1"));

    let mut traj = line_order("o1", 0, &["a", "b"], 0, 0.0, 2);
    traj.edges[0].trajectory = Some(Trajectory {
        degree: 1,
        knot_vector: vec![0.0, 0.0, 1.0, 1.0],
        control_points: vec![
            ControlPoint {
                x: 0.0,
                y: 0.0,
                weight: None,
            },
            ControlPoint {
                x: 1.0,
                y: 0.0,
                weight: None,
            },
        ],
    });
    assert_eq!(
        v.accept_order(traj, t(1)).unwrap_err().kind,
        ErrorKind::Order
    );

    // Each kind of rejection is reported once, the latest of each kind kept.
    let s = v.state(t(2));
    let mut kinds = error_types(&s);
    kinds.sort();
    assert_eq!(kinds, vec!["orderError", "validationError"]);
    assert_eq!(v.order_id(), "");
}

#[test]
fn order_bytes_that_do_not_parse_become_validation_errors() {
    let mut v = vehicle_at(0.0);
    let e = v.handle_order_bytes(b"{\"headerId\": 1", t(1)).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Validation);
    let mut o = serde_json::to_value(line_order("o1", 0, &["a", "b"], 0, 0.0, 2)).unwrap();
    o["version"] = json!("3.0.0");
    let e = v
        .handle_order_bytes(&serde_json::to_vec(&o).unwrap(), t(2))
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Validation);
    assert!(e.description.contains("major"));
    let s = v.state(t(3));
    assert_eq!(error_types(&s), vec!["validationError"]);
    o["version"] = json!("2.0.0");
    assert_eq!(
        v.handle_order_bytes(&serde_json::to_vec(&o).unwrap(), t(4)),
        Ok(OrderAcceptance::New)
    );
    assert!(v.state(t(5)).errors.is_empty());
}

#[test]
fn cancel_order_while_driving_and_without_order() {
    let mut v = vehicle_at(0.0);
    v.accept_instant_actions(
        &instant(0, vec![action("c0", "cancelOrder", BlockingType::Hard)]),
        t(1),
    )
    .unwrap();
    let s = v.state(t(1));
    assert_eq!(status(&s, "c0"), ActionStatus::Failed);
    let err = &s.errors[0];
    assert_eq!(err.error_type, "noOrderToCancel");
    assert_eq!(err.error_level, ErrorLevel::Warning);
    assert!(err
        .error_references
        .as_ref()
        .unwrap()
        .iter()
        .any(|r| r.reference_key == "actionId" && r.reference_value == "c0"));

    let mut cfg = config();
    cfg.order_action_types = vec!["beep".to_owned()];
    let mut v = Vehicle::new(cfg);
    v.update_pose(pose(0.0, 0.0, 0.0, 0.0), t(0)).unwrap();
    let mut o = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 3);
    o.nodes[2].actions = vec![action("b1", "beep", BlockingType::None)];
    v.accept_order(o, t(1)).unwrap();
    v.update_pose(pose(0.5, 0.0, 0.0, 0.5), t(2)).unwrap();
    v.accept_instant_actions(
        &instant(1, vec![action("c1", "cancelOrder", BlockingType::Hard)]),
        t(3),
    )
    .unwrap();
    let s = v.state(t(3));
    assert_eq!(status(&s, "c1"), ActionStatus::Running, "still moving");
    assert_eq!(status(&s, "b1"), ActionStatus::Failed);
    assert!(s.node_states.is_empty() && s.edge_states.is_empty());
    assert_eq!(s.order_id, "o1", "orderId is kept");
    assert!(v.next_target().is_none());
    v.update_pose(pose(0.6, 0.0, 0.0, 0.0), t(4)).unwrap();
    let s = v.state(t(4));
    assert_eq!(status(&s, "c1"), ActionStatus::Finished);
    // A second cancel has nothing to cancel.
    v.accept_instant_actions(
        &instant(2, vec![action("c2", "cancelOrder", BlockingType::Hard)]),
        t(5),
    )
    .unwrap();
    let s = v.state(t(5));
    assert_eq!(status(&s, "c2"), ActionStatus::Failed);
    assert_eq!(error_types(&s), vec!["noOrderToCancel"]);
    // A new order after the cancellation starts where the vehicle stands.
    assert_eq!(
        v.accept_order(line_order("o2", 0, &["x", "y"], 0, 0.6, 2), t(6)),
        Ok(OrderAcceptance::New)
    );
}

#[test]
fn pause_stops_driving_and_pauses_running_actions() {
    let mut cfg = config();
    cfg.order_action_types = vec!["beep".to_owned()];
    let mut v = Vehicle::new(cfg);
    v.update_pose(pose(0.0, 0.0, 0.0, 0.0), t(0)).unwrap();
    let mut o = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 3);
    o.nodes[0].actions = vec![action("n1", "beep", BlockingType::None)];
    v.accept_order(o, t(1)).unwrap();
    assert!(v.set_action_status("n1", ActionStatus::Running, None));
    v.accept_instant_actions(
        &instant(0, vec![action("p1", "startPause", BlockingType::Hard)]),
        t(2),
    )
    .unwrap();
    assert!(v.is_paused());
    assert!(v.next_target().is_none());
    let s = v.state(t(2));
    assert_eq!(s.paused, Some(true));
    assert_eq!(status(&s, "p1"), ActionStatus::Finished);
    assert_eq!(status(&s, "n1"), ActionStatus::Paused);
    // Paused: standing on b does not count.
    assert!(v
        .update_pose(pose(1.0, 0.0, 0.0, 0.0), t(3))
        .unwrap()
        .reached
        .is_empty());
    v.accept_instant_actions(
        &instant(1, vec![action("p2", "stopPause", BlockingType::Hard)]),
        t(4),
    )
    .unwrap();
    let s = v.state(t(4));
    assert_eq!(s.paused, Some(false));
    assert_eq!(status(&s, "n1"), ActionStatus::Running);
    assert_eq!(
        v.update_pose(pose(1.0, 0.0, 0.0, 0.0), t(5))
            .unwrap()
            .reached[0]
            .node_id,
        "b"
    );
}

fn init_action(id: &str, params: serde_json::Value) -> Action {
    let action_parameters = params
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| ActionParameter {
            key: k.clone(),
            value: v.clone(),
        })
        .collect();
    Action {
        action_parameters: Some(action_parameters),
        ..action(id, "initPosition", BlockingType::Hard)
    }
}

#[test]
fn init_position_is_carried_out_by_the_caller() {
    let mut v = Vehicle::new(config());
    v.accept_instant_actions(
        &instant(
            0,
            vec![init_action(
                "i1",
                json!({"x": 3.0, "y": -1.5, "theta": 1.0, "mapId": "hall", "lastNodeId": "n9"}),
            )],
        ),
        t(1),
    )
    .unwrap();
    let req = v.pending_init_position().unwrap().clone();
    assert_eq!(
        (req.x, req.y, req.theta, req.map_id.as_str()),
        (3.0, -1.5, 1.0, "hall")
    );
    assert_eq!(req.last_node_id.as_deref(), Some("n9"));
    assert_eq!(status(&v.state(t(1)), "i1"), ActionStatus::Running);
    assert!(v.finish_init_position(Ok(()), t(2)));
    let s = v.state(t(2));
    assert_eq!(status(&s, "i1"), ActionStatus::Finished);
    let p = s.agv_position.unwrap();
    assert_eq!((p.x, p.y, p.theta), (3.0, -1.5, 1.0));
    assert!(p.position_initialized);
    assert_eq!(s.last_node_id, "n9");
    assert!(!v.finish_init_position(Ok(()), t(3)), "nothing pending");

    // Missing mapId: FAILED with a validation warning.
    v.accept_instant_actions(
        &instant(
            1,
            vec![init_action("i2", json!({"x": 0.0, "y": 0.0, "theta": 0.0}))],
        ),
        t(4),
    )
    .unwrap();
    let s = v.state(t(4));
    assert_eq!(status(&s, "i2"), ActionStatus::Failed);
    assert_eq!(error_types(&s), vec!["validationError"]);
    // The localiser refuses: FAILED with its reason.
    v.accept_instant_actions(
        &instant(
            2,
            vec![init_action(
                "i3",
                json!({"x": 0.0, "y": 0.0, "theta": 0.0, "mapId": "hall"}),
            )],
        ),
        t(5),
    )
    .unwrap();
    v.finish_init_position(Err("scan does not match the map".to_owned()), t(6));
    let s = v.state(t(6));
    let i3 = s
        .action_states
        .iter()
        .find(|a| a.action_id == "i3")
        .unwrap();
    assert_eq!(i3.action_status, ActionStatus::Failed);
    assert_eq!(
        i3.result_description.as_deref(),
        Some("scan does not match the map")
    );
}

#[test]
fn state_and_factsheet_requests_and_unknown_actions() {
    let mut v = Vehicle::new(config());
    let _ = v.state(t(0));
    assert!(!v.publish_due(t(1)));
    v.accept_instant_actions(
        &instant(
            0,
            vec![
                action("s1", "stateRequest", BlockingType::None),
                action("f1", "factsheetRequest", BlockingType::None),
                action("u1", "teleport", BlockingType::None),
            ],
        ),
        t(2),
    )
    .unwrap();
    assert!(v.publish_due(t(2)));
    assert!(v.state_requested() && v.factsheet_requested());
    let s = v.state(t(2));
    assert!(!v.state_requested());
    assert_eq!(status(&s, "s1"), ActionStatus::Finished);
    assert_eq!(status(&s, "f1"), ActionStatus::Finished);
    assert_eq!(status(&s, "u1"), ActionStatus::Failed);
    assert_eq!(error_types(&s), vec!["unsupportedInstantAction"]);
    let _ = v.factsheet(&factsheet_content(), t(3));
    assert!(!v.factsheet_requested());
    // A repeated actionId is refused without a second action state.
    v.accept_instant_actions(
        &instant(1, vec![action("s1", "stateRequest", BlockingType::None)]),
        t(4),
    )
    .unwrap();
    let s = v.state(t(4));
    assert_eq!(
        s.action_states
            .iter()
            .filter(|a| a.action_id == "s1")
            .count(),
        1
    );
    // Instant actions for another vehicle are refused as a whole.
    let mut other = instant(2, vec![action("s9", "stateRequest", BlockingType::None)]);
    other.header.serial_number = "robot-8".to_owned();
    assert_eq!(
        v.accept_instant_actions(&other, t(5)).unwrap_err().kind,
        ErrorKind::Validation
    );
}

#[test]
fn node_and_edge_actions_follow_blocking_types() {
    let mut cfg = config();
    cfg.order_action_types = vec!["beep".to_owned(), "lift".to_owned(), "light".to_owned()];
    let mut v = Vehicle::new(cfg);
    v.update_pose(pose(0.0, 0.0, 0.0, 0.0), t(0)).unwrap();
    let mut o = line_order("o1", 0, &["a", "b", "c"], 0, 0.0, 3);
    o.nodes[1].actions = vec![
        action("h1", "lift", BlockingType::Hard),
        action("n1", "beep", BlockingType::None),
    ];
    o.edges[1].actions = vec![action("l1", "light", BlockingType::None)];
    v.accept_order(o, t(1)).unwrap();
    assert!(v.actions_to_start().is_empty(), "b not reached yet");
    assert_eq!(status(&v.state(t(1)), "h1"), ActionStatus::Waiting);
    v.update_pose(pose(1.0, 0.0, 0.0, 0.0), t(2)).unwrap();
    let ids: Vec<String> = v
        .actions_to_start()
        .into_iter()
        .map(|a| a.action_id)
        .collect();
    assert_eq!(ids, vec!["h1"], "a HARD action starts alone");
    assert!(v.next_target().is_none(), "HARD action holds the vehicle");
    assert!(v.set_action_status("h1", ActionStatus::Running, None));
    assert!(v.actions_to_start().is_empty());
    assert!(v.set_action_status("h1", ActionStatus::Finished, Some("up".to_owned())));
    assert!(
        !v.set_action_status("h1", ActionStatus::Running, None),
        "terminal"
    );
    assert!(!v.set_action_status("nope", ActionStatus::Running, None));
    let ids: Vec<String> = v
        .actions_to_start()
        .into_iter()
        .map(|a| a.action_id)
        .collect();
    // n1 (node, NONE) and l1 (edge b→c entered now that nothing blocks) may start.
    assert_eq!(ids, vec!["n1", "l1"]);
    assert_eq!(v.next_target().unwrap().node_id, "c");
    v.set_action_status("l1", ActionStatus::Running, None);
    v.update_pose(pose(2.0, 0.0, 0.0, 0.0), t(3)).unwrap();
    let s = v.state(t(3));
    assert_eq!(
        status(&s, "l1"),
        ActionStatus::Finished,
        "edge actions end when the edge is left"
    );
    assert_eq!(
        s.action_states
            .iter()
            .find(|a| a.action_id == "h1")
            .unwrap()
            .result_description
            .as_deref(),
        Some("up")
    );
    assert!(v.is_executing(), "n1 never ran");
    v.set_action_status("n1", ActionStatus::Finished, None);
    assert!(!v.is_executing());
}

#[test]
fn device_errors_and_fatal_errors() {
    let mut v = vehicle_at(0.0);
    v.accept_order(line_order("o1", 0, &["a", "b"], 0, 0.0, 2), t(1))
        .unwrap();
    let _ = v.state(t(1));
    let stale = |level| Error {
        error_type: "sensorStale".to_owned(),
        error_references: Some(vec![Reference::new("sensor", "urg0")]),
        error_description: Some("no scan for 2 s".to_owned()),
        error_hint: None,
        error_level: level,
    };
    v.add_error(stale(ErrorLevel::Warning));
    assert!(v.publish_due(t(2)));
    let s = v.state(t(2));
    assert_eq!(error_types(&s), vec!["sensorStale"]);
    assert!(
        v.next_target().is_some(),
        "a WARNING does not stop the vehicle"
    );
    v.add_error(stale(ErrorLevel::Warning));
    assert!(!v.publish_due(t(3)), "the same error again is no change");
    v.add_error(stale(ErrorLevel::Fatal));
    assert!(v.publish_due(t(3)));
    assert_eq!(v.state(t(3)).errors.len(), 1, "replaced, not added");
    assert!(v.next_target().is_none(), "FATAL stops the vehicle");
    assert!(v.clear_error("sensorStale"));
    assert!(!v.clear_error("sensorStale"));
    assert!(v.next_target().is_some());
    assert!(v.state(t(4)).errors.is_empty());
}

#[test]
fn manual_mode_clears_the_order_and_refuses_new_ones() {
    let mut v = vehicle_at(0.0);
    v.accept_order(line_order("o1", 0, &["a", "b"], 0, 0.0, 2), t(1))
        .unwrap();
    v.set_operating_mode(OperatingMode::Manual);
    let s = v.state(t(2));
    assert!(s.node_states.is_empty());
    assert_eq!(s.operating_mode, OperatingMode::Manual);
    assert_eq!(
        v.accept_order(line_order("o2", 0, &["a", "b"], 0, 0.0, 2), t(3))
            .unwrap_err()
            .kind,
        ErrorKind::Order
    );
    v.set_operating_mode(OperatingMode::Automatic);
    assert_eq!(
        v.accept_order(line_order("o2", 0, &["a", "b"], 0, 0.0, 2), t(4)),
        Ok(OrderAcceptance::New)
    );
}

#[test]
fn header_ids_count_per_topic() {
    let mut v = Vehicle::new(config());
    let ids: Vec<u32> = (0..3).map(|i| v.state(t(i)).header.header_id).collect();
    assert_eq!(ids, vec![0, 1, 2]);
    assert_eq!(v.visualization(t(5)).header.header_id, 0);
    assert_eq!(v.visualization(t(6)).header.header_id, 1);
    assert_eq!(
        v.connection(ConnectionState::Online, t(7)).header.header_id,
        0
    );
    assert_eq!(v.state(t(8)).header.header_id, 3);
    let s = v.state(t(9));
    assert_eq!(s.header.version, "2.1.0");
    assert_eq!(s.header.timestamp, "2023-11-14T22:13:20.009Z");
}

#[test]
fn state_is_due_on_change_and_at_least_every_30_s() {
    let mut v = vehicle_at(0.0);
    assert!(v.publish_due(t(0)), "never sent");
    let _ = v.state(t(1000));
    assert!(!v.publish_due(t(1000)));
    assert!(!v.publish_due(t(30_999)));
    assert!(v.publish_due(t(31_000)));
    let _ = v.state(t(31_000));
    // Position alone is no reason (that is what visualization is for) …
    v.update_pose(pose(0.01, 0.0, 0.0, 0.0), t(31_100)).unwrap();
    assert!(!v.publish_due(t(31_100)));
    // … starting to drive is.
    v.update_pose(pose(0.02, 0.0, 0.0, 0.3), t(31_200)).unwrap();
    assert!(v.publish_due(t(31_200)));
    let mut cfg = config();
    cfg.state_interval_ms = 120_000;
    let mut v = Vehicle::new(cfg);
    assert_eq!(v.config().state_interval_ms, 30_000, "capped at 30 s");
    let _ = v.state(t(0));
    assert!(v.publish_due(t(30_000)));
}

#[test]
fn rate_limiter_caps_visualization() {
    let mut r = RateLimiter::from_hz(10.0);
    assert!(r.ready(t(0)));
    assert!(!r.ready(t(50)));
    assert!(!r.ready(t(99)));
    assert!(r.ready(t(100)));
    assert!(!r.ready(t(150)));
    assert!(r.ready(t(10)), "clock went back");
    let mut never = RateLimiter::from_hz(0.0);
    assert!(never.ready(t(0)));
    assert!(!never.ready(t(60_000)));
}

#[test]
fn pose_reports_are_checked() {
    let mut v = Vehicle::new(config());
    assert!(v.update_pose(pose(f64::NAN, 0.0, 0.0, 0.0), t(0)).is_err());
    let mut p = pose(0.0, 0.0, 0.0, 0.0);
    p.localization_score = Some(1.2);
    assert!(v.update_pose(p, t(0)).is_err());
    let cov = [[0.04, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.1]];
    let p = PoseReport::from_estimate(1.0, 2.0, 4.0, &cov, "hall", Velocity::default());
    v.update_pose(p, t(1)).unwrap();
    let s = v.state(t(1));
    let a = s.agv_position.unwrap();
    assert!((a.theta - (4.0 - 2.0 * PI)).abs() < 1e-12);
    assert!((a.localization_score.unwrap() - 0.2).abs() < 1e-12);
    assert!((a.deviation_range.unwrap() - 0.4).abs() < 1e-12);
}

// ------------------------------------------------------------- random sequences

#[derive(Debug, Clone)]
enum Step {
    Pose(f64, f64, f64, f64),
    Order(Order),
    Instant(String),
    ActionDone(usize, bool),
    Error(bool),
    ClearError,
    Pause(bool),
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        4 => (-1.0..6.0f64, -0.5..0.5f64, -PI..PI, 0.0..1.0f64).prop_map(|(x, y, th, v)| Step::Pose(x, y, th, v)),
        2 => (valid_order(), 0u32..3, -1.0..5.0f64).prop_map(|(mut o, update, x0)| {
            // Make it ours, on our map, near the vehicle's track and with caller-run actions.
            o.header.manufacturer = MANUFACTURER.to_owned();
            o.header.serial_number = SERIAL.to_owned();
            o.order_id = format!("o{}", o.order_id.len() % 2);
            o.order_update_id = update;
            for (i, n) in o.nodes.iter_mut().enumerate() {
                if let Some(p) = n.node_position.as_mut() {
                    p.map_id = "hall".to_owned();
                    p.x = x0 + i as f64;
                    p.y = 0.0;
                    p.theta = None;
                }
                for a in &mut n.actions {
                    a.action_type = "beep".to_owned();
                }
            }
            for e in &mut o.edges {
                e.trajectory = None;
                for a in &mut e.actions {
                    a.action_type = "beep".to_owned();
                }
            }
            Step::Order(o)
        }),
        2 => prop_oneof![
            Just("cancelOrder"), Just("startPause"), Just("stopPause"),
            Just("stateRequest"), Just("factsheetRequest"), Just("dance"),
        ].prop_map(|s| Step::Instant(s.to_owned())),
        2 => (0usize..8, any::<bool>()).prop_map(|(i, ok)| Step::ActionDone(i, ok)),
        1 => any::<bool>().prop_map(Step::Error),
        1 => Just(Step::ClearError),
        1 => any::<bool>().prop_map(Step::Pause),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Whatever arrives in whatever order, the vehicle does not panic, every state it builds
    /// validates against the schema, headerIds count up by one, and lastNodeSequenceId never
    /// runs backwards within one order.
    #[test]
    fn random_sequences_keep_the_state_valid(steps in proptest::collection::vec(step(), 1..40)) {
        let mut cfg = config();
        cfg.order_action_types = vec!["beep".to_owned()];
        let mut v = Vehicle::new(cfg);
        let schema = validator("state");
        let mut ms = 0u64;
        let mut last_header = None;
        let mut instant_id = 0u32;
        let mut previous: Option<(String, u32)> = None;
        for step in steps {
            ms += 100;
            match step {
                Step::Pose(x, y, th, speed) => { v.update_pose(pose(x, y, th, speed), t(ms)).unwrap(); }
                Step::Order(o) => { let _ = v.accept_order(o, t(ms)); }
                Step::Instant(kind) => {
                    instant_id += 1;
                    v.accept_instant_actions(
                        &instant(instant_id, vec![action(&format!("ia{instant_id}"), &kind, BlockingType::None)]),
                        t(ms),
                    ).unwrap();
                }
                Step::ActionDone(i, ok) => {
                    if let Some(a) = v.actions_to_start().get(i % 8) {
                        let s = if ok { ActionStatus::Finished } else { ActionStatus::Failed };
                        prop_assert!(v.set_action_status(&a.action_id.clone(), s, None));
                    }
                }
                Step::Error(fatal) => v.add_error(Error {
                    error_type: "sensorStale".to_owned(),
                    error_references: None,
                    error_description: None,
                    error_hint: None,
                    error_level: if fatal { ErrorLevel::Fatal } else { ErrorLevel::Warning },
                }),
                Step::ClearError => { v.clear_error("sensorStale"); }
                Step::Pause(p) => v.set_paused(p),
            }
            let s = v.state(t(ms));
            let value = serde_json::to_value(&s).unwrap();
            prop_assert!(schema.is_valid(&value), "{:?}", schema.iter_errors(&value).map(|e| e.to_string()).collect::<Vec<_>>());
            if let Some(h) = last_header { prop_assert_eq!(s.header.header_id, h + 1); }
            last_header = Some(s.header.header_id);
            if let Some((id, seq)) = &previous {
                if *id == s.order_id {
                    prop_assert!(s.last_node_sequence_id >= *seq);
                }
            }
            previous = Some((s.order_id.clone(), s.last_node_sequence_id));
            // Node and edge states alternate in sequence after the last node.
            let mut expect = s.last_node_sequence_id + 1;
            for (i, n) in s.node_states.iter().enumerate() {
                if let Some(e) = s.edge_states.get(i) {
                    prop_assert_eq!(e.sequence_id, expect);
                }
                prop_assert_eq!(n.sequence_id, expect + 1);
                expect += 2;
            }
            prop_assert_eq!(s.node_states.len(), s.edge_states.len());
        }
    }
}
