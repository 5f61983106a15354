//! The numbers the four source theses publish, keyed by scenario name, each with the table it
//! comes from. Metric keys match [`crate::metrics::Summary::metrics`].

/// One published number.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PublishedMetric {
    /// Metric key (e.g. `rmse_m`).
    pub key: &'static str,
    /// The value; `None` when the seed reports that the run could not complete.
    pub value: Option<f64>,
    /// How the seed states it, for the report.
    pub note: &'static str,
}

/// The published results for one scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Published {
    /// Scenario name (the `name` in `scenarios/*.toml`).
    pub scenario: &'static str,
    /// Seed, section and table.
    pub source: &'static str,
    /// [`crate::Scenario::fingerprint`] of the seed's own scenario file: the report shows these
    /// numbers only for a scenario with the same fingerprint (`tests/scenarios.rs` checks the
    /// files against these).
    pub fingerprint: u64,
    pub metrics: &'static [PublishedMetric],
}

const fn m(key: &'static str, value: f64, note: &'static str) -> PublishedMetric {
    PublishedMetric {
        key,
        value: Some(value),
        note,
    }
}

/// Every scenario with published numbers.
pub const ALL: &[Published] = &[
    Published {
        scenario: "seed000-sim",
        source: "seed 000 section 4, Table 4.9 (20 simulated trials, 5×5 m, 800 tags, 1000 exploration steps)",
        fingerprint: 0xc2af23346aeadf14,
        metrics: &[
            m("rmse_m", 0.338, "mean of the per-trial 'RMS Loc Error' column (0.33790395); the text calls it 'averaged an error of 0.34 m'"),
            m("max_error_m", 1.063, "mean of the per-trial 'Max Loc Error' column (1.0627218)"),
            m("failures", 2.0, "trial 10 circling, trial 17 limit cycling"),
            m("time_to_goal", 51.17, "steps, mean of the 18 trials without circling/limit cycling (79.55 over all 20)"),
        ],
    },
    Published {
        scenario: "seed001-a",
        source: "seed 001 section 7.2, Table 1 (A: 4 m straight line; mean of 3 runs)",
        fingerprint: 0x2377f0498cfdb55d,
        metrics: &[m("time_to_goal", 90.0, "s, full system"), m("time_to_goal_preliminary", 89.0, "s, preliminary system")],
    },
    Published {
        scenario: "seed001-b",
        source: "seed 001 section 7.2, Table 1 (B: blocked 4 m straight line)",
        fingerprint: 0x16c22a74513fabcb,
        metrics: &[m("time_to_goal", 230.0, "s, full system"), m("time_to_goal_preliminary", 126.0, "s, preliminary system")],
    },
    Published {
        scenario: "seed001-c",
        source: "seed 001 section 7.2, Table 1 (C: partially blocked 4 m right angle)",
        fingerprint: 0xa767c33f6c799df4,
        metrics: &[m("time_to_goal", 225.0, "s, full system"), m("time_to_goal_preliminary", 252.0, "s, preliminary system")],
    },
    Published {
        scenario: "seed001-d",
        source: "seed 001 section 7.2, Table 1 (D: blocked 4 m right angle)",
        fingerprint: 0xbf9c5a8c97ad6e0e,
        metrics: &[
            m("time_to_goal", 222.0, "s, full system"),
            m("time_to_goal_preliminary", 391.0, "s, preliminary system, the only one of 3 runs that completed"),
        ],
    },
    Published {
        scenario: "seed001-e",
        source: "seed 001 section 7.2, Table 1 (E: U-turn)",
        fingerprint: 0x8869062b01bc88a0,
        metrics: &[
            m("time_to_goal", 455.0, "s, full system"),
            PublishedMetric { key: "time_to_goal_preliminary", value: None, note: "preliminary system could not complete" },
        ],
    },
    Published {
        scenario: "seed002-3x3",
        source: "seed 002 section 7.4 (9-tag test, start (200, 200) mm at 0/90/180/−90°)",
        fingerprint: 0x13bbc128a05e4127,
        metrics: &[
            m("mean_error_m", 0.0375, "37.5 mm mean position error"),
            m("worst_error_m", 0.077, "77 mm maximum position error"),
            m("mean_error_x_m", 0.0245, "24.5 mm mean |x| error"),
            m("mean_error_y_m", 0.0233, "23.3 mm mean |y| error"),
            m("mean_theta_error_rad", 0.401_425_727_958_695_9, "23° mean orientation error"),
            m("worst_theta_error_rad", 0.654_498_469_497_873_6, "37.5° maximum orientation error"),
        ],
    },
    Published {
        scenario: "seed002-large",
        source: "seed 002 section 6.4, Table 5 (simulation with emulated data)",
        fingerprint: 0xad01cd474ce76f0e,
        metrics: &[
            m("mean_error_m", 0.010, "10 mm, own recorded (blind-spot) RSSI data"),
            m("mean_theta_error_rad", 0.349_065_850_398_865_9, "20°, blind-spot RSSI data"),
            m("mean_error_m_ideal_rssi", 0.002, "2 mm with the paper's monotonic RSSI"),
            m("mean_theta_error_rad_ideal_rssi", 0.017_453_292_519_943_3, "< 1° with the monotonic RSSI (1° used as bound)"),
        ],
    },
    Published {
        scenario: "seed003-case1",
        source: "seed 003 section 3.3, Table 3.2 (simulation case I)",
        fingerprint: 0xbe51d131600ecb62,
        metrics: &[
            m("rmse_m", 0.69, "robot position RMSE"),
            m("rmse_theta_rad", 0.04, "robot heading RMSE"),
            m("beacon_rmse_1_m", 0.36, "b1 (0, 3.5)"),
            m("beacon_rmse_2_m", 0.32, "b2 (6.5, 2.5)"),
            m("beacon_rmse_3_m", 0.36, "b3 (4, 7.25)"),
            m("beacon_rmse_4_m", 0.25, "b4 (0, 8)"),
        ],
    },
    Published {
        scenario: "seed003-case2",
        source: "seed 003 section 3.4, Table 3.3 (simulation case II)",
        fingerprint: 0xa05e804523221d72,
        metrics: &[
            m("rmse_m", 0.15, "robot position RMSE"),
            m("rmse_theta_rad", 0.14, "robot heading RMSE"),
            m("beacon_rmse_1_m", 0.73, "b1 (0, 0)"),
            m("beacon_rmse_2_m", 0.21, "b2 (9, 2)"),
            m("beacon_rmse_3_m", 0.46, "b3 (4, 4)"),
            m("beacon_rmse_4_m", 0.47, "b4 (8, 7)"),
        ],
    },
];

