//! MQTT topic names and the quality of service the specification asks per topic (6.2, 6.3).

use std::fmt;

use crate::error::{ErrorKind, Vda5050Error};
use crate::messages::{Reference, PROTOCOL_MAJOR};

/// The subtopics of VDA 5050 2.1.0 (section 6.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `order`: master control → AGV.
    Order,
    /// `instantActions`: master control → AGV.
    InstantActions,
    /// `state`: AGV → master control.
    State,
    /// `visualization`: AGV → visualisation systems.
    Visualization,
    /// `connection`: AGV/broker → master control.
    Connection,
    /// `factsheet`: AGV → master control.
    Factsheet,
}

/// MQTT quality of service levels used by the specification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Qos {
    /// QoS 0, best effort.
    AtMostOnce,
    /// QoS 1, at least once.
    AtLeastOnce,
}

impl Qos {
    /// The MQTT numeric level.
    pub fn level(self) -> u8 {
        match self {
            Qos::AtMostOnce => 0,
            Qos::AtLeastOnce => 1,
        }
    }
}

impl Topic {
    /// Every topic, in the specification's order.
    pub const ALL: [Topic; 6] = [
        Topic::Order,
        Topic::InstantActions,
        Topic::State,
        Topic::Visualization,
        Topic::Connection,
        Topic::Factsheet,
    ];

    /// The last topic level, as spelled in the specification.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Order => "order",
            Topic::InstantActions => "instantActions",
            Topic::State => "state",
            Topic::Visualization => "visualization",
            Topic::Connection => "connection",
            Topic::Factsheet => "factsheet",
        }
    }

    /// QoS 1 for `connection`, QoS 0 for every other topic (section 6.2).
    pub fn qos(self) -> Qos {
        match self {
            Topic::Connection => Qos::AtLeastOnce,
            _ => Qos::AtMostOnce,
        }
    }

    /// Whether messages on the topic are sent with the retained flag (`connection`, sections
    /// 6.14, and `factsheet`, 6.15).
    pub fn retained(self) -> bool {
        matches!(self, Topic::Connection | Topic::Factsheet)
    }

    /// Whether the vehicle publishes on the topic (rather than subscribes to it).
    pub fn published_by_vehicle(self) -> bool {
        !matches!(self, Topic::Order | Topic::InstantActions)
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The topic prefix of one vehicle: `{interfaceName}/{majorVersion}/{manufacturer}/{serialNumber}`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicPrefix {
    prefix: String,
}

impl TopicPrefix {
    /// The prefix for `interface_name` (e.g. `uagv`), major version `v2`, `manufacturer` and
    /// `serial_number`.
    ///
    /// Fails with a `validationError` if a level is empty or holds `/`, `+`, `#` or `$`, which
    /// would change the topic hierarchy or clash with broker-internal topics (section 6.3).
    pub fn new(
        interface_name: &str,
        manufacturer: &str,
        serial_number: &str,
    ) -> Result<TopicPrefix, Vda5050Error> {
        for (key, level) in [
            ("interfaceName", interface_name),
            ("manufacturer", manufacturer),
            ("serialNumber", serial_number),
        ] {
            if level.is_empty() || level.contains(['/', '+', '#', '$']) {
                return Err(Vda5050Error::new(
                    ErrorKind::Validation,
                    format!("topic level {key} {level:?} is empty or holds / + # or $"),
                )
                .with_reference(Reference::new(key, level)));
            }
        }
        Ok(TopicPrefix {
            prefix: format!("{interface_name}/v{PROTOCOL_MAJOR}/{manufacturer}/{serial_number}"),
        })
    }

    /// The full topic, e.g. `uagv/v2/acme/robot-7/state`.
    pub fn topic(&self, topic: Topic) -> String {
        format!("{}/{}", self.prefix, topic.name())
    }

    /// The prefix alone.
    pub fn as_str(&self) -> &str {
        &self.prefix
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_strings_and_qos() {
        let p = TopicPrefix::new("uagv", "acme", "robot-7").unwrap();
        assert_eq!(p.topic(Topic::State), "uagv/v2/acme/robot-7/state");
        assert_eq!(
            p.topic(Topic::InstantActions),
            "uagv/v2/acme/robot-7/instantActions"
        );
        assert_eq!(p.as_str(), "uagv/v2/acme/robot-7");
        let qos: Vec<u8> = Topic::ALL.iter().map(|t| t.qos().level()).collect();
        assert_eq!(qos, vec![0, 0, 0, 0, 1, 0]);
        assert!(Topic::Connection.retained());
        assert!(Topic::Factsheet.retained());
        assert!(!Topic::State.retained());
        assert!(!Topic::Order.published_by_vehicle());
        assert!(Topic::Visualization.published_by_vehicle());
    }

    #[test]
    fn bad_levels_are_refused() {
        assert!(TopicPrefix::new("uagv", "ac/me", "1").is_err());
        assert!(TopicPrefix::new("uagv", "acme", "").is_err());
        assert!(TopicPrefix::new("uagv", "acme", "r#1").is_err());
        assert!(TopicPrefix::new("$SYS", "acme", "1").is_err());
    }
}
