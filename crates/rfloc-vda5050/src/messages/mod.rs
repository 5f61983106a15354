//! The JSON messages of VDA 5050 2.1.0 as serde types.
//!
//! Field names are the specification's camelCase names; optional fields are `Option`s that are
//! left out of the JSON when `None`; enumerations serialize in the specification's UPPERCASE.

mod common;
mod factsheet;
mod order;
mod state;

pub use common::{
    Action, ActionParameter, BlockingType, ControlPoint, Header, NodePosition, Trajectory,
    PROTOCOL_MAJOR, PROTOCOL_VERSION,
};
pub use factsheet::{
    ActionScope, AgvAction, AgvClass, AgvGeometry, AgvKinematic, Envelope2d, Envelope3d, Factsheet,
    FactsheetActionParameter, LoadSet, LoadSpecification, LocalizationType, MaxArrayLens,
    MaxStringLens, NavigationType, Network, OptionalParameter, PhysicalParameters, PolygonPoint,
    ProtocolFeatures, ProtocolLimits, Support, Timing, TypeSpecification, ValueDataType,
    VehicleConfigInfo, VersionInfo, WheelDefinition, WheelPosition, WheelType,
};
pub use order::{Corridor, CorridorRefPoint, Edge, InstantActions, Node, Order, OrientationType};
pub use state::{
    ActionState, ActionStatus, AgvPosition, BatteryState, BoundingBoxReference, Connection,
    ConnectionState, EStop, EdgeState, Error, ErrorLevel, Info, InfoLevel, Load, LoadDimensions,
    MapInfo, MapStatus, NodeState, OperatingMode, Reference, SafetyState, State, Velocity,
    Visualization,
};
