//! The vehicle's order and action state machine, without I/O.
//!
//! A [`Vehicle`] holds the current order, the action states and everything else that goes into
//! `state`. The caller feeds it what arrives (orders, instant actions, pose reports, results of
//! actions it ran) together with the current time, and takes out what to send (`state`,
//! `visualization`, `connection`, `factsheet`) and where to drive next ([`Target`]). Nothing here
//! reads a clock, a socket or a sensor.

use crate::error::{ErrorKind, Vda5050Error};
use crate::localization::{agv_position_from_estimate, wrap_angle};
use crate::messages::{
    Action, ActionScope, ActionState, ActionStatus, AgvAction, AgvPosition, BatteryState,
    BlockingType, Connection, ConnectionState, EStop, Edge, EdgeState, Error, ErrorLevel,
    Factsheet, FactsheetActionParameter, Header, Info, InstantActions, Load, Node, NodeState,
    OperatingMode, Order, Reference, SafetyState, State, ValueDataType, Velocity, Visualization,
    PROTOCOL_VERSION,
};
use crate::parse::{
    parse_instant_actions, parse_order, validate_instant_actions, validate_order, ANGLE_LIMIT,
};
use crate::time::Timestamp;

/// The longest the specification lets a vehicle go without a `state` message, ms (section 6.10).
pub const MAX_STATE_INTERVAL_MS: u64 = 30_000;

/// Instant actions the state machine handles itself.
pub const BUILT_IN_INSTANT_ACTIONS: [&str; 6] = [
    "cancelOrder",
    "startPause",
    "stopPause",
    "initPosition",
    "stateRequest",
    "factsheetRequest",
];

/// Fixed settings of a vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleConfig {
    /// Manufacturer, as in every header.
    pub manufacturer: String,
    /// Serial number, as in every header; orders for another serial number are rejected.
    pub serial_number: String,
    /// Radius within which a node counts as reached when the order gives no
    /// `allowedDeviationXY` (or 0), m.
    pub default_deviation_xy: f64,
    /// Orientation tolerance on a node when the order gives no `allowedDeviationTheta` (or 0),
    /// rad.
    pub default_deviation_theta: f64,
    /// Longest interval between two `state` messages, ms; capped at [`MAX_STATE_INTERVAL_MS`].
    pub state_interval_ms: u64,
    /// Speed (m/s) from which the vehicle reports `driving`.
    pub driving_speed_threshold: f64,
    /// Turn rate (rad/s) from which the vehicle reports `driving`.
    pub driving_turn_threshold: f64,
    /// Action types the caller can run on nodes and edges; orders with other node or edge
    /// actions are rejected with `orderError`.
    pub order_action_types: Vec<String>,
    /// Instant action types the caller runs, beyond [`BUILT_IN_INSTANT_ACTIONS`].
    pub instant_action_types: Vec<String>,
    /// Whether the caller's navigator follows edge trajectories; if not, orders with a
    /// trajectory are rejected with `orderError`.
    pub trajectories_supported: bool,
}

impl VehicleConfig {
    /// Settings with the defaults: 0.25 m and 0.35 rad node tolerance, a state at least every
    /// 30 s, `driving` from 0.01 m/s or 0.01 rad/s, no caller-run actions, no trajectories.
    pub fn new(manufacturer: impl Into<String>, serial_number: impl Into<String>) -> Self {
        VehicleConfig {
            manufacturer: manufacturer.into(),
            serial_number: serial_number.into(),
            default_deviation_xy: 0.25,
            default_deviation_theta: 0.35,
            state_interval_ms: MAX_STATE_INTERVAL_MS,
            driving_speed_threshold: 0.01,
            driving_turn_threshold: 0.01,
            order_action_types: Vec::new(),
            instant_action_types: Vec::new(),
            trajectories_supported: false,
        }
    }
}

/// What [`Vehicle::accept_order`] did with an order it did not reject.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OrderAcceptance {
    /// A new order (new `orderId`) was taken over.
    New,
    /// An update (same `orderId`, higher `orderUpdateId`) was stitched onto the current order.
    Updated,
    /// The same `orderId` and `orderUpdateId` arrived again and was ignored (section 6.6.4.3).
    Duplicate,
}

/// Where the vehicle stands, as the caller's localiser reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseReport {
    /// X on the map, m.
    pub x: f64,
    /// Y on the map, m.
    pub y: f64,
    /// Heading, rad (wrapped into (−π, π] when reported).
    pub theta: f64,
    /// Map of the position.
    pub map_id: String,
    /// Whether the localiser has a position fix at all.
    pub position_initialized: bool,
    /// `localizationScore` in [0, 1], e.g. from [`crate::localization::localization_score`].
    pub localization_score: Option<f64>,
    /// `deviationRange`, m, e.g. from [`crate::localization::deviation_range`].
    pub deviation_range: Option<f64>,
    /// Measured velocity in vehicle coordinates.
    pub velocity: Velocity,
}

impl PoseReport {
    /// A report from a pose estimate with a 3×3 (x, y, yaw) covariance: score and range derived
    /// as documented in [`crate::localization`].
    pub fn from_estimate(
        x: f64,
        y: f64,
        yaw: f64,
        cov: &[[f64; 3]; 3],
        map_id: &str,
        velocity: Velocity,
    ) -> Self {
        let p = agv_position_from_estimate(x, y, yaw, cov, map_id, true);
        PoseReport {
            x: p.x,
            y: p.y,
            theta: p.theta,
            map_id: p.map_id,
            position_initialized: true,
            localization_score: p.localization_score,
            deviation_range: p.deviation_range,
            velocity,
        }
    }
}

/// A node reached while processing a pose report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeRef {
    /// Node id.
    pub node_id: String,
    /// Sequence id.
    pub sequence_id: u32,
}

/// The next node to drive to; the caller's navigator drives there.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Node id.
    pub node_id: String,
    /// Sequence id.
    pub sequence_id: u32,
    /// Edge leading to the node.
    pub edge_id: String,
    /// X on the map, m.
    pub x: f64,
    /// Y on the map, m.
    pub y: f64,
    /// Heading to assume on the node, if the order sets one.
    pub theta: Option<f64>,
    /// Map of the node.
    pub map_id: String,
    /// Radius within which the node counts as reached, m.
    pub allowed_deviation_xy: f64,
    /// Heading tolerance on the node, rad.
    pub allowed_deviation_theta: f64,
    /// Speed limit on the edge, m/s.
    pub max_speed: Option<f64>,
}

