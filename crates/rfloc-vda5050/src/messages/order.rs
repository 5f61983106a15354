//! Topic `order` (master control → AGV), section 6.7, and topic `instantActions`, section 6.9.

use serde::{Deserialize, Serialize};

use super::common::{Action, Header, NodePosition, Trajectory};

/// A driving order or order update: a chain of nodes joined by edges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Order {
    /// The message header.
    #[serde(flatten)]
    pub header: Header,
    /// Order identification, shared by all updates of one order.
    pub order_id: String,
    /// Order update identification, unique per order id.
    pub order_update_id: u32,
    /// Zone set the AGV has to use for navigation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zone_set_id: Option<String>,
    /// Base and horizon nodes, in the order they are to be traversed.
    pub nodes: Vec<Node>,
    /// Base and horizon edges; one fewer than nodes.
    pub edges: Vec<Edge>,
}

/// A node of an order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Node {
    /// Node identification.
    pub node_id: String,
    /// Position in the sequence of nodes (even) and edges (odd) of the order.
    pub sequence_id: u32,
    /// Additional information on the node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_description: Option<String>,
    /// `true`: part of the base; `false`: part of the horizon.
    pub released: bool,
    /// Position of the node; optional for vehicles that do not need it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_position: Option<NodePosition>,
    /// Actions to run when the node is reached.
    pub actions: Vec<Action>,
}

/// How an edge's `orientation` is to be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum OrientationType {
    /// Relative to the map frame.
    Global,
    /// Tangential to the edge (the default).
    Tangential,
}

/// Which point of the vehicle a corridor bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum CorridorRefPoint {
    /// The kinematic centre stays inside the corridor.
    Kinematiccenter,
    /// The vehicle's contour stays inside the corridor.
    Contour,
}

/// Space beside an edge the vehicle may use to drive around obstacles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Corridor {
    /// Width to the left of the edge, metres, ≥ 0.
    pub left_width: f64,
    /// Width to the right of the edge, metres, ≥ 0.
    pub right_width: f64,
    /// Point of the vehicle the corridor bounds (default KINEMATICCENTER).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corridor_ref_point: Option<CorridorRefPoint>,
}

/// A directed edge between two consecutive nodes of an order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Edge {
    /// Edge identification.
    pub edge_id: String,
    /// Position in the sequence of nodes and edges (odd).
    pub sequence_id: u32,
    /// Additional information on the edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_description: Option<String>,
    /// `true`: part of the base; `false`: part of the horizon.
    pub released: bool,
    /// Node id of the start node.
    pub start_node_id: String,
    /// Node id of the end node.
    pub end_node_id: String,
    /// Permitted maximum speed, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed: Option<f64>,
    /// Permitted maximum height of vehicle and load, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_height: Option<f64>,
    /// Permitted minimum height of the load handling device, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_height: Option<f64>,
    /// Orientation of the AGV on the edge, rad in [−π, π].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation: Option<f64>,
    /// How `orientation` is to be read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation_type: Option<OrientationType>,
    /// Direction at junctions for line-guided vehicles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<String>,
    /// Whether rotation is allowed on the edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_allowed: Option<bool>,
    /// Maximum rotation speed, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_rotation_speed: Option<f64>,
    /// Curve to follow between the nodes, as a NURBS.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<Trajectory>,
    /// Length of the path from start to end node, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<f64>,
    /// Corridor beside the edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corridor: Option<Corridor>,
    /// Actions active while the edge is traversed.
    pub actions: Vec<Action>,
}

/// Actions to run at once, outside the order (topic `instantActions`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct InstantActions {
    /// The message header.
    #[serde(flatten)]
    pub header: Header,
    /// The actions, in the order received.
    pub actions: Vec<Action>,
}
