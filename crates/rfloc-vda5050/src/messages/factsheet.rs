//! Topic `factsheet` (AGV → master control), section 6.15.

use serde::{Deserialize, Serialize};

use super::common::Header;
use super::state::{BoundingBoxReference, LoadDimensions};

/// Basic information on the vehicle type and its protocol capabilities.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Factsheet {
    /// The message header.
    #[serde(flatten)]
    pub header: Header,
    /// Class and capabilities of the vehicle type.
    pub type_specification: TypeSpecification,
    /// Basic physical properties.
    pub physical_parameters: PhysicalParameters,
    /// Limits on identifiers, arrays, strings and timing.
    pub protocol_limits: ProtocolLimits,
    /// Supported optional parameters and actions.
    pub protocol_features: ProtocolFeatures,
    /// Wheels and envelopes.
    pub agv_geometry: AgvGeometry,
    /// Load handling and load types.
    pub load_specification: LoadSpecification,
    /// Software, hardware and network configuration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vehicle_config: Option<VehicleConfigInfo>,
}

/// Simplified kinematics of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum AgvKinematic {
    /// Differential drive.
    Diff,
    /// Omni-directional.
    Omni,
    /// Three-wheel driven or similar.
    Threewheel,
}

/// Simplified class of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum AgvClass {
    /// Forklift.
    Forklift,
    /// Vehicle with conveyors.
    Conveyor,
    /// Tugger.
    Tugger,
    /// Load carrier with or without lifting unit.
    Carrier,
}

/// Localisation technique.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum LocalizationType {
    /// Natural landmarks.
    Natural,
    /// Laser reflectors.
    Reflector,
    /// RFID tags.
    Rfid,
    /// Data matrix codes.
    Dmc,
    /// Magnetic spots.
    Spot,
    /// Magnetic grid.
    Grid,
}

/// Path planning type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum NavigationType {
    /// Follows physically installed paths.
    PhysicalLineGuided,
    /// Follows fixed virtual paths.
    VirtualLineGuided,
    /// Plans its path itself.
    Autonomous,
}

/// Class and capabilities of the vehicle type.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct TypeSpecification {
    /// Series name as specified by the manufacturer.
    pub series_name: String,
    /// Human readable description of the series.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub series_description: Option<String>,
    /// Kinematics.
    pub agv_kinematic: AgvKinematic,
    /// Class.
    pub agv_class: AgvClass,
    /// Maximum loadable mass, kg.
    pub max_load_mass: f64,
    /// Localisation techniques.
    pub localization_types: Vec<LocalizationType>,
    /// Path planning types, by priority.
    pub navigation_types: Vec<NavigationType>,
}

/// Basic physical properties.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct PhysicalParameters {
    /// Minimal controlled continuous speed, m/s.
    pub speed_min: f64,
    /// Maximum speed, m/s.
    pub speed_max: f64,
    /// Minimal controlled continuous rotation speed, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_speed_min: Option<f64>,
    /// Maximum rotation speed, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_speed_max: Option<f64>,
    /// Maximum acceleration with maximum load, m/s².
    pub acceleration_max: f64,
    /// Maximum deceleration with maximum load, m/s².
    pub deceleration_max: f64,
    /// Minimum height, m.
    pub height_min: f64,
    /// Maximum height, m.
    pub height_max: f64,
    /// Width, m.
    pub width: f64,
    /// Length, m.
    pub length: f64,
}

/// Maximum string lengths; absent or 0 means no explicit limit.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct MaxStringLens {
    /// Maximum MQTT message length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub msg_len: Option<u32>,
    /// Maximum length of the serial number part of topics.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topic_serial_len: Option<u32>,
    /// Maximum length of the other parts of topics.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topic_elem_len: Option<u32>,
    /// Maximum length of id strings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id_len: Option<u32>,
    /// Ids must be numerical only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id_numerical_only: Option<bool>,
    /// Maximum length of enum and key strings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enum_len: Option<u32>,
    /// Maximum length of load ids.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_id_len: Option<u32>,
}