/// Result of a pose report.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Nodes reached with this report, in order.
    pub reached: Vec<NodeRef>,
    /// Where to drive now; `None` to stand still.
    pub target: Option<Target>,
}

/// An `initPosition` request waiting for the caller to carry it out.
#[derive(Debug, Clone, PartialEq)]
pub struct InitPositionRequest {
    /// Id of the `initPosition` action.
    pub action_id: String,
    /// X, m.
    pub x: f64,
    /// Y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
    /// Map id.
    pub map_id: String,
    /// Node the vehicle stands on, if given.
    pub last_node_id: Option<String>,
}

/// The non-header content of the factsheet, which the caller describes.
#[derive(Debug, Clone, PartialEq)]
pub struct FactsheetContent {
    /// `typeSpecification`.
    pub type_specification: crate::messages::TypeSpecification,
    /// `physicalParameters`.
    pub physical_parameters: crate::messages::PhysicalParameters,
    /// `protocolLimits`.
    pub protocol_limits: crate::messages::ProtocolLimits,
    /// `protocolFeatures`; see [`Vehicle::supported_actions`] for `agvActions`.
    pub protocol_features: crate::messages::ProtocolFeatures,
    /// `agvGeometry`.
    pub agv_geometry: crate::messages::AgvGeometry,
    /// `loadSpecification`.
    pub load_specification: crate::messages::LoadSpecification,
    /// `vehicleConfig`.
    pub vehicle_config: Option<crate::messages::VehicleConfigInfo>,
}

/// Where an action came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Origin {
    Node(u32),
    Edge(u32),
    Instant,
}

#[derive(Debug, Clone, PartialEq)]
struct Tracked {
    action: Action,
    origin: Origin,
    status: ActionStatus,
    result: Option<String>,
    triggered: bool,
    status_before_pause: Option<ActionStatus>,
}

impl Tracked {
    fn new(action: Action, origin: Origin) -> Self {
        Tracked {
            action,
            origin,
            status: ActionStatus::Waiting,
            result: None,
            triggered: false,
            status_before_pause: None,
        }
    }

    fn active(&self) -> bool {
        self.triggered && !self.status.is_terminal()
    }
}

/// Header counters, one per topic the vehicle sends on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Counters {
    state: u32,
    visualization: u32,
    connection: u32,
    factsheet: u32,
}

fn next_id(counter: &mut u32) -> u32 {
    let id = *counter;
    *counter = counter.wrapping_add(1);
    id
}

/// Smallest difference between two angles, rad in [0, π].
fn angle_distance(a: f64, b: f64) -> f64 {
    wrap_angle(a - b).abs()
}

/// The vehicle side of VDA 5050: order, action states, errors and the state message.
#[derive(Debug, Clone)]
pub struct Vehicle {
    config: VehicleConfig,
    order_id: String,
    order_update_id: u32,
    zone_set_id: Option<String>,
    /// Nodes still to traverse (base and horizon).
    nodes: Vec<Node>,
    /// Edges still to traverse (base and horizon).
    edges: Vec<Edge>,
    /// Last released node of the order so far: where an update has to stitch on.
    base_end: Option<NodeRef>,
    entered_edge: Option<u32>,
    last_node_id: String,
    last_node_sequence_id: u32,
    order_cancelled: bool,
    cancel_action: Option<String>,
    actions: Vec<Tracked>,
    pose: Option<AgvPosition>,
    velocity: Option<Velocity>,
    driving: bool,
    paused: bool,
    init_request: Option<InitPositionRequest>,
    /// Rejections and action problems, kept until the next accepted order.
    rejection_errors: Vec<Error>,
    /// Errors the caller sets for device problems.
    device_errors: Vec<Error>,
    information: Option<Vec<Info>>,
    loads: Option<Vec<Load>>,
    battery: BatteryState,
    operating_mode: OperatingMode,
    safety: SafetyState,
    counters: Counters,
    last_state_at: Option<Timestamp>,
    dirty: bool,
    state_requested: bool,
    factsheet_requested: bool,
}

impl Vehicle {
    /// A vehicle with no order, no position, battery unknown (0 %, not charging), operating
    /// mode AUTOMATIC, no e-stop.
    pub fn new(mut config: VehicleConfig) -> Self {
        config.state_interval_ms = config.state_interval_ms.min(MAX_STATE_INTERVAL_MS);
        Vehicle {
            config,
            order_id: String::new(),
            order_update_id: 0,
            zone_set_id: None,
            nodes: Vec::new(),
            edges: Vec::new(),
            base_end: None,
            entered_edge: None,
            last_node_id: String::new(),
            last_node_sequence_id: 0,
            order_cancelled: false,
            cancel_action: None,
            actions: Vec::new(),
            pose: None,
            velocity: None,
            driving: false,
            paused: false,
            init_request: None,
            rejection_errors: Vec::new(),
            device_errors: Vec::new(),
            information: None,
            loads: None,
            battery: BatteryState {
                battery_charge: 0.0,
                battery_voltage: None,
                battery_health: None,
                charging: false,
                reach: None,
            },
            operating_mode: OperatingMode::Automatic,
            safety: SafetyState {
                e_stop: EStop::None,
                field_violation: false,
            },
            counters: Counters::default(),
            last_state_at: None,
            dirty: true,
            state_requested: false,
            factsheet_requested: false,
        }
    }

    /// The settings.
    pub fn config(&self) -> &VehicleConfig {
        &self.config
    }

    fn header(&self, header_id: u32, now: Timestamp) -> Header {
        Header {
            header_id,
            timestamp: now.to_iso8601(),
            version: PROTOCOL_VERSION.to_owned(),
            manufacturer: self.config.manufacturer.clone(),
            serial_number: self.config.serial_number.clone(),
        }
    }

    // ----------------------------------------------------------------- errors

    fn record_rejection(&mut self, e: &Vda5050Error) {
        let entry = e.to_state_error();
        self.rejection_errors
            .retain(|x| x.error_type != entry.error_type);
        self.rejection_errors.push(entry);
        self.dirty = true;
    }

    /// Adds (or replaces, by `errorType`) a device error, e.g. a stale sensor.
    pub fn add_error(&mut self, error: Error) {
        if let Some(old) = self
            .device_errors
            .iter_mut()
            .find(|e| e.error_type == error.error_type)
        {
            if *old != error {
                *old = error;
                self.dirty = true;
            }
        } else {
            self.device_errors.push(error);
            self.dirty = true;
        }
    }

