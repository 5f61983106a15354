//! Objects shared by several topics: the header, node positions, actions and trajectories.

use serde::{Deserialize, Serialize};

/// Protocol version this crate speaks, sent in every header it produces.
pub const PROTOCOL_VERSION: &str = "2.1.0";

/// Major version of [`PROTOCOL_VERSION`]; incoming messages of another major are rejected.
pub const PROTOCOL_MAJOR: u32 = 2;

/// The fields that start every message (section 6.4). Flattened into each message object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Header {
    /// Per topic, incremented by 1 with each sent message.
    pub header_id: u32,
    /// ISO 8601, UTC (`2017-04-15T11:40:03.123Z`).
    pub timestamp: String,
    /// Protocol version `[Major].[Minor].[Patch]`.
    pub version: String,
    /// Manufacturer of the AGV.
    pub manufacturer: String,
    /// Serial number of the AGV.
    pub serial_number: String,
}

/// Position of a node on a map (order topic), also echoed in the state's node states.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct NodePosition {
    /// X on the map, metres.
    pub x: f64,
    /// Y on the map, metres.
    pub y: f64,
    /// Orientation the AGV has to assume on the node, radians in [−π, π].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta: Option<f64>,
    /// Radius within which the node counts as traversed, metres; 0 means the vehicle's own
    /// tolerance.
    #[serde(
        default,
        rename = "allowedDeviationXY",
        skip_serializing_if = "Option::is_none"
    )]
    pub allowed_deviation_xy: Option<f64>,
    /// Allowed orientation deviation, radians in [0, π]; 0 means the vehicle's own tolerance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub allowed_deviation_theta: Option<f64>,
    /// Map the position refers to.
    pub map_id: String,
    /// Additional information on the map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_description: Option<String>,
}

/// How an action may run beside driving and other actions (section 6.12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum BlockingType {
    /// Runs in parallel with other actions and while driving.
    None,
    /// Runs in parallel with other actions; the vehicle must not drive.
    Soft,
    /// Runs alone; the vehicle must not drive.
    Hard,
}

/// One key/value parameter of an action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ActionParameter {
    /// Parameter name, e.g. `x` or `mapId`.
    pub key: String,
    /// Parameter value: array, boolean, number, string or object.
    pub value: serde_json::Value,
}

/// An action on a node, on an edge, or sent as an instant action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Action {
    /// Name of the action, e.g. `initPosition`.
    pub action_type: String,
    /// Unique id that maps the action to its action state.
    pub action_id: String,
    /// Additional information on the action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_description: Option<String>,
    /// How the action may run beside driving and other actions.
    pub blocking_type: BlockingType,
    /// Parameters of the action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_parameters: Option<Vec<ActionParameter>>,
}

impl Action {
    /// The value of parameter `key`, if present.
    pub fn parameter(&self, key: &str) -> Option<&serde_json::Value> {
        self.action_parameters
            .as_ref()?
            .iter()
            .find(|p| p.key == key)
            .map(|p| &p.value)
    }
}

/// A control point of a NURBS trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ControlPoint {
    /// X in the map frame, metres.
    pub x: f64,
    /// Y in the map frame, metres.
    pub y: f64,
    /// Weight with which the point pulls on the curve (default 1.0), ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight: Option<f64>,
}

/// A NURBS trajectory of an edge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Trajectory {
    /// Degree of the NURBS, ≥ 1.
    pub degree: u32,
    /// Knot vector, values in [0, 1]; length = control points + degree + 1.
    pub knot_vector: Vec<f64>,
    /// Control points, including start and end point.
    pub control_points: Vec<ControlPoint>,
}
