//! UHF RFID snapshot localisation, clustering, MDP value iteration and navigation (pure, no I/O
//! except the atomic save/load of the learned database in [`store`]).
#![forbid(unsafe_code)]

pub mod action;
pub mod cluster;
pub mod cycle;
pub mod distance;
pub mod error;
pub mod explore;
pub mod snapshot;
pub mod tag;
pub mod transition;
pub mod value_iteration;

pub use action::{integrate, Action, ActionTable, MotionCommand};
pub use cluster::{ClusterCount, Clustering, ClusteringMethod};
pub use cycle::CycleBreaker;
pub use distance::{DissimilarityMatrix, SnapshotDistance};
pub use error::SnapshotError;
pub use explore::{ExplorationConfig, ExplorationInput, ExplorationPolicy};
pub use snapshot::{AverageConfig, AverageTagSet, Snapshot};
pub use tag::TagId;
pub use transition::{TransitionCounts, TransitionModel, TransitionPrior, TransitionRow};
pub use value_iteration::{q_values, value_iteration, ValueIterationConfig, ValueIterationResult};

pub mod database;
pub mod filter;
pub mod joint;
pub mod lattice;
pub mod navigate;
mod posegraph;
mod readpass;
mod readtable;
mod simd;
pub mod state_set;
pub mod store;
pub mod survey;
pub mod tagmap;
pub mod track;

pub use database::{
    LearnConfig, LearnedState, Localisation, Observation, SnapshotDatabase, FORMAT_VERSION,
};
pub use filter::{FilterConfig, StateFilter};
pub use joint::{learn_jointly, JointConfig, JointReport};
pub use lattice::{ActionModel, LatticeConfig, LatticePlan, MAX_LATTICE_STATES};
pub use navigate::{NavCommand, NavReason, Navigator, NavigatorConfig, Plan, PlanConfig};
pub use survey::{Survey, SurveySample, SURVEY_FORMAT_VERSION};
pub use tagmap::{LikelihoodScratch, MapObservation, MappedTag, ReadModel, TagMap, TagMapConfig};
pub use track::{FingerprintMap, TrackConfig, TrackEstimate, TrackFilter};