    /// Removes the device error of `error_type`; `true` if there was one.
    pub fn clear_error(&mut self, error_type: &str) -> bool {
        let before = self.device_errors.len();
        self.device_errors.retain(|e| e.error_type != error_type);
        let removed = self.device_errors.len() != before;
        self.dirty |= removed;
        removed
    }

    /// Every active error: rejections and action problems, then device errors.
    pub fn errors(&self) -> Vec<Error> {
        self.rejection_errors
            .iter()
            .chain(self.device_errors.iter())
            .cloned()
            .collect()
    }

    fn has_fatal_error(&self) -> bool {
        self.device_errors
            .iter()
            .any(|e| e.error_level == ErrorLevel::Fatal)
    }

    // ----------------------------------------------------------------- orders

    /// Whether the vehicle is executing an order or waiting for its update: node states left,
    /// or an action state that is neither FINISHED nor FAILED (figure 8, step 3).
    pub fn is_executing(&self) -> bool {
        !self.nodes.is_empty() || self.actions.iter().any(|a| !a.status.is_terminal())
    }

    /// Parses `bytes` as an order and accepts it; a parse failure is recorded as a
    /// `validationError` like any other rejection.
    pub fn handle_order_bytes(
        &mut self,
        bytes: &[u8],
        now: Timestamp,
    ) -> Result<OrderAcceptance, Vda5050Error> {
        match parse_order(bytes) {
            Ok(order) => self.accept_order(order, now),
            Err(e) => {
                self.record_rejection(&e);
                Err(e)
            }
        }
    }

    /// Takes over a new order or an order update, or rejects it (figure 8).
    ///
    /// On rejection the error is also added to `state.errors` (as a WARNING, kept until an
    /// order is accepted), and the current order goes on unchanged.
    pub fn accept_order(
        &mut self,
        order: Order,
        now: Timestamp,
    ) -> Result<OrderAcceptance, Vda5050Error> {
        let _ = now;
        let result = self.try_accept(order);
        match &result {
            Ok(OrderAcceptance::Duplicate) => {}
            Ok(_) => {
                self.rejection_errors.clear();
                self.dirty = true;
            }
            Err(e) => self.record_rejection(e),
        }
        result
    }

    /// Rejects `order` for a reason the caller found (e.g. `noRouteError` from a vehicle whose
    /// localiser cannot drive): the error goes into `state.errors` like the vehicle's own
    /// rejections, with the order's references, and the current order goes on unchanged.
    pub fn reject_order(
        &mut self,
        order: &Order,
        kind: ErrorKind,
        description: impl Into<String>,
    ) -> Vda5050Error {
        let e = Self::reject(kind, order, description.into());
        self.record_rejection(&e);
        e
    }

    fn refs(order: &Order) -> [Reference; 3] {
        [
            Reference::new("headerId", order.header.header_id.to_string()),
            Reference::new("orderId", order.order_id.clone()),
            Reference::new("orderUpdateId", order.order_update_id.to_string()),
        ]
    }

    fn reject(kind: ErrorKind, order: &Order, description: String) -> Vda5050Error {
        let mut e = Vda5050Error::new(kind, description);
        e.references.push(Reference::new("topic", "order"));
        e.references.extend(Self::refs(order));
        e
    }

    fn try_accept(&mut self, order: Order) -> Result<OrderAcceptance, Vda5050Error> {
        validate_order(&order)?;
        if order.header.serial_number != self.config.serial_number
            || order.header.manufacturer != self.config.manufacturer
        {
            return Err(Self::reject(
                ErrorKind::Validation,
                &order,
                format!(
                    "order is for {}/{}, not this vehicle",
                    order.header.manufacturer, order.header.serial_number
                ),
            ));
        }
        if !matches!(
            self.operating_mode,
            OperatingMode::Automatic | OperatingMode::Semiautomatic
        ) {
            return Err(Self::reject(
                ErrorKind::Order,
                &order,
                format!(
                    "operating mode {:?} takes no orders from master control",
                    self.operating_mode
                ),
            ));
        }
        if order.order_id == self.order_id {
            if order.order_update_id < self.order_update_id {
                return Err(Self::reject(
                    ErrorKind::OrderUpdate,
                    &order,
                    format!(
                        "orderUpdateId {} is lower than the current {}",
                        order.order_update_id, self.order_update_id
                    ),
                ));
            }
            if order.order_update_id == self.order_update_id {
                return Ok(OrderAcceptance::Duplicate);
            }
            self.check_capabilities(&order)?;
            self.stitch_update(order)?;
            return Ok(OrderAcceptance::Updated);
        }
        if self.is_executing() {
            return Err(Self::reject(
                ErrorKind::Order,
                &order,
                format!(
                    "order {} arrived while order {} is still being executed",
                    order.order_id, self.order_id
                ),
            ));
        }
        self.check_capabilities(&order)?;
        self.check_first_node_reachable(&order)?;
        self.take_new_order(order);
        Ok(OrderAcceptance::New)
    }

    /// `orderError` for actions the vehicle cannot run or fields it cannot use, `noRouteError`
    /// for nodes without a position.
    fn check_capabilities(&self, order: &Order) -> Result<(), Vda5050Error> {
        for node in &order.nodes {
            if node.node_position.is_none() {
                return Err(Self::reject(
                    ErrorKind::NoRoute,
                    order,
                    format!("node {} has no nodePosition to drive to", node.node_id),
                )
                .with_reference(Reference::new("nodeId", node.node_id.clone())));
            }
        }
        let node_actions = order.nodes.iter().flat_map(|n| n.actions.iter());
        let edge_actions = order.edges.iter().flat_map(|e| e.actions.iter());
        for action in node_actions.chain(edge_actions) {
            if !self.config.order_action_types.contains(&action.action_type) {
                return Err(Self::reject(
                    ErrorKind::Order,
                    order,
                    format!("action type {} is not supported", action.action_type),
                )
                .with_reference(Reference::new("actionId", action.action_id.clone()))
                .with_reference(Reference::new("actionType", action.action_type.clone())));
            }
        }
        if !self.config.trajectories_supported {
            if let Some(edge) = order.edges.iter().find(|e| e.trajectory.is_some()) {
                return Err(Self::reject(
                    ErrorKind::Order,
                    order,
                    format!(
                        "edge {} has a trajectory, which is not supported",
                        edge.edge_id
                    ),
                )
                .with_reference(Reference::new("edgeId", edge.edge_id.clone())));
            }
        }
        Ok(())
    }

