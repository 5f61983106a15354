//! Clustering snapshots into states.
//!
//! Two methods, selected by [`ClusteringMethod`]: swap-based k-medoids ([`fasterpam`], an own
//! implementation of FasterPAM after Schubert & Rousseeuw 2021) and the seed's threshold
//! ("custom") clustering ([`threshold`]). Both return medoids: every state is represented by one
//! of the observed snapshots.

pub mod fasterpam;
pub mod threshold;

use serde::{Deserialize, Serialize};

use crate::distance::DissimilarityMatrix;

/// How many clusters k-medoids should find.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClusterCount {
    /// Exactly this many (capped at the number of snapshots).
    Fixed(usize),
    /// This fraction of the number of snapshots (the seed found 1/2 to 2/3 best, section 3.3.2).
    Fraction(f64),
}

impl ClusterCount {
    /// Resolves to a count in `1..=n` (0 when `n == 0`).
    #[must_use]
    pub fn resolve(self, n: usize) -> usize {
        let k = match self {
            ClusterCount::Fixed(k) => k,
            ClusterCount::Fraction(f) => (f.clamp(0.0, 1.0) * n as f64).round() as usize,
        };
        k.clamp(usize::from(n > 0), n)
    }
}

/// The clustering method and its parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum ClusteringMethod {
    /// FasterPAM k-medoids from a seeded k-means++-style initialisation.
    KMedoids {
        /// Number of clusters.
        k: ClusterCount,
        /// Maximum number of passes over the data.
        max_iter: usize,
        /// Seed of the initialisation RNG (ChaCha8).
        seed: u64,
    },
    /// The seed's leader clustering: each unassigned snapshot, in order, opens a cluster and
    /// absorbs every later unassigned snapshot within `max_distance` of it.
    Threshold {
        /// Largest dissimilarity to the leader for a snapshot to join its cluster.
        max_distance: f64,
    },
}

impl Default for ClusteringMethod {
    fn default() -> Self {
        ClusteringMethod::KMedoids {
            k: ClusterCount::Fraction(0.5),
            max_iter: 100,
            seed: 1,
        }
    }
}

/// Result of clustering `n` objects.
#[derive(Debug, Clone, PartialEq)]
pub struct Clustering {
    /// Object index of each cluster's medoid.
    pub medoids: Vec<usize>,
    /// Cluster index (into `medoids`) of every object.
    pub assignment: Vec<usize>,
    /// Sum of dissimilarities of every object to its medoid.
    pub loss: f64,
    /// Passes made (k-medoids) or 1 (threshold).
    pub iterations: usize,
    /// Medoid swaps performed (0 for threshold clustering).
    pub swaps: usize,
}

impl Clustering {
    /// Members of cluster `c`.
    #[must_use]
    pub fn members(&self, c: usize) -> Vec<usize> {
        self.assignment
            .iter()
            .enumerate()
            .filter(|(_, a)| **a == c)
            .map(|(i, _)| i)
            .collect()
    }
}

/// Runs the selected method on a dissimilarity matrix.
#[must_use]
pub fn cluster(d: &DissimilarityMatrix, method: &ClusteringMethod) -> Clustering {
    match *method {
        ClusteringMethod::KMedoids { k, max_iter, seed } => {
            let k = k.resolve(d.len());
            let init = fasterpam::init_kmeanspp(d, k, seed);
            fasterpam::fasterpam(d, init, max_iter)
        }
        ClusteringMethod::Threshold { max_distance } => threshold::leader(d, max_distance),
    }
}
