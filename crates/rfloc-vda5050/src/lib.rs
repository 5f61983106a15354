//! The vehicle (AGV) side of VDA 5050 version 2.1.0, without I/O.
//!
//! * [`messages`]: the JSON messages as serde types (`Order`, `InstantActions`, `State`,
//!   `Visualization`, `Connection`, `Factsheet`), field names as the specification spells them.
//! * [`topic`]: MQTT topic names and the QoS per topic.
//! * [`parse`]: reading `order` and `instantActions` from bytes, answering a VDA 5050
//!   `validationError` for anything malformed.
//! * [`vehicle`]: the order/action state machine ([`Vehicle`]) that builds the `state`.
//! * [`localization`]: from a pose with a 3×3 covariance to `agvPosition`, with
//!   `localizationScore` and `deviationRange`.
//!
//! No MQTT, no sockets, no clocks: time is passed in as a [`Timestamp`].

#![forbid(unsafe_code)]

pub mod error;
pub mod localization;
pub mod messages;
pub mod parse;
#[cfg(feature = "schema")]
pub mod schema;
pub mod time;
pub mod topic;
pub mod vehicle;

pub use error::{ErrorKind, Vda5050Error};
pub use parse::{parse_instant_actions, parse_order};
pub use time::Timestamp;
pub use topic::{Qos, Topic, TopicPrefix};
pub use vehicle::{
    FactsheetContent, InitPositionRequest, NodeRef, OrderAcceptance, PoseReport, Progress,
    RateLimiter, Target, Vehicle, VehicleConfig,
};