    fn within(&self, node: &Node, pose: &AgvPosition) -> bool {
        let Some(p) = &node.node_position else {
            return false;
        };
        if p.map_id != pose.map_id {
            return false;
        }
        let dev_xy = p
            .allowed_deviation_xy
            .filter(|d| *d > 0.0)
            .unwrap_or(self.config.default_deviation_xy);
        let dev_theta = p
            .allowed_deviation_theta
            .filter(|d| *d > 0.0)
            .unwrap_or(self.config.default_deviation_theta);
        let close = (pose.x - p.x).hypot(pose.y - p.y) <= dev_xy;
        let aligned = p
            .theta
            .is_none_or(|t| angle_distance(pose.theta, t) <= dev_theta);
        close && aligned
    }

    fn check_first_node_reachable(&self, order: &Order) -> Result<(), Vda5050Error> {
        let Some(first) = order.nodes.first() else {
            return Err(Self::reject(
                ErrorKind::Validation,
                order,
                "order has no node".to_owned(),
            ));
        };
        let Some(pose) = self.pose.as_ref().filter(|p| p.position_initialized) else {
            return Err(Self::reject(
                ErrorKind::NoRoute,
                order,
                "the vehicle's position is not initialised".to_owned(),
            ));
        };
        if self.within(first, pose) {
            Ok(())
        } else {
            Err(Self::reject(
                ErrorKind::NoRoute,
                order,
                format!(
                    "first node {} is not within its deviation range of the vehicle",
                    first.node_id
                ),
            )
            .with_reference(Reference::new("nodeId", first.node_id.clone())))
        }
    }

    fn last_released(order: &Order) -> Option<NodeRef> {
        order
            .nodes
            .iter()
            .take_while(|n| n.released)
            .last()
            .map(|n| NodeRef {
                node_id: n.node_id.clone(),
                sequence_id: n.sequence_id,
            })
    }

    fn track_actions(&mut self, nodes: &[Node], edges: &[Edge]) {
        // In sequence order: node, edge, node, …
        let mut items: Vec<(u32, &[Action], bool)> = nodes
            .iter()
            .map(|n| (n.sequence_id, n.actions.as_slice(), true))
            .chain(
                edges
                    .iter()
                    .map(|e| (e.sequence_id, e.actions.as_slice(), false)),
            )
            .collect();
        items.sort_by_key(|(seq, _, _)| *seq);
        for (seq, actions, is_node) in items {
            let origin = if is_node {
                Origin::Node(seq)
            } else {
                Origin::Edge(seq)
            };
            for a in actions {
                self.actions.push(Tracked::new(a.clone(), origin));
            }
        }
    }

    fn take_new_order(&mut self, order: Order) {
        // Action states are kept until a new order arrives; states of running instant actions
        // are kept (section 6.10.6).
        self.actions
            .retain(|a| a.origin == Origin::Instant && !a.status.is_terminal());
        self.base_end = Self::last_released(&order);
        self.order_id = order.order_id;
        self.order_update_id = order.order_update_id;
        self.zone_set_id = order.zone_set_id;
        self.order_cancelled = false;
        self.entered_edge = None;
        self.track_actions(&order.nodes, &order.edges);
        self.nodes = order.nodes;
        self.edges = order.edges;
        // The first node is trivially reachable (checked): it counts as traversed at once.
        if !self.nodes.is_empty() {
            let first = self.nodes.remove(0);
            self.traverse(first);
        }
        self.enter_edge_if_allowed();
    }

    fn stitch_update(&mut self, order: Order) -> Result<(), Vda5050Error> {
        let Some(first) = order.nodes.first() else {
            return Err(Self::reject(
                ErrorKind::Validation,
                &order,
                "order has no node".to_owned(),
            ));
        };
        let executing = self.is_executing();
        let stitch_ok = if executing {
            self.base_end
                .as_ref()
                .is_some_and(|b| b.node_id == first.node_id && b.sequence_id == first.sequence_id)
        } else {
            first.node_id == self.last_node_id && first.sequence_id == self.last_node_sequence_id
        };
        if !stitch_ok {
            let (id, seq) = match (&self.base_end, executing) {
                (Some(b), true) => (b.node_id.clone(), b.sequence_id),
                _ => (self.last_node_id.clone(), self.last_node_sequence_id),
            };
            return Err(Self::reject(
                ErrorKind::OrderUpdate,
                &order,
                format!(
                    "update starts at node {} (sequenceId {}), not at {} (sequenceId {})",
                    first.node_id, first.sequence_id, id, seq
                ),
            )
            .with_reference(Reference::new("nodeId", first.node_id.clone())));
        }
        let stitch_seq = first.sequence_id;
        // Drop the old horizon and the waiting actions on it.
        self.nodes.retain(|n| n.released);
        self.edges.retain(|e| e.released);
        self.actions.retain(|a| match a.origin {
            Origin::Node(s) | Origin::Edge(s) => {
                s <= stitch_seq || a.status != ActionStatus::Waiting
            }
            Origin::Instant => true,
        });
        // The stitching node keeps its contents from the earlier message.
        let new_nodes: Vec<Node> = order.nodes.iter().skip(1).cloned().collect();
        let new_edges: Vec<Edge> = order.edges.clone();
        self.track_actions(&new_nodes, &new_edges);
        if let Some(end) = Self::last_released(&order) {
            self.base_end = Some(end);
        }
        self.nodes.extend(new_nodes);
        self.edges.extend(new_edges);
        self.order_update_id = order.order_update_id;
        if order.zone_set_id.is_some() {
            self.zone_set_id = order.zone_set_id;
        }
        self.order_cancelled = false;
        self.enter_edge_if_allowed();
        Ok(())
    }

    /// Marks `node` traversed: last node, leaves the edge leading to it (finishing that edge's
    /// actions) and triggers the node's actions.
    fn traverse(&mut self, node: Node) {
        self.last_node_id = node.node_id;
        self.last_node_sequence_id = node.sequence_id;
        let seq = node.sequence_id;
        self.edges.retain(|e| e.sequence_id >= seq);
        for a in &mut self.actions {
            match a.origin {
                Origin::Edge(s) if s < seq && !a.status.is_terminal() => {
                    a.status = ActionStatus::Finished;
                }
                Origin::Node(s) if s == seq => a.triggered = true,
                _ => {}
            }
        }
        self.entered_edge = None;
        self.dirty = true;
    }

