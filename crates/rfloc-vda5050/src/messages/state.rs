//! Topic `state` (AGV → master control), section 6.10, and topic `visualization`, section 6.13.

use serde::{Deserialize, Serialize};

use super::common::{Header, NodePosition, Trajectory};

/// The vehicle's full state report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct State {
    /// The message header.
    #[serde(flatten)]
    pub header: Header,
    /// Maps stored on the vehicle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub maps: Option<Vec<MapInfo>>,
    /// Current or last finished order; `""` if none.
    pub order_id: String,
    /// Last accepted order update; 0 if none.
    pub order_update_id: u32,
    /// Zone set in use.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zone_set_id: Option<String>,
    /// Last reached node, or the node the vehicle stands on; `""` if none.
    pub last_node_id: String,
    /// Sequence id of `last_node_id`; 0 if none.
    pub last_node_sequence_id: u32,
    /// Nodes still to traverse; empty if idle.
    pub node_states: Vec<NodeState>,
    /// Edges still to traverse; empty if idle.
    pub edge_states: Vec<EdgeState>,
    /// Current position on the map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_position: Option<AgvPosition>,
    /// Velocity in vehicle coordinates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Velocity>,
    /// Loads carried; absent if the vehicle cannot tell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loads: Option<Vec<Load>>,
    /// Whether the vehicle is driving and/or rotating.
    pub driving: bool,
    /// Whether the vehicle is paused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paused: Option<bool>,
    /// The vehicle is near the end of its base and asks for a new one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub new_base_request: Option<bool>,
    /// Distance driven past the last node, m (line-guided vehicles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance_since_last_node: Option<f64>,
    /// States of the current order's actions and of instant actions since the last order.
    pub action_states: Vec<ActionState>,
    /// Battery information.
    pub battery_state: BatteryState,
    /// Current operating mode.
    pub operating_mode: OperatingMode,
    /// Active errors; empty if none.
    pub errors: Vec<Error>,
    /// Information for visualisation and debugging only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub information: Option<Vec<Info>>,
    /// Safety related information.
    pub safety_state: SafetyState,
}

/// Whether a stored map is in use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum MapStatus {
    /// The map is in use.
    Enabled,
    /// The map is stored but not in use.
    Disabled,
}

/// A map stored on the vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct MapInfo {
    /// Map identification.
    pub map_id: String,
    /// Version of the map.
    pub map_version: String,
    /// Additional information on the map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_description: Option<String>,
    /// Whether the map is in use.
    pub map_status: MapStatus,
}

/// A node still to be traversed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct NodeState {
    /// Node identification.
    pub node_id: String,
    /// Sequence id of the node.
    pub sequence_id: u32,
    /// Additional information on the node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_description: Option<String>,
    /// `true`: base; `false`: horizon.
    pub released: bool,
    /// Position of the node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_position: Option<NodePosition>,
}

/// An edge still to be traversed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct EdgeState {
    /// Edge identification.
    pub edge_id: String,
    /// Sequence id of the edge.
    pub sequence_id: u32,
    /// Additional information on the edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_description: Option<String>,
    /// `true`: base; `false`: horizon.
    pub released: bool,
    /// Trajectory of the edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<Trajectory>,
}

/// The vehicle's position on a map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct AgvPosition {
    /// X on the map, m.
    pub x: f64,
    /// Y on the map, m.
    pub y: f64,
    /// Orientation, rad in [−π, π].
    pub theta: f64,
    /// Map the position refers to.
    pub map_id: String,
    /// Additional information on the map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_description: Option<String>,
    /// Whether the position is initialised.
    pub position_initialized: bool,
    /// Quality of the localisation, 0 (unknown) … 1 (known).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localization_score: Option<f64>,
    /// Deviation range of the position, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deviation_range: Option<f64>,
}

/// Velocity in vehicle coordinates.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Velocity {
    /// Speed along the vehicle's x axis, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vx: Option<f64>,
    /// Speed along the vehicle's y axis, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vy: Option<f64>,
    /// Turn rate about the z axis, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega: Option<f64>,
}

/// Reference point of a load's bounding box, in vehicle coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct BoundingBoxReference {
    /// X, m.
    pub x: f64,
    /// Y, m.
    pub y: f64,
    /// Z, m.
    pub z: f64,
    /// Orientation of the bounding box, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta: Option<f64>,
}

/// Dimensions of a load's bounding box.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct LoadDimensions {
    /// Length, m.
    pub length: f64,
    /// Width, m.
    pub width: f64,
    /// Height, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<f64>,
}

