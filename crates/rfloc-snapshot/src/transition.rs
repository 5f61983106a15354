//! Learned state-transition model per action: counts → probabilities.

use serde::{Deserialize, Serialize};

use crate::action::Action;
use crate::error::SnapshotError;

/// Transition counts `n_a(i → j)` over `n` states (the last one is conventionally the
/// "no tags visible" state), kept sparse: per action and source state, `(target, count)` pairs
/// sorted by target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransitionCounts {
    n: usize,
    counts: Vec<Vec<Vec<(usize, f64)>>>,
}

impl TransitionCounts {
    /// Zero counts for `n` states and the five actions.
    #[must_use]
    pub fn new(n: usize) -> Self {
        Self {
            n,
            counts: vec![vec![Vec::new(); n]; Action::COUNT],
        }
    }

    /// Number of states (including the no-tags state if the caller uses one).
    #[must_use]
    pub fn states(&self) -> usize {
        self.n
    }

    /// Adds `weight` to the count of `from --action--> to`.
    ///
    /// # Errors
    /// [`SnapshotError::StateOutOfRange`] when a state index is `>= states()`.
    pub fn record_weighted(
        &mut self,
        from: usize,
        action: Action,
        to: usize,
        weight: f64,
    ) -> Result<(), SnapshotError> {
        if from >= self.n || to >= self.n {
            return Err(SnapshotError::StateOutOfRange {
                state: from.max(to),
                states: self.n,
            });
        }
        let row = self
            .counts
            .get_mut(action.index())
            .and_then(|a| a.get_mut(from))
            .ok_or(SnapshotError::StateOutOfRange {
                state: from,
                states: self.n,
            })?;
        match row.binary_search_by_key(&to, |e| e.0) {
            Ok(pos) => {
                if let Some(e) = row.get_mut(pos) {
                    e.1 += weight;
                }
            }
            Err(pos) => row.insert(pos, (to, weight)),
        }
        Ok(())
    }

    /// Adds one observed transition.
    ///
    /// # Errors
    /// See [`TransitionCounts::record_weighted`].
    pub fn record(&mut self, from: usize, action: Action, to: usize) -> Result<(), SnapshotError> {
        self.record_weighted(from, action, to, 1.0)
    }

    /// Count of one transition.
    #[must_use]
    pub fn count(&self, from: usize, action: Action, to: usize) -> f64 {
        self.row(from, action)
            .iter()
            .find(|e| e.0 == to)
            .map_or(0.0, |e| e.1)
    }

    /// Total count out of `from` under `action`.
    #[must_use]
    pub fn row_total(&self, from: usize, action: Action) -> f64 {
        self.row(from, action).iter().map(|e| e.1).sum()
    }

    fn row(&self, from: usize, action: Action) -> &[(usize, f64)] {
        self.counts
            .get(action.index())
            .and_then(|a| a.get(from))
            .map_or(&[], Vec::as_slice)
    }

    /// Normalises counts into probabilities with the given prior.
    #[must_use]
    pub fn to_model(&self, prior: &TransitionPrior) -> TransitionModel {
        let n = self.n;
        let alpha = prior.alpha.max(0.0);
        let beta = prior.self_fraction.clamp(0.0, 1.0);
        let rows = (0..Action::COUNT)
            .map(|a| {
                (0..n)
                    .map(|s| {
                        let counts = self
                            .counts
                            .get(a)
                            .and_then(|r| r.get(s))
                            .map_or(&[][..], Vec::as_slice);
                        let total: f64 = counts.iter().map(|e| e.1).sum();
                        let z = total + alpha;
                        if z <= 0.0 {
                            return TransitionRow {
                                entries: vec![(s, 1.0)],
                                uniform: 0.0,
                            };
                        }
                        let mut entries: Vec<(usize, f64)> =
                            counts.iter().map(|&(j, c)| (j, c / z)).collect();
                        let self_mass = alpha * beta / z;
                        if self_mass > 0.0 {
                            match entries.binary_search_by_key(&s, |e| e.0) {
                                Ok(p) => {
                                    if let Some(e) = entries.get_mut(p) {
                                        e.1 += self_mass;
                                    }
                                }
                                Err(p) => entries.insert(p, (s, self_mass)),
                            }
                        }
                        TransitionRow {
                            entries,
                            uniform: alpha * (1.0 - beta) / z / n as f64,
                        }
                    })
                    .collect()
            })
            .collect();
        TransitionModel { n, rows }
    }
}