    /// Whether driving is held back: paused, cancelling, a FATAL error, a mode without master
    /// control, or an active SOFT or HARD action.
    fn blocked(&self) -> bool {
        self.paused
            || self.cancel_action.is_some()
            || self.has_fatal_error()
            || !matches!(
                self.operating_mode,
                OperatingMode::Automatic | OperatingMode::Semiautomatic
            )
            || self
                .actions
                .iter()
                .any(|a| a.active() && a.action.blocking_type != BlockingType::None)
    }

    fn enter_edge_if_allowed(&mut self) {
        if self.blocked() || self.entered_edge.is_some() {
            return;
        }
        let Some(edge) = self.edges.first() else {
            return;
        };
        if !edge.released || edge.sequence_id != self.last_node_sequence_id.wrapping_add(1) {
            return;
        }
        let seq = edge.sequence_id;
        self.entered_edge = Some(seq);
        for a in &mut self.actions {
            if a.origin == Origin::Edge(seq) {
                a.triggered = true;
            }
        }
        self.dirty = true;
    }

    /// The next node to drive to, or `None` to stand still (no released node left, paused,
    /// cancelling, FATAL error, blocking action, or a mode without master control).
    pub fn next_target(&self) -> Option<Target> {
        if self.blocked() {
            return None;
        }
        let node = self.nodes.first().filter(|n| n.released)?;
        let edge = self.edges.first()?;
        let p = node.node_position.as_ref()?;
        Some(Target {
            node_id: node.node_id.clone(),
            sequence_id: node.sequence_id,
            edge_id: edge.edge_id.clone(),
            x: p.x,
            y: p.y,
            theta: p.theta,
            map_id: p.map_id.clone(),
            allowed_deviation_xy: p
                .allowed_deviation_xy
                .filter(|d| *d > 0.0)
                .unwrap_or(self.config.default_deviation_xy),
            allowed_deviation_theta: p
                .allowed_deviation_theta
                .filter(|d| *d > 0.0)
                .unwrap_or(self.config.default_deviation_theta),
            max_speed: edge.max_speed,
        })
    }

    /// Takes a pose report: updates position and velocity, `driving`, counts nodes as reached
    /// (within `allowedDeviationXY`/`Theta` or the defaults) and returns where to drive next.
    ///
    /// Fails with a `validationError` (and changes nothing) for a non-finite pose or velocity,
    /// a score outside [0, 1] or a negative deviation range.
    pub fn update_pose(
        &mut self,
        report: PoseReport,
        now: Timestamp,
    ) -> Result<Progress, Vda5050Error> {
        let _ = now;
        let v = &report.velocity;
        let finite = [report.x, report.y, report.theta]
            .iter()
            .all(|x| x.is_finite())
            && [v.vx, v.vy, v.omega]
                .iter()
                .flatten()
                .all(|x| x.is_finite())
            && report
                .localization_score
                .is_none_or(|s| (0.0..=1.0).contains(&s))
            && report
                .deviation_range
                .is_none_or(|d| d.is_finite() && d >= 0.0);
        if !finite {
            return Err(Vda5050Error::new(
                ErrorKind::Validation,
                "pose report holds a non-finite value or an out-of-range score or deviation",
            ));
        }
        let speed = v.vx.unwrap_or(0.0).hypot(v.vy.unwrap_or(0.0));
        let turn = v.omega.unwrap_or(0.0).abs();
        let driving = speed >= self.config.driving_speed_threshold
            || turn >= self.config.driving_turn_threshold;
        if driving != self.driving {
            self.driving = driving;
            self.dirty = true;
        }
        let pose = AgvPosition {
            x: report.x,
            y: report.y,
            theta: wrap_angle(report.theta),
            map_id: report.map_id,
            map_description: None,
            position_initialized: report.position_initialized,
            localization_score: report.localization_score,
            deviation_range: report.deviation_range,
        };
        if self.pose.as_ref().map(|p| p.position_initialized) != Some(pose.position_initialized) {
            self.dirty = true;
        }
        self.velocity = Some(report.velocity);
        let mut reached = Vec::new();
        if pose.position_initialized {
            while !self.blocked() {
                let Some(node) = self.nodes.first().filter(|n| n.released) else {
                    break;
                };
                if !self.within(node, &pose) {
                    break;
                }
                let node = self.nodes.remove(0);
                reached.push(NodeRef {
                    node_id: node.node_id.clone(),
                    sequence_id: node.sequence_id,
                });
                self.traverse(node);
                self.enter_edge_if_allowed();
            }
        }
        self.pose = Some(pose);
        self.finish_cancel_if_stopped();
        Ok(Progress {
            reached,
            target: self.next_target(),
        })
    }

    fn finish_cancel_if_stopped(&mut self) {
        if self.driving {
            return;
        }
        if let Some(id) = self.cancel_action.take() {
            self.set_status(&id, ActionStatus::Finished, None);
        }
    }

    // ---------------------------------------------------------------- actions

    fn set_status(&mut self, action_id: &str, status: ActionStatus, result: Option<String>) {
        if let Some(a) = self
            .actions
            .iter_mut()
            .find(|a| a.action.action_id == action_id)
        {
            if a.status != status || (result.is_some() && a.result != result) {
                a.status = status;
                if result.is_some() {
                    a.result = result;
                }
                self.dirty = true;
            }
        }
    }

    /// Parses `bytes` as instant actions and handles them; a parse failure is recorded as a
    /// `validationError`.
    pub fn handle_instant_actions_bytes(
        &mut self,
        bytes: &[u8],
        now: Timestamp,
    ) -> Result<(), Vda5050Error> {
        match parse_instant_actions(bytes) {
            Ok(msg) => self.accept_instant_actions(&msg, now),
            Err(e) => {
                self.record_rejection(&e);
                Err(e)
            }
        }
    }

