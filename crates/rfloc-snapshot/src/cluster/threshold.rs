//! The seed's threshold ("custom") clustering (section 5.1, appendix A `preprocess`).
//!
//! Leader clustering: objects are visited in order; an object not yet in a cluster opens a new
//! one and pulls in every later unassigned object whose dissimilarity to it is at most
//! `max_distance`. The seed scores pairs with `0.5·(IDsc + RSSsc) ≥ match` (match 0.7–0.8); here
//! the test is `d ≤ max_distance` on the configured snapshot distance. Afterwards each cluster is
//! represented by its medoid (the member with the least summed dissimilarity to the others)
//! instead of the seed's consensus centroid (`calCentroids`: tags in ≥ 60 % of members, mean RSS).

use super::Clustering;
use crate::distance::DissimilarityMatrix;

/// Leader clustering with a fixed threshold.
#[must_use]
pub fn leader(d: &DissimilarityMatrix, max_distance: f64) -> Clustering {
    let n = d.len();
    let mut assignment: Vec<Option<usize>> = vec![None; n];
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for lead in 0..n {
        if assignment.get(lead).copied().flatten().is_some() {
            continue;
        }
        let c = groups.len();
        let mut members = vec![lead];
        if let Some(a) = assignment.get_mut(lead) {
            *a = Some(c);
        }
        for other in lead + 1..n {
            if assignment.get(other).copied().flatten().is_none()
                && d.get(lead, other) <= max_distance
            {
                if let Some(a) = assignment.get_mut(other) {
                    *a = Some(c);
                }
                members.push(other);
            }
        }
        groups.push(members);
    }
    let medoids: Vec<usize> = groups
        .iter()
        .map(|members| {
            members
                .iter()
                .copied()
                .map(|m| (m, members.iter().map(|&o| d.get(m, o)).sum::<f64>()))
                .fold((usize::MAX, f64::INFINITY), |b, (m, s)| {
                    if s < b.1 {
                        (m, s)
                    } else {
                        b
                    }
                })
                .0
        })
        .collect();
    let assignment: Vec<usize> = assignment.into_iter().map(|a| a.unwrap_or(0)).collect();
    let loss = assignment
        .iter()
        .enumerate()
        .map(|(o, &c)| medoids.get(c).map_or(0.0, |&m| d.get(o, m)))
        .sum();
    Clustering {
        medoids,
        assignment,
        loss,
        iterations: 1,
        swaps: 0,
    }
}