/// Prior for transitions never (or rarely) observed: a Dirichlet pseudo-count of total `alpha`
/// per (state, action) row, of which a fraction `self_fraction` sits on staying in the same state
/// and the rest is spread uniformly over all states:
/// `P(j | i, a) = (n_a(i→j) + α·β·[j = i] + α·(1−β)/N) / (Σ_j n_a(i→j) + α)`.
/// A row with no counts and `α = 0` becomes a self-loop. The seed's experiment code starts from
/// all-ones counts (Laplace smoothing, `α = N`, `β = 1/N`); its simulation normalises raw
/// counts (`α = 0`), leaving unseen rows as 0/0.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TransitionPrior {
    /// Total pseudo-count per row.
    pub alpha: f64,
    /// Share of the pseudo-count on the self-transition.
    pub self_fraction: f64,
}

impl Default for TransitionPrior {
    fn default() -> Self {
        Self {
            alpha: 1.0,
            self_fraction: 0.5,
        }
    }
}

/// One row of a transition matrix: `P(j) = uniform + entries[j]` (entries sparse, sorted).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransitionRow {
    /// Sparse part: `(target, probability)` sorted by target.
    pub entries: Vec<(usize, f64)>,
    /// Probability added to every target.
    pub uniform: f64,
}

impl TransitionRow {
    /// `P(j)`.
    #[must_use]
    pub fn prob(&self, j: usize) -> f64 {
        self.uniform
            + self
                .entries
                .binary_search_by_key(&j, |e| e.0)
                .ok()
                .and_then(|p| self.entries.get(p))
                .map_or(0.0, |e| e.1)
    }

    /// `Σ_j P(j)·v[j]`, given `sum_v = Σ_j v[j]`.
    #[must_use]
    pub fn expect(&self, v: &[f64], sum_v: f64) -> f64 {
        self.uniform * sum_v
            + self
                .entries
                .iter()
                .map(|&(j, p)| p * v.get(j).copied().unwrap_or(0.0))
                .sum::<f64>()
    }
}

/// Transition probabilities `P(j | i, a)` for every action, row-stochastic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransitionModel {
    n: usize,
    /// `rows[a][i]`.
    rows: Vec<Vec<TransitionRow>>,
}

impl TransitionModel {
    /// Builds a model from dense matrices `p[a][i][j]` (any number of actions), checking that
    /// they are square, non-negative and row-stochastic within `1e-10`.
    ///
    /// # Errors
    /// [`SnapshotError::InvalidModel`] describing the first violation.
    pub fn from_dense(p: &[Vec<Vec<f64>>]) -> Result<Self, SnapshotError> {
        let n = p.first().map_or(0, Vec::len);
        let mut rows = Vec::with_capacity(p.len());
        for (a, m) in p.iter().enumerate() {
            if m.len() != n {
                return Err(SnapshotError::InvalidModel(format!(
                    "action {a}: {} rows, expected {n}",
                    m.len()
                )));
            }
            let mut arows = Vec::with_capacity(n);
            for (i, r) in m.iter().enumerate() {
                if r.len() != n {
                    return Err(SnapshotError::InvalidModel(format!(
                        "action {a} row {i}: {} columns",
                        r.len()
                    )));
                }
                if r.iter().any(|x| !x.is_finite() || *x < 0.0) {
                    return Err(SnapshotError::InvalidModel(format!(
                        "action {a} row {i}: negative or non-finite"
                    )));
                }
                let s: f64 = r.iter().sum();
                if (s - 1.0).abs() > 1e-10 {
                    return Err(SnapshotError::InvalidModel(format!(
                        "action {a} row {i}: sums to {s}"
                    )));
                }
                let entries = r
                    .iter()
                    .copied()
                    .enumerate()
                    .filter(|(_, x)| *x != 0.0)
                    .collect();
                arows.push(TransitionRow {
                    entries,
                    uniform: 0.0,
                });
            }
            rows.push(arows);
        }
        Ok(Self { n, rows })
    }

    /// Number of states.
    #[must_use]
    pub fn states(&self) -> usize {
        self.n
    }

    /// Number of actions.
    #[must_use]
    pub fn actions(&self) -> usize {
        self.rows.len()
    }

