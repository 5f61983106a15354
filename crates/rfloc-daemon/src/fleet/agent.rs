//! The robot as a VDA 5050 vehicle, without I/O: what arrives (poses, device states, orders,
//! instant actions, initialisation results) goes in with the current time; what to publish and
//! what to tell the estimator thread comes out in an [`Outbox`].

use std::collections::BTreeMap;

use rfloc_pose::{EstimateMode, Pose2};
use rfloc_vda5050::messages::{
    BatteryState, ConnectionState, Error as VdaError, ErrorLevel, Reference, Velocity,
};
use rfloc_vda5050::{
    ErrorKind, FactsheetContent, PoseReport, RateLimiter, Timestamp, Topic, TopicPrefix, Vehicle,
    VehicleConfig,
};

use crate::config::{EstimatorConfig, FleetConfig};
use crate::events::DeviceState;
use crate::pipeline::Goal;

use super::{Control, Sample};

/// One MQTT message to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Publish {
    pub topic: String,
    pub payload: Vec<u8>,
    /// MQTT QoS level (0 or 1).
    pub qos: u8,
    pub retain: bool,
}

/// What one input produced.
#[derive(Debug, Default)]
pub struct Outbox {
    /// Messages to publish, in order.
    pub publish: Vec<Publish>,
    /// Controls for the estimator thread, in order.
    pub controls: Vec<Control>,
    /// Stop the base now (a zero velocity request, before the pipeline hears of it).
    pub stop_base: bool,
}

/// Why the agent could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    #[error("fleet topics: {0}")]
    Topic(#[from] rfloc_vda5050::Vda5050Error),
}

/// A device the fleet manager hears about (stale or failed).
#[derive(Debug, Clone)]
struct DeviceCondition {
    driver: &'static str,
    state: DeviceState,
    detail: String,
}

/// The vehicle agent.
pub struct Agent {
    vehicle: Vehicle,
    prefix: TopicPrefix,
    map_id: String,
    factsheet: FactsheetContent,
    drives: bool,
    visualization: Option<RateLimiter>,
    battery_range: (f64, f64),
    battery_v: Option<f64>,
    devices: BTreeMap<String, DeviceCondition>,
    /// The goal the estimator thread was last told.
    goal_sent: Option<Goal>,
    /// The `initPosition` handed to the estimator thread, waiting for its result.
    init_sent: Option<String>,
    /// Whether anything is published (false while the broker is away).
    connected: bool,
    /// Inputs refused (malformed, wrong version, another vehicle, unsupported).
    pub rejections: u64,
}

/// The instant actions this agent carries out.
const INSTANT_ACTIONS: [&str; 6] = rfloc_vda5050::vehicle::BUILT_IN_INSTANT_ACTIONS;

/// Timestamp of a wall-clock instant.
#[must_use]
pub fn timestamp(t: std::time::SystemTime) -> Timestamp {
    let ms = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX));
    Timestamp::from_unix_millis(ms).unwrap_or(Timestamp::EPOCH)
}

