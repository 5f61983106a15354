//! Particle filter: convergence with seeded noise, filtered vs raw error, N_eff and systematic
//! resampling properties.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test helpers

use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_emitter::{
    differential_range_bearing, effective_sample_size, systematic_resample, DirectionalArrayModel,
    EmitterParticleFilter, ParticleFilterConfig, Point2,
};
use rfloc_pose::Pose2;

struct RunErrors {
    raw: Vec<f64>,
    filtered: Vec<f64>,
    resamples: usize,
}

/// Robot drives along +x at 0.1 m/s, one RSS reading every 0.5 s, emitter fixed.
fn run(seed: u64, emitter: Point2, updates: usize) -> RunErrors {
    let model = DirectionalArrayModel {
        noise_std_db: 2.0,
        ..DirectionalArrayModel::default()
    };
    let cal = model.matching_calibration();
    let start = Pose2::new(0.0, 0.0, 0.0);
    let mut pf = EmitterParticleFilter::new(ParticleFilterConfig::default(), &start, seed).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let mut out = RunErrors {
        raw: Vec::new(),
        filtered: Vec::new(),
        resamples: 0,
    };
    for k in 0..updates {
        let robot = Pose2::new(0.05 * k as f64, 0.0, 0.0);
        let rss = model.sample(&robot, &emitter, &mut rng);
        let rb = differential_range_bearing(&rss, &cal).unwrap();
        let est = pf.update(&robot, &rb, 0.5).unwrap();
        out.raw.push(est.raw.distance(&emitter));
        out.filtered.push(est.mean.distance(&emitter));
        out.resamples += usize::from(est.resampled);
        // Weights stay normalised.
        let sum: f64 = pf.particles().iter().map(|p| p.weight).sum();
        assert!((sum - 1.0).abs() < 1e-9);
    }
    out
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn filter_converges_and_beats_raw_estimate() {
    let emitter = Point2::new(4.0, 1.0);
    let mut ratios = Vec::new();
    let mut final_errors = Vec::new();
    for seed in 0..10u64 {
        let r = run(seed, emitter, 40);
        // Skip the first 10 updates (convergence from the uniform prior).
        let raw = mean(&r.raw[10..]);
        let filt = mean(&r.filtered[10..]);
        ratios.push(filt / raw);
        final_errors.push(*r.filtered.last().unwrap());
        assert!(r.resamples > 0, "seed {seed}: never resampled");
    }
    let ratio = mean(&ratios);
    let final_err = mean(&final_errors);
    println!(
        "PF/raw mean error ratio over updates 10..40, 10 seeds: {ratio:.3}; \
         mean filtered error after 40 updates: {final_err:.3} m"
    );
    assert!(
        final_err < 0.6,
        "filtered error after 40 updates {final_err}"
    );
    assert!(
        ratio < 0.75,
        "filter should clearly beat raw: ratio {ratio}"
    );
}

#[test]
fn filtered_error_shrinks_with_updates() {
    let emitter = Point2::new(3.0, -2.0);
    let r = run(7, emitter, 40);
    let early = r.filtered[0];
    let late = mean(&r.filtered[30..]);
    println!("filtered error: first update {early:.2} m, updates 30..40 {late:.2} m");
    assert!(late < early / 3.0, "early {early}, late {late}");
}

#[test]
fn same_seed_same_result() {
    let a = run(3, Point2::new(4.0, 0.0), 15);
    let b = run(3, Point2::new(4.0, 0.0), 15);
    assert_eq!(a.filtered, b.filtered);
}

#[test]
fn resampling_triggers_only_below_half_n() {
    // A measurement that only a few particles agree with makes N_eff drop below N/2.
    let cfg = ParticleFilterConfig::default();
    let robot = Pose2::new(0.0, 0.0, 0.0);
    let mut pf = EmitterParticleFilter::new(cfg, &robot, 11).unwrap();
    let rb = rfloc_emitter::RangeBearing {
        range_m: 5.0,
        bearing_rad: 0.3,
    };
    // Repeat the same measurement; before each update recompute the post-update weights
    // independently and check the filter's N_eff and its resampling decision.
    let mut decisions = Vec::new();
    for _ in 0..5 {
        let prior: Vec<_> = pf.particles().to_vec();
        let lik: Vec<f64> = prior
            .iter()
            .map(|p| p.weight * cfg.likelihood(&robot, &p.position, &rb))
            .collect();
        let total: f64 = lik.iter().sum();
        let w: Vec<f64> = lik.iter().map(|x| x / total).collect();
        let n_eff = effective_sample_size(&w);
        let est = pf.update(&robot, &rb, 0.0).unwrap();
        assert!((est.effective_sample_size - n_eff).abs() < 1e-6 * n_eff);
        assert_eq!(est.resampled, n_eff < 500.0, "n_eff {n_eff}");
        if est.resampled {
            assert!(pf
                .particles()
                .iter()
                .all(|p| (p.weight - 1e-3).abs() < 1e-12));
        }
        decisions.push(est.resampled);
    }
    // The first update keeps N_eff above N/2 (weights are floored at 0.1), a later one drops.
    assert_eq!(decisions.first(), Some(&false));
    assert!(decisions.contains(&true), "{decisions:?}");
    // A measurement every particle agrees with equally does not resample.
    let mut flat = EmitterParticleFilter::new(
        ParticleFilterConfig {
            range_offset_m: 100.0,
            angle_offset_deg: 180.0,
            ..cfg
        },
        &robot,
        12,
    )
    .unwrap();
    let e = flat.update(&robot, &rb, 0.0).unwrap();
    assert!(!e.resampled);
    assert!((e.effective_sample_size - 1000.0).abs() < 1e-6);
}

#[test]
fn systematic_resampling_survives_round_off() {
    // Weights summing to slightly less than 1 (filterpy PR #186 regression).
    let n = 1000;
    let mut w = vec![1.0 / n as f64; n];
    w[n - 1] -= 1e-12;
    let idx = systematic_resample(&w, 0.999_999_999);
    assert_eq!(idx.len(), n);
    assert!(idx.iter().all(|&i| i < n));
    // Degenerate inputs do not panic.
    assert_eq!(systematic_resample(&[], 0.5), Vec::<usize>::new());
    assert_eq!(systematic_resample(&[0.0, 0.0], 0.5), vec![0, 1]);
    assert_eq!(systematic_resample(&[f64::NAN, 1.0], 0.5), vec![0, 1]);
}

#[test]
fn systematic_resampling_known_answer() {
    // N = 4, u0 = 0.5: pointers 0.125, 0.375, 0.625, 0.875 over cumulative 0.1, 0.6, 0.7, 1.0.
    let idx = systematic_resample(&[0.1, 0.5, 0.1, 0.3], 0.5);
    assert_eq!(idx, vec![1, 1, 2, 3]);
}

proptest! {
    /// Each parent is copied ⌊N·wᵢ⌋ or ⌈N·wᵢ⌉ times (systematic resampling keeps the expected
    /// counts N·wᵢ to within one).
    #[test]
    fn systematic_counts_are_floor_or_ceil(
        raw in proptest::collection::vec(0.0f64..10.0, 1..200),
        u0 in 0.0f64..1.0,
    ) {
        let total: f64 = raw.iter().sum();
        prop_assume!(total > 1e-9);
        let n = raw.len();
        let idx = systematic_resample(&raw, u0);
        prop_assert_eq!(idx.len(), n);
        let mut counts = vec![0usize; n];
        for i in idx {
            counts[i] += 1;
        }
        for (i, c) in counts.iter().enumerate() {
            let expected = n as f64 * raw[i] / total;
            let lo = (expected - 1e-9).floor().max(0.0) as usize;
            let hi = (expected + 1e-9).ceil() as usize;
            prop_assert!(*c >= lo && *c <= hi, "parent {} copied {} times, expected {}", i, c, expected);
        }
    }

    /// The parent indices are non-decreasing (the walk is monotone).
    #[test]
    fn systematic_indices_sorted(raw in proptest::collection::vec(0.0f64..1.0, 1..100), u0 in 0.0f64..1.0) {
        let idx = systematic_resample(&raw, u0);
        prop_assert!(idx.windows(2).all(|w| w[0] <= w[1]));
    }
}