    /// Row `P(· | i, a)`.
    #[must_use]
    pub fn row(&self, action: usize, from: usize) -> Option<&TransitionRow> {
        self.rows.get(action).and_then(|r| r.get(from))
    }

    /// `P(j | i, a)` (0 out of range).
    #[must_use]
    pub fn prob(&self, action: usize, from: usize, to: usize) -> f64 {
        if to >= self.n {
            return 0.0;
        }
        self.row(action, from).map_or(0.0, |r| r.prob(to))
    }

    /// Makes `state` absorbing under every action.
    pub fn make_absorbing(&mut self, state: usize) {
        for a in &mut self.rows {
            if let Some(r) = a.get_mut(state) {
                *r = TransitionRow {
                    entries: vec![(state, 1.0)],
                    uniform: 0.0,
                };
            }
        }
    }

    /// Pushes a distribution one step: `out[j] = Σ_i b[i]·P(j | i, a)`.
    #[must_use]
    pub fn propagate(&self, action: usize, belief: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n];
        let mut uniform = 0.0;
        if let Some(rows) = self.rows.get(action) {
            for (b, row) in belief.iter().zip(rows) {
                if *b == 0.0 {
                    continue;
                }
                uniform += b * row.uniform;
                for &(j, p) in &row.entries {
                    if let Some(o) = out.get_mut(j) {
                        *o += b * p;
                    }
                }
            }
        }
        if uniform != 0.0 {
            out.iter_mut().for_each(|o| *o += uniform);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_to_probabilities_with_prior() {
        let mut c = TransitionCounts::new(4);
        c.record(0, Action::Forward, 1).unwrap();
        c.record(0, Action::Forward, 1).unwrap();
        c.record(0, Action::Forward, 2).unwrap();
        assert!(c.record(0, Action::Forward, 4).is_err());
        assert_eq!(c.count(0, Action::Forward, 1), 2.0);
        let m = c.to_model(&TransitionPrior {
            alpha: 1.0,
            self_fraction: 0.5,
        });
        // z = 3 + 1: P(1) = 2/4 + 0.5/4/4, P(0) = 0.5/4 + 0.5/16, P(3) = 0.5/16
        assert!((m.prob(0, 0, 1) - (0.5 + 0.5 / 16.0)).abs() < 1e-15);
        assert!((m.prob(0, 0, 2) - (0.25 + 0.5 / 16.0)).abs() < 1e-15);
        assert!((m.prob(0, 0, 0) - (0.125 + 0.5 / 16.0)).abs() < 1e-15);
        assert!((m.prob(0, 0, 3) - 0.5 / 16.0).abs() < 1e-15);
        // every row of every action sums to 1 within 1e-12
        for a in 0..Action::COUNT {
            for i in 0..4 {
                let s: f64 = (0..4).map(|j| m.prob(a, i, j)).sum();
                assert!((s - 1.0).abs() < 1e-12, "a{a} i{i} {s}");
            }
        }
        // unseen row: prior only
        assert!((m.prob(1, 2, 2) - (0.5 + 0.125)).abs() < 1e-15);
        // no prior: unseen rows are self-loops, seen rows are plain frequencies
        let raw = c.to_model(&TransitionPrior {
            alpha: 0.0,
            self_fraction: 0.0,
        });
        assert_eq!(raw.prob(0, 0, 1), 2.0 / 3.0);
        assert_eq!(raw.prob(3, 3, 3), 1.0);
    }

    #[test]
    fn propagate_conserves_mass_and_dense_validation() {
        let mut c = TransitionCounts::new(3);
        c.record(0, Action::ArcLeft, 2).unwrap();
        c.record(1, Action::ArcLeft, 0).unwrap();
        let m = c.to_model(&TransitionPrior::default());
        let out = m.propagate(Action::ArcLeft.index(), &[0.2, 0.5, 0.3]);
        assert!((out.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(TransitionModel::from_dense(&[vec![vec![0.5, 0.4], vec![0.0, 1.0]]]).is_err());
        assert!(TransitionModel::from_dense(&[vec![vec![0.5, 0.5], vec![-0.1, 1.1]]]).is_err());
        assert!(TransitionModel::from_dense(&[vec![vec![0.5, 0.5]]]).is_err());
    }
}