impl Agent {
    /// An agent for the robot file's `[fleet]`, on a robot whose pipeline `drives` to goals.
    ///
    /// # Errors
    /// Topic levels the checks let through but the protocol crate refuses.
    pub fn new(
        fleet: &FleetConfig,
        estimator: &EstimatorConfig,
        default_map: &str,
        drives: bool,
    ) -> Result<Self, AgentError> {
        let prefix = TopicPrefix::new(
            &fleet.interface_name,
            &fleet.manufacturer,
            &fleet.serial_number,
        )?;
        let mut config = VehicleConfig::new(&fleet.manufacturer, &fleet.serial_number);
        config.default_deviation_xy = fleet.node_tolerance_m;
        config.default_deviation_theta = fleet.node_tolerance_rad;
        // Whole milliseconds of a checked 1–30 s interval.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        {
            config.state_interval_ms = (fleet.state_interval_s * 1000.0).round() as u64;
        }
        let vehicle = Vehicle::new(config);
        let mut factsheet = super::factsheet::content(fleet, estimator, drives);
        factsheet.protocol_features.agv_actions = vehicle.supported_actions();
        Ok(Self {
            vehicle,
            prefix,
            map_id: fleet
                .map_id
                .clone()
                .unwrap_or_else(|| default_map.to_string()),
            factsheet,
            drives,
            visualization: (fleet.visualization_hz > 0.0)
                .then(|| RateLimiter::from_hz(fleet.visualization_hz)),
            battery_range: (fleet.battery_empty_v, fleet.battery_full_v),
            battery_v: None,
            devices: BTreeMap::new(),
            goal_sent: None,
            init_sent: None,
            connected: false,
            rejections: 0,
        })
    }

    /// The vehicle state machine (tests, benchmarks).
    #[must_use]
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The MQTT topic of `topic`.
    #[must_use]
    pub fn topic(&self, topic: Topic) -> String {
        self.prefix.topic(topic)
    }

    /// The topics to subscribe to: `order` and `instantActions`.
    #[must_use]
    pub fn subscriptions(&self) -> [String; 2] {
        [self.topic(Topic::Order), self.topic(Topic::InstantActions)]
    }

    fn message<T: serde::Serialize>(&self, topic: Topic, msg: &T) -> Option<Publish> {
        match serde_json::to_vec(msg) {
            Ok(payload) => Some(Publish {
                topic: self.topic(topic),
                payload,
                qos: topic.qos().level(),
                retain: topic.retained(),
            }),
            Err(e) => {
                tracing::error!(topic = %topic, error = %e, "fleet message not encoded");
                None
            }
        }
    }

    /// The `connection` message of `state` (the last will is the CONNECTIONBROKEN one).
    pub fn connection(&mut self, state: ConnectionState, now: Timestamp) -> Option<Publish> {
        let msg = self.vehicle.connection(state, now);
        self.message(Topic::Connection, &msg)
    }

    /// Connected to the broker: ONLINE, the factsheet and a full state.
    pub fn on_connected(&mut self, now: Timestamp, out: &mut Outbox) {
        self.connected = true;
        out.publish
            .extend(self.connection(ConnectionState::Online, now));
        self.publish_factsheet(now, out);
        self.publish_state(now, out);
    }

    /// The broker went away: nothing is published until it is back (the order goes on).
    pub fn on_disconnected(&mut self) {
        self.connected = false;
    }

    /// Whether the broker is there.
    #[must_use]
    pub fn is_connected(&self) -> bool {
        self.connected
    }

    fn publish_factsheet(&mut self, now: Timestamp, out: &mut Outbox) {
        let msg = self.vehicle.factsheet(&self.factsheet, now);
        out.publish.extend(self.message(Topic::Factsheet, &msg));
    }

    fn publish_state(&mut self, now: Timestamp, out: &mut Outbox) {
        if !self.connected {
            return;
        }
        self.refresh_battery();
        let msg = self.vehicle.state(now);
        out.publish.extend(self.message(Topic::State, &msg));
    }

    /// A `state` message now, due or not (benchmarks; a `stateRequest` gets one through the
    /// vehicle).
    pub fn state_now(&mut self, now: Timestamp) -> Option<Publish> {
        self.refresh_battery();
        let msg = self.vehicle.state(now);
        self.message(Topic::State, &msg)
    }

    /// A state when one is due (a change, a request, or the interval), and the factsheet when
    /// one was requested.
    fn flush(&mut self, now: Timestamp, out: &mut Outbox) {
        if !self.connected {
            return;
        }
        if self.vehicle.factsheet_requested() {
            self.publish_factsheet(now, out);
        }
        if self.vehicle.publish_due(now) {
            self.publish_state(now, out);
        }
    }

    /// A pose estimate (with the base's latest velocity) from the estimator thread.
    pub fn on_sample(&mut self, s: &Sample, now: Timestamp, out: &mut Outbox) {
        let cov: [[f64; 3]; 3] = s.covariance;
        let velocity = Velocity {
            vx: Some(s.v),
            vy: Some(0.0),
            omega: Some(s.w),
        };
        let mut report = PoseReport::from_estimate(
            s.pose.x,
            s.pose.y,
            s.pose.theta,
            &cov,
            &self.map_id,
            velocity,
        );
        report.position_initialized = s.mode != EstimateMode::NoFix;
        if let Err(e) = self.vehicle.update_pose(report, now) {
            tracing::debug!(error = %e, "pose not given to the fleet vehicle");
            return;
        }
        if self.connected {
            if let Some(limit) = self.visualization.as_mut() {
                if limit.ready(now) {
                    let msg = self.vehicle.visualization(now);
                    out.publish.extend(self.message(Topic::Visualization, &msg));
                }
            }
        }
        self.steer(out);
        self.flush(now, out);
    }

    /// The battery voltage the base reports.
    pub fn on_battery(&mut self, volts: f64) {
        if volts.is_finite() && volts > 0.0 {
            self.battery_v = Some(volts);
        }
    }

    fn refresh_battery(&mut self) {
        let Some(v) = self.battery_v else {
            return;
        };
        let (empty, full) = self.battery_range;
        let charge = ((v - empty) / (full - empty) * 100.0).clamp(0.0, 100.0);
        self.vehicle.set_battery_state(BatteryState {
            battery_charge: (charge * 10.0).round() / 10.0,
            battery_voltage: Some((v * 100.0).round() / 100.0),
            battery_health: None,
            charging: false,
            reach: None,
        });
    }

    /// A device changed state (from the router): stale and failed devices are `errors`.
    pub fn on_device(
        &mut self,
        name: &str,
        driver: &'static str,
        state: DeviceState,
        detail: &str,
        now: Timestamp,
        out: &mut Outbox,
    ) {
        match state {
            DeviceState::Stale | DeviceState::Failed | DeviceState::Reconnecting => {
                self.devices.insert(
                    name.to_string(),
                    DeviceCondition {
                        driver,
                        state,
                        detail: detail.to_string(),
                    },
                );
            }
            // Closed: the daemon is stopping; it goes OFFLINE next.
            DeviceState::Connected | DeviceState::Connecting | DeviceState::Closed => {
                self.devices.remove(name);
            }
        }
        self.refresh_device_errors();
        self.steer(out);
        self.flush(now, out);
    }

    /// One `deviceStale` (WARNING) and one `deviceFailed` error (FATAL when the base that drives
    /// the robot is among them, else WARNING), each naming its devices.
    fn refresh_device_errors(&mut self) {
        for (error_type, states) in [
            ("deviceStale", &[DeviceState::Stale][..]),
            (
                "deviceFailed",
                &[DeviceState::Failed, DeviceState::Reconnecting][..],
            ),
        ] {
            let hit: Vec<(&String, &DeviceCondition)> = self
                .devices
                .iter()
                .filter(|(_, c)| states.contains(&c.state))
                .collect();
            if hit.is_empty() {
                self.vehicle.clear_error(error_type);
                continue;
            }
            let fatal = error_type == "deviceFailed" && hit.iter().any(|(_, c)| c.driver == "aria");
            let description = hit
                .iter()
                .map(|(n, c)| format!("{n} ({}): {} {}", c.driver, c.state.as_str(), c.detail))
                .collect::<Vec<_>>()
                .join("; ");
            self.vehicle.add_error(VdaError {
                error_type: error_type.to_owned(),
                error_references: Some(
                    hit.iter()
                        .map(|(n, _)| Reference::new("device", n.as_str()))
                        .collect(),
                ),
                error_description: Some(description),
                error_hint: Some(if fatal {
                    "the base is down: the robot stands still until it is back".to_owned()
                } else {
                    "poses may be degraded".to_owned()
                }),
                error_level: if fatal {
                    ErrorLevel::Fatal
                } else {
                    ErrorLevel::Warning
                },
            });
        }
    }

    /// A message on a subscribed topic.
    pub fn on_message(&mut self, topic: &str, payload: &[u8], now: Timestamp, out: &mut Outbox) {
        if topic == self.topic(Topic::Order) {
            self.on_order(payload, now);
        } else if topic == self.topic(Topic::InstantActions) {
            self.on_instant_actions(payload, now, out);
        } else {
            tracing::warn!(topic, "message on a topic rfloc does not read; ignored");
            return;
        }
        self.steer(out);
        self.flush(now, out);
    }

    fn refused(&mut self, what: &str, e: &rfloc_vda5050::Vda5050Error) {
        self.rejections += 1;
        tracing::warn!(error_type = e.kind.error_type(), reason = %e.description, "fleet {what} refused");
    }

    fn on_order(&mut self, payload: &[u8], now: Timestamp) {
        let order = match rfloc_vda5050::parse_order(payload) {
            Ok(o) => o,
            Err(_) => {
                // The vehicle records the validationError itself.
                if let Err(e) = self.vehicle.handle_order_bytes(payload, now) {
                    self.refused("order", &e);
                }
                return;
            }
        };
        let own = order.header.serial_number == self.vehicle.config().serial_number
            && order.header.manufacturer == self.vehicle.config().manufacturer;
        let same_order = order.order_id == self.vehicle.order_id();
        if own && !same_order {
            if let Some(reason) = self.cannot_drive(&order) {
                let e = self
                    .vehicle
                    .reject_order(&order, ErrorKind::NoRoute, reason);
                self.refused("order", &e);
                return;
            }
        }
        let (id, update, nodes) = (
            order.order_id.clone(),
            order.order_update_id,
            order.nodes.len(),
        );
        match self.vehicle.accept_order(order, now) {
            Ok(how) => tracing::info!(
                order = %id,
                update,
                nodes,
                how = ?how,
                "fleet order accepted"
            ),
            Err(e) => self.refused("order", &e),
        }
    }

    /// Why this robot cannot drive `order`: a pipeline that does not drive and an order that
    /// goes anywhere, or a node on another map.
    fn cannot_drive(&self, order: &rfloc_vda5050::messages::Order) -> Option<String> {
        if !self.drives && order.nodes.len() > 1 {
            return Some(
                "this robot's pipeline cannot drive to goals (it only localises)".to_owned(),
            );
        }
        order
            .nodes
            .iter()
            .find(|n| {
                n.node_position
                    .as_ref()
                    .is_some_and(|p| p.map_id != self.map_id)
            })
            .map(|n| {
                format!(
                    "node {} is on another map than the robot's {:?}",
                    n.node_id, self.map_id
                )
            })
    }

    fn on_instant_actions(&mut self, payload: &[u8], now: Timestamp, out: &mut Outbox) {
        let msg = match rfloc_vda5050::parse_instant_actions(payload) {
            Ok(m) => m,
            Err(_) => {
                if let Err(e) = self.vehicle.handle_instant_actions_bytes(payload, now) {
                    self.refused("instantActions", &e);
                }
                return;
            }
        };
        for a in &msg.actions {
            if INSTANT_ACTIONS.contains(&a.action_type.as_str()) {
                tracing::info!(action = %a.action_id, kind = %a.action_type, "fleet instant action");
            } else {
                self.rejections += 1;
                tracing::warn!(action = %a.action_id, kind = %a.action_type, "fleet instant action type not supported; FAILED");
            }
        }
        if let Err(e) = self.vehicle.accept_instant_actions(&msg, now) {
            self.refused("instantActions", &e);
            return;
        }
        if msg.actions.iter().any(|a| a.action_type == "cancelOrder") {
            out.stop_base = true;
        }
        if let Some(init) = self.vehicle.pending_init_position() {
            if self.init_sent.as_deref() != Some(init.action_id.as_str()) {
                self.init_sent = Some(init.action_id.clone());
                out.controls.push(Control::InitPosition {
                    action_id: init.action_id.clone(),
                    pose: Pose2::new(init.x, init.y, init.theta),
                });
            }
        }
    }

    /// The estimator thread's answer to an `initPosition`.
    pub fn on_init_result(
        &mut self,
        action_id: &str,
        result: Result<(), String>,
        now: Timestamp,
        out: &mut Outbox,
    ) {
        if self.init_sent.as_deref() != Some(action_id) {
            return;
        }
        self.init_sent = None;
        match &result {
            Ok(()) => tracing::info!(action = action_id, "initPosition finished"),
            Err(e) => tracing::warn!(action = action_id, reason = %e, "initPosition failed"),
        }
        self.vehicle.finish_init_position(result, now);
        self.steer(out);
        self.flush(now, out);
    }

    /// The interval tick: a state when one is due.
    pub fn tick(&mut self, now: Timestamp, out: &mut Outbox) {
        self.flush(now, out);
    }

    /// Tells the estimator thread the next node, when it changed; stops the base when there is
    /// none any more.
    fn steer(&mut self, out: &mut Outbox) {
        if !self.drives {
            return;
        }
        let goal = self.vehicle.next_target().map(|t| Goal {
            x: t.x,
            y: t.y,
            tolerance_m: t.allowed_deviation_xy,
            max_speed: t.max_speed,
        });
        if goal == self.goal_sent {
            return;
        }
        match &goal {
            Some(g) => tracing::info!(x = g.x, y = g.y, "fleet goal: next node"),
            None => {
                tracing::info!("fleet goal: none (stand still)");
                out.stop_base = true;
            }
        }
        self.goal_sent = goal;
        out.controls.push(Control::Goal(goal));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{json, Value};

    fn fleet() -> FleetConfig {
        toml::from_str(
            "broker = \"127.0.0.1:1883\"\nmanufacturer = \"rfloc\"\nserial_number = \"r1\"\n",
        )
        .unwrap()
    }

    fn agent(drives: bool) -> Agent {
        let mut a = Agent::new(&fleet(), &EstimatorConfig::Odometry, "map", drives).unwrap();
        let mut out = Outbox::default();
        a.on_connected(t(0), &mut out);
        check(&out);
        a
    }

    fn t(ms: u64) -> Timestamp {
        Timestamp::from_unix_millis(1_800_000_000_000 + ms).unwrap()
    }

    fn sample(x: f64, y: f64, v: f64) -> Sample {
        Sample {
            time: 0.0,
            pose: Pose2::new(x, y, 0.0),
            covariance: [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]],
            mode: EstimateMode::Fix,
            v,
            w: 0.0,
        }
    }

    /// Every published message validates against its topic's schema; returns them as JSON.
    fn check(out: &Outbox) -> Vec<(String, Value)> {
        out.publish
            .iter()
            .map(|p| {
                let v: Value = serde_json::from_slice(&p.payload).unwrap();
                let topic = rfloc_vda5050::schema::topic_of(&p.topic).unwrap();
                rfloc_vda5050::schema::validate(topic, &v)
                    .unwrap_or_else(|e| panic!("{}: {e:#?}\n{v:#}", p.topic));
                assert_eq!(p.retain, topic.retained());
                (p.topic.clone(), v)
            })
            .collect()
    }

    fn last_state(out: &Outbox) -> Value {
        check(out)
            .into_iter()
            .rev()
            .find(|(t, _)| t.ends_with("/state"))
            .map(|(_, v)| v)
            .unwrap()
    }

    fn order(id: &str, serial: &str, version: &str, points: &[(f64, f64)]) -> Vec<u8> {
        let nodes: Vec<Value> = points
            .iter()
            .enumerate()
            .map(|(i, (x, y))| {
                json!({"nodeId": format!("n{i}"), "sequenceId": 2 * i, "released": true,
                "nodePosition": {"x": x, "y": y, "mapId": "map"}, "actions": []})
            })
            .collect();
        let edges: Vec<Value> = (1..points.len())
            .map(|i| {
                json!({"edgeId": format!("e{i}"), "sequenceId": 2 * i - 1, "released": true,
                "startNodeId": format!("n{}", i - 1), "endNodeId": format!("n{i}"), "actions": []})
            })
            .collect();
        serde_json::to_vec(
            &json!({"headerId": 1, "timestamp": "2027-01-01T00:00:00.000Z",
            "version": version, "manufacturer": "rfloc", "serialNumber": serial,
            "orderId": id, "orderUpdateId": 0, "nodes": nodes, "edges": edges}),
        )
        .unwrap()
    }

    fn instant(kind: &str, id: &str, params: Value) -> Vec<u8> {
        serde_json::to_vec(&json!({"headerId": 2, "timestamp": "2027-01-01T00:00:00.000Z",
            "version": "2.1.0", "manufacturer": "rfloc", "serialNumber": "r1",
            "actions": [{"actionType": kind, "actionId": id, "blockingType": "NONE", "actionParameters": params}]}))
        .unwrap()
    }

    fn error_types(state: &Value) -> Vec<String> {
        state["errors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["errorType"].as_str().unwrap().to_string())
            .collect()
    }

    #[test]
    fn connecting_publishes_online_factsheet_and_state() {
        let mut a = Agent::new(&fleet(), &EstimatorConfig::Odometry, "map", true).unwrap();
        let will = a
            .connection(ConnectionState::Connectionbroken, t(0))
            .unwrap();
        assert_eq!(will.topic, "uagv/v2/rfloc/r1/connection");
        assert!(will.retain && will.qos == 1);
        let mut out = Outbox::default();
        a.on_connected(t(1), &mut out);
        let msgs = check(&out);
        let topics: Vec<&str> = msgs
            .iter()
            .map(|(t, _)| t.rsplit('/').next().unwrap())
            .collect();
        assert_eq!(topics, ["connection", "factsheet", "state"]);
        assert_eq!(msgs[0].1["connectionState"], "ONLINE");
        assert_eq!(msgs[0].1["headerId"], 1, "the will had headerId 0");
        let actions: Vec<&str> = msgs[1].1["protocolFeatures"]["agvActions"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a["actionType"].as_str().unwrap())
            .collect();
        assert!(actions.contains(&"cancelOrder") && actions.contains(&"initPosition"));
        assert_eq!(a.subscriptions()[0], "uagv/v2/rfloc/r1/order");
    }

    #[test]
    fn an_order_becomes_goals_node_by_node_and_ends_with_a_stop() {
        let mut a = agent(true);
        let mut out = Outbox::default();
        a.on_sample(&sample(0.0, 0.0, 0.0), t(10), &mut out);
        let s = last_state(&out);
        assert_eq!(s["agvPosition"]["positionInitialized"], true);
        assert_eq!(s["agvPosition"]["localizationScore"], 0.5);
        let mut out = Outbox::default();
        a.on_message(
            "uagv/v2/rfloc/r1/order",
            &order("o1", "r1", "2.1.0", &[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]),
            t(20),
            &mut out,
        );
        let goal = |x: f64, y: f64| {
            Control::Goal(Some(Goal {
                x,
                y,
                tolerance_m: 0.25,
                max_speed: None,
            }))
        };
        assert_eq!(out.controls, vec![goal(1.0, 0.0)]);
        let s = last_state(&out);
        assert_eq!(
            (s["orderId"].as_str(), s["lastNodeId"].as_str()),
            (Some("o1"), Some("n0"))
        );
        assert_eq!(s["nodeStates"].as_array().unwrap().len(), 2);
        // Driving there: no new goal; reaching it: the next one.
        let mut out = Outbox::default();
        a.on_sample(&sample(0.5, 0.0, 0.3), t(30), &mut out);
        assert!(out.controls.is_empty());
        assert_eq!(last_state(&out)["driving"], true);
        let mut out = Outbox::default();
        a.on_sample(&sample(0.9, 0.05, 0.3), t(40), &mut out);
        assert_eq!(out.controls, vec![goal(1.0, 1.0)]);
        assert_eq!(last_state(&out)["lastNodeId"], "n1");
        let mut out = Outbox::default();
        a.on_sample(&sample(1.0, 0.9, 0.0), t(50), &mut out);
        assert_eq!(out.controls, vec![Control::Goal(None)]);
        assert!(out.stop_base);
        let s = last_state(&out);
        assert_eq!(s["lastNodeId"], "n2");
        assert!(s["nodeStates"].as_array().unwrap().is_empty());
    }

    #[test]
    fn bad_input_is_refused_with_vda_errors() {
        let mut a = agent(true);
        let mut out = Outbox::default();
        a.on_sample(&sample(0.0, 0.0, 0.0), t(10), &mut out);
        let topic = "uagv/v2/rfloc/r1/order";
        for (bytes, kind) in [
            (b"{not json".to_vec(), "validationError"),
            (order("o1", "r1", "1.1.0", &[(0.0, 0.0)]), "validationError"),
            (
                order("o1", "other", "2.1.0", &[(0.0, 0.0)]),
                "validationError",
            ),
            (
                order("o2", "r1", "2.1.0", &[(5.0, 5.0), (6.0, 5.0)]),
                "noRouteError",
            ),
        ] {
            let mut out = Outbox::default();
            a.on_message(topic, &bytes, t(20), &mut out);
            assert!(out.controls.is_empty());
            assert!(error_types(&last_state(&out)).contains(&kind.to_string()));
        }
        let mut out = Outbox::default();
        a.on_message(
            "uagv/v2/rfloc/r1/instantActions",
            &instant("fly", "a1", json!([])),
            t(30),
            &mut out,
        );
        let s = last_state(&out);
        assert!(error_types(&s).contains(&"unsupportedInstantAction".to_string()));
        assert_eq!(s["actionStates"][0]["actionStatus"], "FAILED");
        assert_eq!(a.rejections, 5);
    }

    #[test]
    fn a_pipeline_that_cannot_drive_refuses_orders_that_go_anywhere() {
        let mut a = agent(false);
        let mut out = Outbox::default();
        a.on_sample(&sample(0.0, 0.0, 0.0), t(10), &mut out);
        let topic = "uagv/v2/rfloc/r1/order";
        let mut out = Outbox::default();
        a.on_message(
            topic,
            &order("o1", "r1", "2.1.0", &[(0.0, 0.0), (1.0, 0.0)]),
            t(20),
            &mut out,
        );
        assert_eq!(error_types(&last_state(&out)), ["noRouteError"]);
        assert!(out.controls.is_empty());
        // Where it stands, an order of one node is fine.
        let mut out = Outbox::default();
        a.on_message(
            topic,
            &order("o2", "r1", "2.1.0", &[(0.0, 0.0)]),
            t(30),
            &mut out,
        );
        let s = last_state(&out);
        assert!(error_types(&s).is_empty());
        assert_eq!(s["lastNodeId"], "n0");
    }

    #[test]
    fn cancel_pause_and_init_position_reach_the_estimator() {
        let mut a = agent(true);
        let mut out = Outbox::default();
        a.on_sample(&sample(0.0, 0.0, 0.0), t(10), &mut out);
        let ia = "uagv/v2/rfloc/r1/instantActions";
        a.on_message(
            "uagv/v2/rfloc/r1/order",
            &order("o1", "r1", "2.1.0", &[(0.0, 0.0), (2.0, 0.0)]),
            t(20),
            &mut Outbox::default(),
        );
        let mut out = Outbox::default();
        a.on_message(ia, &instant("startPause", "p1", json!([])), t(30), &mut out);
        assert_eq!(out.controls, vec![Control::Goal(None)]);
        assert!(out.stop_base);
        assert_eq!(last_state(&out)["paused"], true);
        let mut out = Outbox::default();
        a.on_message(ia, &instant("stopPause", "p2", json!([])), t(40), &mut out);
        assert!(matches!(out.controls.as_slice(), [Control::Goal(Some(_))]));
        let mut out = Outbox::default();
        a.on_sample(&sample(0.5, 0.0, 0.3), t(50), &mut out);
        let mut out = Outbox::default();
        a.on_message(
            ia,
            &instant("cancelOrder", "c1", json!([])),
            t(60),
            &mut out,
        );
        assert_eq!(out.controls, vec![Control::Goal(None)]);
        assert!(out.stop_base);
        let s = last_state(&out);
        assert_eq!(
            s["actionStates"][2]["actionStatus"], "RUNNING",
            "until the robot stands"
        );
        let mut out = Outbox::default();
        a.on_sample(&sample(0.55, 0.0, 0.0), t(70), &mut out);
        assert_eq!(
            last_state(&out)["actionStates"][2]["actionStatus"],
            "FINISHED"
        );
        // initPosition goes to the pipeline; its answer finishes or fails the action.
        let params = json!([{"key": "x", "value": 1.0}, {"key": "y", "value": 2.0}, {"key": "theta", "value": 0.5}, {"key": "mapId", "value": "map"}]);
        let mut out = Outbox::default();
        a.on_message(ia, &instant("initPosition", "i1", params), t(80), &mut out);
        assert!(
            matches!(&out.controls[..], [Control::InitPosition { action_id, pose }] if action_id == "i1" && (pose.x - 1.0).abs() < 1e-12)
        );
        let mut out = Outbox::default();
        a.on_init_result("i1", Err("no".into()), t(90), &mut out);
        let s = last_state(&out);
        assert_eq!(s["actionStates"][3]["actionStatus"], "FAILED");
    }

    #[test]
    fn stale_and_failed_devices_are_errors_until_they_recover() {
        let mut a = agent(true);
        let mut out = Outbox::default();
        a.on_device(
            "xbee",
            "xbee",
            DeviceState::Stale,
            "silent for more than 60 s",
            t(10),
            &mut out,
        );
        let s = last_state(&out);
        assert_eq!(error_types(&s), ["deviceStale"]);
        assert_eq!(s["errors"][0]["errorLevel"], "WARNING");
        assert_eq!(
            s["errors"][0]["errorReferences"][0]["referenceValue"],
            "xbee"
        );
        let mut out = Outbox::default();
        a.on_device(
            "base",
            "aria",
            DeviceState::Failed,
            "task ended",
            t(20),
            &mut out,
        );
        let s = last_state(&out);
        assert_eq!(error_types(&s), ["deviceStale", "deviceFailed"]);
        assert_eq!(s["errors"][1]["errorLevel"], "FATAL");
        let mut out = Outbox::default();
        a.on_device(
            "base",
            "aria",
            DeviceState::Connected,
            "robot",
            t(30),
            &mut out,
        );
        a.on_device(
            "xbee",
            "xbee",
            DeviceState::Connected,
            "data again",
            t(40),
            &mut out,
        );
        assert!(error_types(&last_state(&out)).is_empty());
    }

    #[test]
    fn the_battery_voltage_becomes_a_charge() {
        let mut a = agent(true);
        a.on_battery(11.9);
        let mut out = Outbox::default();
        a.on_message(
            "uagv/v2/rfloc/r1/instantActions",
            &instant("stateRequest", "s1", json!([])),
            t(10),
            &mut out,
        );
        let s = last_state(&out);
        assert_eq!(s["batteryState"]["batteryVoltage"], 11.9);
        assert_eq!(s["batteryState"]["batteryCharge"], 50.0);
    }

    #[test]
    fn nothing_is_published_while_the_broker_is_away() {
        let mut a = agent(true);
        a.on_disconnected();
        let mut out = Outbox::default();
        a.on_sample(&sample(0.0, 0.0, 0.3), t(10), &mut out);
        a.tick(t(40_000), &mut out);
        assert!(out.publish.is_empty());
        a.on_connected(t(50_000), &mut out);
        assert_eq!(check(&out).len(), 3);
    }
}