/// A load the vehicle carries.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Load {
    /// Identification of the load (barcode, RFID).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_id: Option<String>,
    /// Type of load.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_type: Option<String>,
    /// Load handling unit used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_position: Option<String>,
    /// Reference point of the bounding box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounding_box_reference: Option<BoundingBoxReference>,
    /// Dimensions of the bounding box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_dimensions: Option<LoadDimensions>,
    /// Weight, kg, ≥ 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight: Option<f64>,
}

/// Stage of an action's life cycle (section 6.11).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ActionStatus {
    /// Received; its node not yet reached or its edge not yet entered.
    Waiting,
    /// Triggered; preparations are under way.
    Initializing,
    /// Running.
    Running,
    /// Paused by a pause instant action or an external trigger.
    Paused,
    /// Finished.
    Finished,
    /// Could not be finished.
    Failed,
}

impl ActionStatus {
    /// FINISHED or FAILED: the action will not change again.
    pub fn is_terminal(self) -> bool {
        matches!(self, ActionStatus::Finished | ActionStatus::Failed)
    }
}

/// State of one action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ActionState {
    /// The action's id.
    pub action_id: String,
    /// The action's type.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_type: Option<String>,
    /// Additional information on the action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_description: Option<String>,
    /// Stage of the action.
    pub action_status: ActionStatus,
    /// Result of the action, e.g. what an RFID read returned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub result_description: Option<String>,
}

/// Battery information.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct BatteryState {
    /// State of charge, %.
    pub battery_charge: f64,
    /// Battery voltage, V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery_voltage: Option<f64>,
    /// State of health, % in [0, 100].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery_health: Option<u8>,
    /// Whether charging is in progress.
    pub charging: bool,
    /// Estimated reach with the current charge, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reach: Option<u32>,
}

/// Who controls the vehicle (section 6.10.6, operating modes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum OperatingMode {
    /// Under full control of master control.
    Automatic,
    /// Under control of master control; speed from the HMI.
    Semiautomatic,
    /// Driven by hand; master control not in control.
    Manual,
    /// Being reconfigured by authorised personnel.
    Service,
    /// Being taught, e.g. mapping.
    Teachin,
}

/// Severity of an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ErrorLevel {
    /// Self-resolving; the AGV is ready to start.
    Warning,
    /// The AGV is not in running condition; user intervention required.
    Fatal,
}

/// A key/value reference attached to an error or an information.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Reference {
    /// Kind of reference, e.g. `orderId`, `actionId`.
    pub reference_key: String,
    /// The referenced value.
    pub reference_value: String,
}

impl Reference {
    /// A reference `key` → `value`.
    pub fn new(key: impl Into<String>, value: impl Into<String>) -> Self {
        Reference {
            reference_key: key.into(),
            reference_value: value.into(),
        }
    }
}

/// An active error of the vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Error {
    /// Type or name of the error.
    pub error_type: String,
    /// References that help find the cause.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_references: Option<Vec<Reference>>,
    /// Details and possible causes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_description: Option<String>,
    /// How to approach or solve the error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_hint: Option<String>,
    /// Severity.
    pub error_level: ErrorLevel,
}

/// Level of an information.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum InfoLevel {
    /// For debugging.
    Debug,
    /// For visualisation.
    Info,
}

/// Information for visualisation or debugging, never for master control's logic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Info {
    /// Type or name of the information.
    pub info_type: String,
    /// References.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info_references: Option<Vec<Reference>>,
    /// Description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info_description: Option<String>,
    /// Level.
    pub info_level: InfoLevel,
}

/// Acknowledge type of an active emergency stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum EStop {
    /// Auto-acknowledgeable, e.g. bumper or protective field.
    Autoack,
    /// Must be acknowledged at the vehicle.
    Manual,
    /// Facility e-stop, acknowledged remotely.
    Remote,
    /// No e-stop active.
    None,
}

/// Safety related information.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct SafetyState {
    /// Active e-stop, if any.
    pub e_stop: EStop,
    /// Whether a protective field is violated.
    pub field_violation: bool,
}

/// Position and velocity at a higher rate than the state (topic `visualization`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Visualization {
    /// The message header.
    #[serde(flatten)]
    pub header: Header,
    /// Current position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_position: Option<AgvPosition>,
    /// Current velocity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Velocity>,
}

/// State of the vehicle's broker connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ConnectionState {
    /// Connection to the broker is active.
    Online,
    /// Connection went offline in a coordinated way.
    Offline,
    /// Connection ended unexpectedly (the MQTT last will).
    Connectionbroken,
}

/// Topic `connection` (section 6.14); sent retained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Connection {
    /// The message header.
    #[serde(flatten)]
    pub header: Header,
    /// The connection state.
    pub connection_state: ConnectionState,
}
