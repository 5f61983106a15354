//! The crate's error: a rejection the vehicle reports in `state.errors` with the specification's
//! error type.

use std::fmt;

use crate::messages::{Error as StateError, ErrorLevel, Reference};

/// The kind of rejection, each with the `errorType` the specification gives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// `validationError`: malformed message (JSON, types, version, ids, graph structure).
    Validation,
    /// `orderError`: the vehicle cannot perform the order's actions or use its fields, or a new
    /// order arrived while one is still being executed.
    Order,
    /// `orderUpdateError`: stale update, or an update that does not continue the current base.
    OrderUpdate,
    /// `noRouteError`: the vehicle cannot drive the route (no node position, other map, first
    /// node out of reach, position not initialised).
    NoRoute,
    /// `noOrderToCancel`: `cancelOrder` without an order to cancel.
    NoOrderToCancel,
    /// `unsupportedInstantAction`: an instant action of a type the vehicle does not know (this
    /// error type is this crate's, the specification leaves the name open).
    UnsupportedInstantAction,
}

impl ErrorKind {
    /// The `errorType` string reported in `state.errors`.
    pub fn error_type(self) -> &'static str {
        match self {
            ErrorKind::Validation => "validationError",
            ErrorKind::Order => "orderError",
            ErrorKind::OrderUpdate => "orderUpdateError",
            ErrorKind::NoRoute => "noRouteError",
            ErrorKind::NoOrderToCancel => "noOrderToCancel",
            ErrorKind::UnsupportedInstantAction => "unsupportedInstantAction",
        }
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.error_type())
    }
}

/// A rejected message or action, as the vehicle reports it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{kind}: {description}")]
pub struct Vda5050Error {
    /// Kind and so `errorType`.
    pub kind: ErrorKind,
    /// What was wrong, for `errorDescription`.
    pub description: String,
    /// References (`orderId`, `actionId`, `headerId`, …) for `errorReferences`.
    pub references: Vec<Reference>,
}

impl Vda5050Error {
    /// An error of `kind` described by `description`, without references.
    pub fn new(kind: ErrorKind, description: impl Into<String>) -> Self {
        Vda5050Error {
            kind,
            description: description.into(),
            references: Vec::new(),
        }
    }

    /// The same error with one more reference.
    pub fn with_reference(mut self, reference: Reference) -> Self {
        self.references.push(reference);
        self
    }

    /// The entry for `state.errors`; every rejection is a `WARNING` (sections 6.6.3.2, 6.6.4).
    pub fn to_state_error(&self) -> StateError {
        StateError {
            error_type: self.kind.error_type().to_owned(),
            error_references: (!self.references.is_empty()).then(|| self.references.clone()),
            error_description: Some(self.description.clone()),
            error_hint: None,
            error_level: ErrorLevel::Warning,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_types_are_spelled_as_the_specification() {
        let e = Vda5050Error::new(ErrorKind::OrderUpdate, "stale")
            .with_reference(Reference::new("orderId", "o1"));
        assert_eq!(e.to_string(), "orderUpdateError: stale");
        let s = e.to_state_error();
        assert_eq!(s.error_type, "orderUpdateError");
        assert_eq!(s.error_level, ErrorLevel::Warning);
        assert_eq!(s.error_references.unwrap()[0].reference_value, "o1");
        assert_eq!(ErrorKind::Validation.error_type(), "validationError");
        assert_eq!(ErrorKind::Order.error_type(), "orderError");
        assert_eq!(ErrorKind::NoRoute.error_type(), "noRouteError");
        assert_eq!(ErrorKind::NoOrderToCancel.error_type(), "noOrderToCancel");
    }
}