    /// Handles instant actions in the order received. Each gets an action state: the built-in
    /// ones ([`BUILT_IN_INSTANT_ACTIONS`]) are carried out here, configured caller-run types wait
    /// for the caller ([`Vehicle::actions_to_start`]), and unknown types FAIL with an
    /// `unsupportedInstantAction` warning.
    ///
    /// Fails as a whole (validationError) only if the message is malformed or addressed to
    /// another vehicle.
    pub fn accept_instant_actions(
        &mut self,
        msg: &InstantActions,
        now: Timestamp,
    ) -> Result<(), Vda5050Error> {
        let _ = now;
        let checked = validate_instant_actions(msg).and_then(|()| {
            if msg.header.serial_number != self.config.serial_number
                || msg.header.manufacturer != self.config.manufacturer
            {
                Err(Vda5050Error::new(
                    ErrorKind::Validation,
                    format!(
                        "instant actions are for {}/{}, not this vehicle",
                        msg.header.manufacturer, msg.header.serial_number
                    ),
                )
                .with_reference(Reference::new("topic", "instantActions"))
                .with_reference(Reference::new("headerId", msg.header.header_id.to_string())))
            } else {
                Ok(())
            }
        });
        if let Err(e) = checked {
            self.record_rejection(&e);
            return Err(e);
        }
        for action in &msg.actions {
            self.run_instant(action.clone());
        }
        self.enter_edge_if_allowed();
        Ok(())
    }

    fn action_error(kind: ErrorKind, action: &Action, description: String) -> Vda5050Error {
        Vda5050Error::new(kind, description)
            .with_reference(Reference::new("actionId", action.action_id.clone()))
            .with_reference(Reference::new("actionType", action.action_type.clone()))
    }

    fn run_instant(&mut self, action: Action) {
        if self
            .actions
            .iter()
            .any(|a| a.action.action_id == action.action_id)
        {
            let e = Self::action_error(
                ErrorKind::Validation,
                &action,
                format!("actionId {} is already in use", action.action_id),
            );
            self.record_rejection(&e);
            return;
        }
        let id = action.action_id.clone();
        let mut tracked = Tracked::new(action, Origin::Instant);
        tracked.triggered = true;
        self.actions.push(tracked);
        self.dirty = true;
        let Some(action) = self.actions.last().map(|t| t.action.clone()) else {
            return;
        };
        match action.action_type.as_str() {
            "cancelOrder" => self.cancel_order(&action),
            "startPause" => {
                self.set_paused(true);
                self.set_status(&id, ActionStatus::Finished, None);
            }
            "stopPause" => {
                self.set_paused(false);
                self.set_status(&id, ActionStatus::Finished, None);
            }
            "initPosition" => self.start_init_position(&action),
            "stateRequest" => {
                self.state_requested = true;
                self.set_status(&id, ActionStatus::Finished, None);
            }
            "factsheetRequest" => {
                self.factsheet_requested = true;
                self.set_status(&id, ActionStatus::Finished, None);
            }
            other if self.config.instant_action_types.iter().any(|t| t == other) => {}
            other => {
                let e = Self::action_error(
                    ErrorKind::UnsupportedInstantAction,
                    &action,
                    format!("instant action type {other} is not supported"),
                );
                self.record_rejection(&e);
                self.set_status(
                    &id,
                    ActionStatus::Failed,
                    Some(format!("unsupported action type {other}")),
                );
            }
        }
    }

    fn cancel_order(&mut self, action: &Action) {
        let has_order = !self.nodes.is_empty()
            || self
                .actions
                .iter()
                .any(|a| a.origin != Origin::Instant && !a.status.is_terminal());
        if !has_order || self.order_cancelled {
            let e = Self::action_error(
                ErrorKind::NoOrderToCancel,
                action,
                "cancelOrder without an order to cancel".to_owned(),
            );
            self.record_rejection(&e);
            self.set_status(&action.action_id, ActionStatus::Failed, None);
            return;
        }
        self.nodes.clear();
        self.edges.clear();
        self.entered_edge = None;
        self.base_end = None;
        for a in &mut self.actions {
            if a.origin != Origin::Instant && !a.status.is_terminal() {
                a.status = ActionStatus::Failed;
                a.result = Some("order cancelled".to_owned());
            }
        }
        self.order_cancelled = true;
        if self.driving {
            self.set_status(&action.action_id, ActionStatus::Running, None);
            self.cancel_action = Some(action.action_id.clone());
        } else {
            self.set_status(&action.action_id, ActionStatus::Finished, None);
        }
        self.dirty = true;
    }

    fn start_init_position(&mut self, action: &Action) {
        let num = |k: &str| action.parameter(k).and_then(serde_json::Value::as_f64);
        let text = |k: &str| {
            action
                .parameter(k)
                .and_then(serde_json::Value::as_str)
                .map(str::to_owned)
        };
        let parsed = match (num("x"), num("y"), num("theta"), text("mapId")) {
            (Some(x), Some(y), Some(theta), Some(map_id))
                if x.is_finite()
                    && y.is_finite()
                    && (-ANGLE_LIMIT..=ANGLE_LIMIT).contains(&theta)
                    && !map_id.is_empty() =>
            {
                Some(InitPositionRequest {
                    action_id: action.action_id.clone(),
                    x,
                    y,
                    theta,
                    map_id,
                    last_node_id: text("lastNodeId"),
                })
            }
            _ => None,
        };
        let Some(request) = parsed else {
            let e = Self::action_error(
                ErrorKind::Validation,
                action,
                "initPosition needs numbers x, y, theta in [-pi, pi] and a string mapId".to_owned(),
            );
            self.record_rejection(&e);
            self.set_status(
                &action.action_id,
                ActionStatus::Failed,
                Some("invalid parameters".to_owned()),
            );
            return;
        };
        if let Some(old) = self.init_request.take() {
            self.set_status(
                &old.action_id,
                ActionStatus::Failed,
                Some("superseded by a later initPosition".to_owned()),
            );
        }
        self.set_status(&action.action_id, ActionStatus::Running, None);
        self.init_request = Some(request);
    }

    /// The `initPosition` the caller has to carry out, if any.
    pub fn pending_init_position(&self) -> Option<&InitPositionRequest> {
        self.init_request.as_ref()
    }

