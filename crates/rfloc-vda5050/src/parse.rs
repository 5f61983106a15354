//! Reading the vehicle's input topics from bytes, and the structural checks of an order.
//!
//! Everything here answers a VDA 5050 `validationError` rather than panicking: malformed JSON,
//! missing fields, wrong types, another major version, a timestamp that is not ISO 8601, and
//! orders whose node/edge graph breaks the rules of section 6.6.1.

use std::collections::HashSet;

use crate::error::{ErrorKind, Vda5050Error};
use crate::messages::{Action, Header, InstantActions, Order, Reference, PROTOCOL_MAJOR};
use crate::time::is_valid_timestamp_text;

/// Largest |angle| accepted for `theta`, `orientation` and `allowedDeviationTheta`: π + 1e-12,
/// which holds π rounded up to 11 decimals (`3.14159265359`, the bound the published schemas
/// use), so that a master control sending that for π is not rejected.
pub const ANGLE_LIMIT: f64 = std::f64::consts::PI + 1e-12;

fn validation(description: impl Into<String>) -> Vda5050Error {
    Vda5050Error::new(ErrorKind::Validation, description)
}

/// Parses and checks an `order` message; see [`validate_order`].
pub fn parse_order(bytes: &[u8]) -> Result<Order, Vda5050Error> {
    let order: Order = serde_json::from_slice(bytes).map_err(|e| {
        validation(format!("order is not a valid order message: {e}"))
            .with_reference(Reference::new("topic", "order"))
    })?;
    validate_order(&order)?;
    Ok(order)
}

/// Parses and checks an `instantActions` message; see [`validate_instant_actions`].
pub fn parse_instant_actions(bytes: &[u8]) -> Result<InstantActions, Vda5050Error> {
    let msg: InstantActions = serde_json::from_slice(bytes).map_err(|e| {
        validation(format!(
            "instantActions is not a valid instantActions message: {e}"
        ))
        .with_reference(Reference::new("topic", "instantActions"))
    })?;
    validate_instant_actions(&msg)?;
    Ok(msg)
}

/// Checks a header: major version [`PROTOCOL_MAJOR`] and an ISO 8601 timestamp.
pub fn validate_header(header: &Header, topic: &str) -> Result<(), Vda5050Error> {
    let refs = |e: Vda5050Error| {
        e.with_reference(Reference::new("topic", topic))
            .with_reference(Reference::new("headerId", header.header_id.to_string()))
    };
    let major = header
        .version
        .split('.')
        .next()
        .and_then(|m| m.parse::<u32>().ok());
    if major != Some(PROTOCOL_MAJOR) {
        return Err(refs(validation(format!(
            "version {:?} is not of major version {PROTOCOL_MAJOR}",
            header.version
        ))));
    }
    if !is_valid_timestamp_text(&header.timestamp) {
        return Err(refs(validation(format!(
            "timestamp {:?} is not ISO 8601 UTC",
            header.timestamp
        ))));
    }
    Ok(())
}

fn finite(value: f64, what: &str, order: &Order) -> Result<(), Vda5050Error> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(order_refs(
            validation(format!("{what} is not a finite number")),
            order,
        ))
    }
}

fn order_refs(e: Vda5050Error, order: &Order) -> Vda5050Error {
    e.with_reference(Reference::new(
        "headerId",
        order.header.header_id.to_string(),
    ))
    .with_reference(Reference::new("topic", "order"))
    .with_reference(Reference::new("orderId", order.order_id.clone()))
    .with_reference(Reference::new(
        "orderUpdateId",
        order.order_update_id.to_string(),
    ))
}

fn check_action(action: &Action, ids: &mut HashSet<String>) -> Result<(), String> {
    if action.action_id.is_empty() || action.action_type.is_empty() {
        return Err("an action has an empty actionId or actionType".to_owned());
    }
    if !ids.insert(action.action_id.clone()) {
        return Err(format!("actionId {:?} is not unique", action.action_id));
    }
    for p in action.action_parameters.iter().flatten() {
        if p.value.is_null() {
            return Err(format!(
                "parameter {:?} of action {:?} is null",
                p.key, action.action_id
            ));
        }
    }
    Ok(())
}