/// Maximum array lengths; absent or 0 means no explicit limit. Keys carry dots in JSON.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MaxArrayLens {
    /// Nodes per order.
    #[serde(
        rename = "order.nodes",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub order_nodes: Option<u32>,
    /// Edges per order.
    #[serde(
        rename = "order.edges",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub order_edges: Option<u32>,
    /// Actions per node.
    #[serde(
        rename = "node.actions",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub node_actions: Option<u32>,
    /// Actions per edge.
    #[serde(
        rename = "edge.actions",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub edge_actions: Option<u32>,
    /// Parameters per action.
    #[serde(
        rename = "actions.actionsParameters",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub actions_actions_parameters: Option<u32>,
    /// Instant actions per message.
    #[serde(
        rename = "instantActions",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub instant_actions: Option<u32>,
    /// Knots per trajectory.
    #[serde(
        rename = "trajectory.knotVector",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub trajectory_knot_vector: Option<u32>,
    /// Control points per trajectory.
    #[serde(
        rename = "trajectory.controlPoints",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub trajectory_control_points: Option<u32>,
    /// Node states per state message.
    #[serde(
        rename = "state.nodeStates",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub state_node_states: Option<u32>,
    /// Edge states per state message.
    #[serde(
        rename = "state.edgeStates",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub state_edge_states: Option<u32>,
    /// Loads per state message.
    #[serde(
        rename = "state.loads",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub state_loads: Option<u32>,
    /// Action states per state message.
    #[serde(
        rename = "state.actionStates",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub state_action_states: Option<u32>,
    /// Errors per state message.
    #[serde(
        rename = "state.errors",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub state_errors: Option<u32>,
    /// Informations per state message.
    #[serde(
        rename = "state.informations",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub state_information: Option<u32>,
    /// References per error.
    #[serde(
        rename = "error.errorReferences",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub error_error_references: Option<u32>,
    /// References per information.
    #[serde(
        rename = "informations.infoReferences",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub information_info_references: Option<u32>,
}

/// Timing limits, seconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Timing {
    /// Minimum interval between order messages to the vehicle, s.
    pub min_order_interval: f64,
    /// Minimum interval between state messages, s.
    pub min_state_interval: f64,
    /// Default interval between state messages, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub default_state_interval: Option<f64>,
    /// Default interval between visualization messages, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visualization_interval: Option<f64>,
}

/// Limits of the vehicle's protocol implementation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ProtocolLimits {
    /// Maximum string lengths.
    pub max_string_lens: MaxStringLens,
    /// Maximum array lengths.
    pub max_array_lens: MaxArrayLens,
    /// Timing limits.
    pub timing: Timing,
}

/// How an optional parameter is supported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum Support {
    /// Supported as specified.
    Supported,
    /// Required for proper operation.
    Required,
}

/// An optional parameter the vehicle supports or requires.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct OptionalParameter {
    /// Full name, e.g. `order.nodes.nodePosition.allowedDeviationTheta`.
    pub parameter: String,
    /// Kind of support.
    pub support: Support,
    /// Free-form description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

/// Where an action may be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ActionScope {
    /// As an instant action.
    Instant,
    /// On nodes.
    Node,
    /// On edges.
    Edge,
}

/// Data type of an action parameter's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ValueDataType {
    /// Boolean.
    Bool,
    /// Any number.
    Number,
    /// Integer.
    Integer,
    /// Floating point number.
    Float,
    /// String.
    String,
    /// JSON object.
    Object,
    /// JSON array.
    Array,
}

/// A parameter of a supported action (not the order's key/value parameter).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct FactsheetActionParameter {
    /// Key of the parameter.
    pub key: String,
    /// Data type of the value.
    pub value_data_type: ValueDataType,
    /// Free-form description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Whether the parameter is optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub is_optional: Option<bool>,
}

/// An action the vehicle supports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct AgvAction {
    /// The action type, as in `action.actionType`.
    pub action_type: String,
    /// Free-form description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_description: Option<String>,
    /// Where the action may be used.
    pub action_scopes: Vec<ActionScope>,
    /// Parameters of the action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_parameters: Option<Vec<FactsheetActionParameter>>,
    /// Description of the result.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub result_description: Option<String>,
}

/// Supported optional parameters and actions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ProtocolFeatures {
    /// Optional parameters supported or required.
    pub optional_parameters: Vec<OptionalParameter>,
    /// Supported actions.
    pub agv_actions: Vec<AgvAction>,
}

/// Wheel type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum WheelType {
    /// Drive wheel.
    Drive,
    /// Caster wheel.
    Caster,
    /// Fixed wheel.
    Fixed,
    /// Mecanum wheel.
    Mecanum,
}