    /// Reports the outcome of the pending `initPosition`. On success the position becomes the
    /// requested one (initialised, no score until the next pose report) and `lastNodeId` the
    /// requested node; the action FINISHES. On failure it FAILS with `reason`.
    /// Returns `false` if no initPosition was pending.
    pub fn finish_init_position(&mut self, result: Result<(), String>, now: Timestamp) -> bool {
        let _ = now;
        let Some(req) = self.init_request.take() else {
            return false;
        };
        match result {
            Ok(()) => {
                self.pose = Some(AgvPosition {
                    x: req.x,
                    y: req.y,
                    theta: req.theta,
                    map_id: req.map_id.clone(),
                    map_description: None,
                    position_initialized: true,
                    localization_score: None,
                    deviation_range: None,
                });
                if let Some(node) = req.last_node_id {
                    self.last_node_id = node;
                    self.last_node_sequence_id = 0;
                }
                self.set_status(&req.action_id, ActionStatus::Finished, None);
            }
            Err(reason) => self.set_status(&req.action_id, ActionStatus::Failed, Some(reason)),
        }
        self.dirty = true;
        true
    }

    /// Triggered actions the caller may start now, in order: WAITING, their node reached or
    /// their edge entered (or instant), respecting HARD blocking (a HARD action starts only
    /// alone and nothing starts beside it). Empty while paused.
    pub fn actions_to_start(&self) -> Vec<Action> {
        if self.paused {
            return Vec::new();
        }
        let running: Vec<&Tracked> = self
            .actions
            .iter()
            .filter(|a| a.active() && a.status != ActionStatus::Waiting)
            .collect();
        if running
            .iter()
            .any(|a| a.action.blocking_type == BlockingType::Hard)
        {
            return Vec::new();
        }
        let mut out = Vec::new();
        for a in self
            .actions
            .iter()
            .filter(|a| a.triggered && a.status == ActionStatus::Waiting)
        {
            if self.init_request.as_ref().map(|r| &r.action_id) == Some(&a.action.action_id) {
                continue;
            }
            if a.action.blocking_type == BlockingType::Hard {
                if running.is_empty() && out.is_empty() {
                    out.push(a.action.clone());
                }
                break;
            }
            out.push(a.action.clone());
        }
        out
    }

    /// Sets the status (and optionally the result) of an action the caller runs. Returns
    /// `false`, changing nothing, for an unknown id or an action already FINISHED or FAILED.
    pub fn set_action_status(
        &mut self,
        action_id: &str,
        status: ActionStatus,
        result_description: Option<String>,
    ) -> bool {
        let Some(a) = self
            .actions
            .iter()
            .find(|a| a.action.action_id == action_id)
        else {
            return false;
        };
        if a.status.is_terminal() {
            return false;
        }
        self.set_status(action_id, status, result_description);
        self.enter_edge_if_allowed();
        true
    }

    /// The action states as they go into `state`.
    pub fn action_states(&self) -> Vec<ActionState> {
        self.actions
            .iter()
            .map(|a| ActionState {
                action_id: a.action.action_id.clone(),
                action_type: Some(a.action.action_type.clone()),
                action_description: a.action.action_description.clone(),
                action_status: a.status,
                result_description: a.result.clone(),
            })
            .collect()
    }

    /// Pauses or resumes (a pause button, or the pause instant actions). Pausing stops
    /// driving and puts running actions in PAUSED; resuming restores them.
    pub fn set_paused(&mut self, paused: bool) {
        if paused == self.paused {
            return;
        }
        self.paused = paused;
        for a in &mut self.actions {
            if paused
                && a.triggered
                && matches!(a.status, ActionStatus::Running | ActionStatus::Initializing)
            {
                a.status_before_pause = Some(a.status);
                a.status = ActionStatus::Paused;
            } else if !paused && a.status == ActionStatus::Paused {
                if let Some(s) = a.status_before_pause.take() {
                    a.status = s;
                }
            }
        }
        self.dirty = true;
        if !paused {
            self.enter_edge_if_allowed();
        }
    }

    /// Whether the vehicle is paused.
    pub fn is_paused(&self) -> bool {
        self.paused
    }

    /// Whether a `stateRequest` is waiting to be answered (by [`Vehicle::state`]).
    pub fn state_requested(&self) -> bool {
        self.state_requested
    }

    /// Whether a `factsheetRequest` is waiting to be answered (by [`Vehicle::factsheet`]).
    pub fn factsheet_requested(&self) -> bool {
        self.factsheet_requested
    }

    // ----------------------------------------------------------- other state

    /// Sets the battery information (not by itself a reason to publish).
    pub fn set_battery_state(&mut self, battery: BatteryState) {
        self.battery = battery;
    }

    /// Sets the operating mode. Entering or leaving MANUAL clears the order (section 6.10.6):
    /// node and edge states go, unfinished order actions FAIL.
    pub fn set_operating_mode(&mut self, mode: OperatingMode) {
        if mode == self.operating_mode {
            return;
        }
        let manual_change =
            mode == OperatingMode::Manual || self.operating_mode == OperatingMode::Manual;
        self.operating_mode = mode;
        if manual_change {
            self.nodes.clear();
            self.edges.clear();
            self.entered_edge = None;
            self.base_end = None;
            for a in &mut self.actions {
                if a.origin != Origin::Instant && !a.status.is_terminal() {
                    a.status = ActionStatus::Failed;
                    a.result = Some("order cleared by operating mode change".to_owned());
                }
            }
        }
        self.dirty = true;
    }

    /// Sets the safety state; a change triggers a state message.
    pub fn set_safety_state(&mut self, safety: SafetyState) {
        if safety != self.safety {
            self.safety = safety;
            self.dirty = true;
        }
    }

    /// Sets the loads (`None`: the vehicle cannot tell); a change triggers a state message.
    pub fn set_loads(&mut self, loads: Option<Vec<Load>>) {
        if loads != self.loads {
            self.loads = loads;
            self.dirty = true;
        }
    }

    /// Sets the information entries (visualisation and debugging only).
    pub fn set_information(&mut self, information: Option<Vec<Info>>) {
        if information != self.information {
            self.information = information;
            self.dirty = true;
        }
    }

    /// Current `orderId` (`""` before the first order).
    pub fn order_id(&self) -> &str {
        &self.order_id
    }

    /// Current `orderUpdateId`.
    pub fn order_update_id(&self) -> u32 {
        self.order_update_id
    }

    /// `lastNodeId` and `lastNodeSequenceId`.
    pub fn last_node(&self) -> (&str, u32) {
        (&self.last_node_id, self.last_node_sequence_id)
    }

    /// Whether the vehicle reports `driving`.
    pub fn is_driving(&self) -> bool {
        self.driving
    }

    // -------------------------------------------------------------- messages

