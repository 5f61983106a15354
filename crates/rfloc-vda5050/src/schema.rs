//! Schema checks of messages (cargo feature `schema`): each topic's JSON Schema from `schemas/`,
//! built into the crate, with `format` (date-time) checked.

use std::sync::OnceLock;

use serde_json::Value;

use crate::topic::Topic;

const SOURCES: [(Topic, &str); 6] = [
    (Topic::Order, include_str!("../schemas/order.schema")),
    (
        Topic::InstantActions,
        include_str!("../schemas/instantActions.schema"),
    ),
    (Topic::State, include_str!("../schemas/state.schema")),
    (
        Topic::Visualization,
        include_str!("../schemas/visualization.schema"),
    ),
    (
        Topic::Connection,
        include_str!("../schemas/connection.schema"),
    ),
    (
        Topic::Factsheet,
        include_str!("../schemas/factsheet.schema"),
    ),
];

type Validators = Vec<(Topic, Result<jsonschema::Validator, String>)>;

fn validators() -> &'static Validators {
    static CELL: OnceLock<Validators> = OnceLock::new();
    CELL.get_or_init(|| {
        SOURCES
            .iter()
            .map(|(topic, text)| {
                let built = serde_json::from_str::<Value>(text)
                    .map_err(|e| e.to_string())
                    .and_then(|schema| {
                        jsonschema::options()
                            .should_validate_formats(true)
                            .build(&schema)
                            .map_err(|e| e.to_string())
                    });
                (*topic, built)
            })
            .collect()
    })
}

/// Checks `json` against the schema of `topic`; the errors name the failing value's path.
///
/// # Errors
/// Every schema violation as `message at /path`, or why the schema could not be built.
pub fn validate(topic: Topic, json: &Value) -> Result<(), Vec<String>> {
    let Some((_, built)) = validators().iter().find(|(t, _)| *t == topic) else {
        return Err(vec![format!("no schema for topic {topic}")]);
    };
    let validator = built
        .as_ref()
        .map_err(|e| vec![format!("schema of {topic}: {e}")])?;
    let errors: Vec<String> = validator
        .iter_errors(json)
        .map(|e| format!("{e} at {}", e.instance_path()))
        .collect();
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors)
    }
}

/// The topic named by the last level of an MQTT topic (`uagv/v2/acme/7/state` → `state`).
#[must_use]
pub fn topic_of(mqtt_topic: &str) -> Option<Topic> {
    let last = mqtt_topic.rsplit('/').next()?;
    Topic::ALL.into_iter().find(|t| t.name() == last)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_builds_and_checks() {
        for (topic, built) in validators() {
            assert!(built.is_ok(), "{topic}: {built:?}");
        }
        let bad = serde_json::json!({"headerId": 1});
        assert!(validate(Topic::Connection, &bad).is_err());
        assert_eq!(topic_of("uagv/v2/acme/7/state"), Some(Topic::State));
        assert_eq!(topic_of("uagv/v2/acme/7/nothing"), None);
    }
}