/// Published numbers for `scenario`, if the seeds report any.
#[must_use]
pub fn for_scenario(scenario: &str) -> Option<&'static Published> {
    ALL.iter().find(|p| p.scenario == scenario)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_4_9_means_recomputed_from_rows() {
        // Seed 000 Table 4.9 rows: (max loc error, RMS loc error, time to goal).
        let rows = [
            (0.263108, 0.113088, 28.0),
            (1.373005, 0.408296, 44.0),
            (0.277988, 0.115034, 45.0),
            (0.266809, 0.127836, 21.0),
            (1.209967, 0.339866, 20.0),
            (2.573254, 0.962738, 85.0),
            (1.209967, 0.339866, 20.0),
            (0.770608, 0.289507, 77.0),
            (0.396196, 0.175624, 30.0),
            (0.84493, 0.253016, 182.0),
            (2.651533, 0.997474, 43.0),
            (0.564744, 0.213986, 57.0),
            (0.318143, 0.180671, 37.0),
            (0.948004, 0.246589, 89.0),
            (1.656564, 0.412161, 71.0),
            (0.832765, 0.18374, 51.0),
            (3.670778, 0.858748, 488.0),
            (0.355889, 0.167153, 48.0),
            (0.407162, 0.143514, 41.0),
            (0.663023, 0.229172, 114.0),
        ];
        let n = rows.len() as f64;
        let max_mean: f64 = rows.iter().map(|r| r.0).sum::<f64>() / n;
        let rms_mean: f64 = rows.iter().map(|r| r.1).sum::<f64>() / n;
        assert!((max_mean - 1.0627218).abs() < 1e-6);
        assert!((rms_mean - 0.33790395).abs() < 1e-6);
        let ok_time: f64 = rows
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 9 && *i != 16)
            .map(|(_, r)| r.2)
            .sum::<f64>()
            / 18.0;
        let p = for_scenario("seed000-sim").unwrap();
        let get = |k| {
            p.metrics
                .iter()
                .find(|m| m.key == k)
                .and_then(|m| m.value)
                .unwrap()
        };
        assert!((get("time_to_goal") - ok_time).abs() < 0.01);
        assert!((get("rmse_m") - rms_mean).abs() < 0.001);
        assert!((get("max_error_m") - max_mean).abs() < 0.001);
    }

    #[test]
    fn every_entry_has_unique_keys() {
        for p in ALL {
            let mut keys: Vec<&str> = p.metrics.iter().map(|m| m.key).collect();
            keys.sort_unstable();
            keys.dedup();
            assert_eq!(keys.len(), p.metrics.len(), "{}", p.scenario);
        }
    }
}