    /// Whether a `state` should be sent now: something relevant changed since the last one, a
    /// `stateRequest` arrived, none was sent yet, or the interval (at most 30 s) has passed.
    pub fn publish_due(&self, now: Timestamp) -> bool {
        self.dirty
            || self.state_requested
            || self
                .last_state_at
                .is_none_or(|t| now.millis_since(t) >= self.config.state_interval_ms)
    }

    /// Builds the `state` message, advancing the state topic's headerId and marking the state
    /// as sent at `now`.
    pub fn state(&mut self, now: Timestamp) -> State {
        let header = {
            let id = next_id(&mut self.counters.state);
            self.header(id, now)
        };
        self.last_state_at = Some(now);
        self.dirty = false;
        self.state_requested = false;
        State {
            header,
            maps: None,
            order_id: self.order_id.clone(),
            order_update_id: self.order_update_id,
            zone_set_id: self.zone_set_id.clone(),
            last_node_id: self.last_node_id.clone(),
            last_node_sequence_id: self.last_node_sequence_id,
            node_states: self
                .nodes
                .iter()
                .map(|n| NodeState {
                    node_id: n.node_id.clone(),
                    sequence_id: n.sequence_id,
                    node_description: n.node_description.clone(),
                    released: n.released,
                    node_position: n.node_position.clone(),
                })
                .collect(),
            edge_states: self
                .edges
                .iter()
                .map(|e| EdgeState {
                    edge_id: e.edge_id.clone(),
                    sequence_id: e.sequence_id,
                    edge_description: e.edge_description.clone(),
                    released: e.released,
                    trajectory: e.trajectory.clone(),
                })
                .collect(),
            agv_position: self.pose.clone(),
            velocity: self.velocity.clone(),
            loads: self.loads.clone(),
            driving: self.driving,
            paused: Some(self.paused),
            new_base_request: None,
            distance_since_last_node: None,
            action_states: self.action_states(),
            battery_state: self.battery.clone(),
            operating_mode: self.operating_mode,
            errors: self.errors(),
            information: self.information.clone(),
            safety_state: self.safety.clone(),
        }
    }

    /// Builds a `visualization` message (its own headerId sequence).
    pub fn visualization(&mut self, now: Timestamp) -> Visualization {
        let header = {
            let id = next_id(&mut self.counters.visualization);
            self.header(id, now)
        };
        Visualization {
            header,
            agv_position: self.pose.clone(),
            velocity: self.velocity.clone(),
        }
    }

    /// Builds a `connection` message (its own headerId sequence). For the MQTT last will, build
    /// one with [`ConnectionState::Connectionbroken`] when connecting.
    pub fn connection(&mut self, state: ConnectionState, now: Timestamp) -> Connection {
        Connection {
            header: {
                let id = next_id(&mut self.counters.connection);
                self.header(id, now)
            },
            connection_state: state,
        }
    }

    /// Builds the `factsheet` message from `content` (its own headerId sequence) and clears a
    /// pending `factsheetRequest`.
    pub fn factsheet(&mut self, content: &FactsheetContent, now: Timestamp) -> Factsheet {
        self.factsheet_requested = false;
        Factsheet {
            header: {
                let id = next_id(&mut self.counters.factsheet);
                self.header(id, now)
            },
            type_specification: content.type_specification.clone(),
            physical_parameters: content.physical_parameters.clone(),
            protocol_limits: content.protocol_limits.clone(),
            protocol_features: content.protocol_features.clone(),
            agv_geometry: content.agv_geometry.clone(),
            load_specification: content.load_specification.clone(),
            vehicle_config: content.vehicle_config.clone(),
        }
    }

    /// `agvActions` for the factsheet: the built-in instant actions and the configured
    /// caller-run types.
    pub fn supported_actions(&self) -> Vec<AgvAction> {
        let param = |key: &str, t: ValueDataType, optional: bool| FactsheetActionParameter {
            key: key.to_owned(),
            value_data_type: t,
            description: None,
            is_optional: optional.then_some(true),
        };
        let mut out: Vec<AgvAction> = BUILT_IN_INSTANT_ACTIONS
            .iter()
            .map(|t| AgvAction {
                action_type: (*t).to_owned(),
                action_description: None,
                action_scopes: vec![ActionScope::Instant],
                action_parameters: (*t == "initPosition").then(|| {
                    vec![
                        param("x", ValueDataType::Number, false),
                        param("y", ValueDataType::Number, false),
                        param("theta", ValueDataType::Number, false),
                        param("mapId", ValueDataType::String, false),
                        param("lastNodeId", ValueDataType::String, true),
                    ]
                }),
                result_description: None,
            })
            .collect();
        let mut types: Vec<&String> = self.config.order_action_types.iter().collect();
        for t in &self.config.instant_action_types {
            if !types.contains(&t) {
                types.push(t);
            }
        }
        for t in types {
            let mut scopes = Vec::new();
            if self.config.instant_action_types.contains(t) {
                scopes.push(ActionScope::Instant);
            }
            if self.config.order_action_types.contains(t) {
                scopes.push(ActionScope::Node);
                scopes.push(ActionScope::Edge);
            }
            out.push(AgvAction {
                action_type: t.clone(),
                action_description: None,
                action_scopes: scopes,
                action_parameters: None,
                result_description: None,
            });
        }
        out
    }
}

/// Caps a message rate: [`RateLimiter::ready`] says yes at most once per interval.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RateLimiter {
    min_interval_ms: u64,
    last: Option<Timestamp>,
}

impl RateLimiter {
    /// At most one message every `min_interval_ms` milliseconds.
    pub fn new(min_interval_ms: u64) -> Self {
        RateLimiter {
            min_interval_ms,
            last: None,
        }
    }

    /// At most `hz` messages per second (`hz` ≤ 0 or not finite: one per hour).
    pub fn from_hz(hz: f64) -> Self {
        let ms = if hz.is_finite() && hz > 0.0 {
            (1000.0 / hz).round().clamp(0.0, 3_600_000.0)
        } else {
            3_600_000.0
        };
        // The clamp above keeps the value in u64 range.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let ms = ms as u64;
        RateLimiter::new(ms)
    }

    /// Whether a message may go out at `now`; if so, `now` counts as the last one.
    pub fn ready(&mut self, now: Timestamp) -> bool {
        // A clock that went backwards does not silence the topic.
        let ok = self
            .last
            .is_none_or(|t| now < t || now.millis_since(t) >= self.min_interval_ms);
        if ok {
            self.last = Some(now);
        }
        ok
    }
}