/// Structural checks of an order (section 6.6.1), each failure a `validationError`:
///
/// * header as in [`validate_header`]; non-empty `orderId`;
/// * at least one node, exactly one edge fewer than nodes;
/// * node sequence ids even, and node, edge, node, … numbered consecutively;
/// * every edge joins the node before it to the node after it;
/// * the first node released; released nodes and edges form a prefix (the base), and an edge is
///   released only if both its nodes are;
/// * node positions finite, `theta` and edge `orientation` in [−π, π], `allowedDeviationXY` ≥ 0,
///   `allowedDeviationTheta` in [0, π] (π as [`ANGLE_LIMIT`]), `maxSpeed` etc. finite;
/// * action ids non-empty and unique within the message, no null parameter values.
pub fn validate_order(order: &Order) -> Result<(), Vda5050Error> {
    const PI: f64 = ANGLE_LIMIT;
    let fail = |d: String| Err(order_refs(validation(d), order));
    validate_header(&order.header, "order")?;
    if order.order_id.is_empty() {
        return fail("orderId is empty".to_owned());
    }
    if order.nodes.is_empty() {
        return fail("order has no node".to_owned());
    }
    if order.edges.len() + 1 != order.nodes.len() {
        return fail(format!(
            "order has {} nodes but {} edges",
            order.nodes.len(),
            order.edges.len()
        ));
    }
    let mut action_ids = HashSet::new();
    let mut seen_unreleased = false;
    for (i, node) in order.nodes.iter().enumerate() {
        if node.node_id.is_empty() {
            return fail(format!("node {i} has an empty nodeId"));
        }
        if node.sequence_id % 2 != 0 {
            return fail(format!(
                "node {} has odd sequenceId {}",
                node.node_id, node.sequence_id
            ));
        }
        if i == 0 && !node.released {
            return fail("the first node is not released".to_owned());
        }
        if node.released && seen_unreleased {
            return fail(format!(
                "released node {} follows the horizon",
                node.node_id
            ));
        }
        seen_unreleased |= !node.released;
        if let Some(p) = &node.node_position {
            finite(p.x, "nodePosition.x", order)?;
            finite(p.y, "nodePosition.y", order)?;
            if p.map_id.is_empty() {
                return fail(format!("node {} has an empty mapId", node.node_id));
            }
            if let Some(t) = p.theta {
                if !(-PI..=PI).contains(&t) {
                    return fail(format!(
                        "node {} theta {t} is outside [-pi, pi]",
                        node.node_id
                    ));
                }
            }
            if let Some(d) = p.allowed_deviation_xy {
                if !(d.is_finite() && d >= 0.0) {
                    return fail(format!(
                        "node {} allowedDeviationXY {d} is not >= 0",
                        node.node_id
                    ));
                }
            }
            if let Some(d) = p.allowed_deviation_theta {
                if !(0.0..=PI).contains(&d) {
                    return fail(format!(
                        "node {} allowedDeviationTheta {d} is outside [0, pi]",
                        node.node_id
                    ));
                }
            }
        }
        for a in &node.actions {
            check_action(a, &mut action_ids).or_else(fail)?;
        }
        if let Some(edge) = order.edges.get(i) {
            let Some(next) = order.nodes.get(i + 1) else {
                return fail("edge without end node".to_owned());
            };
            if edge.edge_id.is_empty() {
                return fail(format!("edge {i} has an empty edgeId"));
            }
            if node.sequence_id.checked_add(1) != Some(edge.sequence_id)
                || edge.sequence_id.checked_add(1) != Some(next.sequence_id)
            {
                return fail(format!(
                    "edge {} (sequenceId {}) is not numbered between nodes {} and {}",
                    edge.edge_id, edge.sequence_id, node.sequence_id, next.sequence_id
                ));
            }
            if edge.start_node_id != node.node_id || edge.end_node_id != next.node_id {
                return fail(format!(
                    "edge {} joins {} to {}, not {} to {}",
                    edge.edge_id, edge.start_node_id, edge.end_node_id, node.node_id, next.node_id
                ));
            }
            if edge.released && !(node.released && next.released) {
                return fail(format!(
                    "edge {} is released but one of its nodes is not",
                    edge.edge_id
                ));
            }
            if !edge.released && next.released {
                return fail(format!(
                    "released node {} follows unreleased edge {}",
                    next.node_id, edge.edge_id
                ));
            }
            for (v, what) in [
                (edge.max_speed, "maxSpeed"),
                (edge.max_height, "maxHeight"),
                (edge.min_height, "minHeight"),
                (edge.max_rotation_speed, "maxRotationSpeed"),
                (edge.length, "length"),
            ] {
                if let Some(v) = v {
                    finite(v, what, order)?;
                }
            }
            if let Some(o) = edge.orientation {
                if !(-PI..=PI).contains(&o) {
                    return fail(format!(
                        "edge {} orientation {o} is outside [-pi, pi]",
                        edge.edge_id
                    ));
                }
            }
            if let Some(c) = &edge.corridor {
                if !(c.left_width.is_finite()
                    && c.left_width >= 0.0
                    && c.right_width.is_finite()
                    && c.right_width >= 0.0)
                {
                    return fail(format!(
                        "edge {} corridor widths must be >= 0",
                        edge.edge_id
                    ));
                }
            }
            for a in &edge.actions {
                check_action(a, &mut action_ids).or_else(fail)?;
            }
        }
    }
    Ok(())
}

/// Checks an `instantActions` message: header as in [`validate_header`], action ids non-empty
/// and unique, no null parameter values.
pub fn validate_instant_actions(msg: &InstantActions) -> Result<(), Vda5050Error> {
    validate_header(&msg.header, "instantActions")?;
    let mut ids = HashSet::new();
    for a in &msg.actions {
        check_action(a, &mut ids).map_err(|d| {
            validation(d)
                .with_reference(Reference::new("headerId", msg.header.header_id.to_string()))
                .with_reference(Reference::new("topic", "instantActions"))
        })?;
    }
    Ok(())
}