/// Position of a wheel in vehicle coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct WheelPosition {
    /// X, m.
    pub x: f64,
    /// Y, m.
    pub y: f64,
    /// Orientation, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta: Option<f64>,
}

/// A wheel of the vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct WheelDefinition {
    /// Wheel type.
    #[serde(rename = "type")]
    pub wheel_type: WheelType,
    /// Whether the wheel is actively driven.
    pub is_active_driven: bool,
    /// Whether the wheel is actively steered.
    pub is_active_steered: bool,
    /// Position.
    pub position: WheelPosition,
    /// Nominal diameter, m.
    pub diameter: f64,
    /// Nominal width, m.
    pub width: f64,
    /// Displacement of the wheel centre to the rotation point, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center_displacement: Option<f64>,
    /// Free-form constraints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub constraints: Option<String>,
}

/// A point of a 2D envelope polygon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct PolygonPoint {
    /// X, m.
    pub x: f64,
    /// Y, m.
    pub y: f64,
}

/// A 2D envelope curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Envelope2d {
    /// Name of the envelope set.
    pub set: String,
    /// Closed, non-self-intersecting polygon.
    pub polygon_points: Vec<PolygonPoint>,
    /// Free-form description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

/// A 3D envelope curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Envelope3d {
    /// Name of the envelope set.
    pub set: String,
    /// Data format, e.g. DXF.
    pub format: String,
    /// Envelope data in `format`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<serde_json::Map<String, serde_json::Value>>,
    /// Where to download the data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub url: Option<String>,
    /// Free-form description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

/// Wheels and envelopes.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct AgvGeometry {
    /// Wheels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_definitions: Option<Vec<WheelDefinition>>,
    /// 2D envelopes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envelopes2d: Option<Vec<Envelope2d>>,
    /// 3D envelopes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envelopes3d: Option<Vec<Envelope3d>>,
}

/// A set of loads the vehicle can handle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct LoadSet {
    /// Unique name of the set.
    pub set_name: String,
    /// Type of load.
    pub load_type: String,
    /// Load positions the set is valid for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_positions: Option<Vec<String>>,
    /// Bounding box reference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounding_box_reference: Option<BoundingBoxReference>,
    /// Load dimensions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_dimensions: Option<LoadDimensions>,
    /// Maximum weight, kg.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_weight: Option<f64>,
    /// Minimum load handling height, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_loadhandling_height: Option<f64>,
    /// Maximum load handling height, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_loadhandling_height: Option<f64>,
    /// Minimum load handling depth, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_loadhandling_depth: Option<f64>,
    /// Maximum load handling depth, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_loadhandling_depth: Option<f64>,
    /// Minimum load handling tilt, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_loadhandling_tilt: Option<f64>,
    /// Maximum load handling tilt, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_loadhandling_tilt: Option<f64>,
    /// Speed limit with this load, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_speed_limit: Option<f64>,
    /// Acceleration limit with this load, m/s².
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_acceleration_limit: Option<f64>,
    /// Deceleration limit with this load, m/s².
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_deceleration_limit: Option<f64>,
    /// Approximate pick time, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pick_time: Option<f64>,
    /// Approximate drop time, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drop_time: Option<f64>,
    /// Free-form description.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

/// Load handling and load types.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct LoadSpecification {
    /// Load positions / load handling devices; absent or empty: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_positions: Option<Vec<String>>,
    /// Load sets the vehicle can handle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_sets: Option<Vec<LoadSet>>,
}

/// A software or hardware version.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct VersionInfo {
    /// What the version is of, e.g. `softwareVersion`.
    pub key: String,
    /// The version, e.g. `v1.12.4`.
    pub value: String,
}

/// Network configuration of the vehicle.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Network {
    /// DNS servers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dns_servers: Option<Vec<String>>,
    /// NTP servers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ntp_servers: Option<Vec<String>>,
    /// Address under which the vehicle is reached.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub local_ip_address: Option<String>,
    /// Subnet mask.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub netmask: Option<String>,
    /// Default gateway.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub default_gateway: Option<String>,
}

/// Software, hardware and network configuration.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct VehicleConfigInfo {
    /// Software and hardware versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub versions: Option<Vec<VersionInfo>>,
    /// Network configuration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<Network>,
}
