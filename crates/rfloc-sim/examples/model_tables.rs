//! Prints each sensor model next to the seed table it was built from.
//! Run: `cargo run -p rfloc-sim --example model_tables`.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_pose::{angle_diff, Pose2};
use rfloc_sim::geometry::Point;
use rfloc_sim::hf::{HfModel, TABLE_4};
use rfloc_sim::uhf::{rss_on_axis, TABLE_3_1};
use rfloc_sim::xbee::{argmax_bearing, XbeeModel, TABLE_4_1, TABLE_4_2};

fn main() {
    println!("UHF, seed 000 Table 3.1 vs eq. 3.19");
    println!("| d [m] | table | model | model − table |");
    let mut total = 0.0;
    for (d, t) in TABLE_3_1 {
        let m = rss_on_axis(d);
        total += (m - t).abs();
        println!("| {d:.1} | {t:.0} | {m:.1} | {:+.1} |", m - t);
    }
    println!("accumulated |error| = {total:.1} (seed states 1907)\n");

    println!("HF, seed 002 Table 4 vs the blind-spot curve (noiseless)");
    let hf = HfModel::default();
    for (rssi, max, mid, min) in TABLE_4 {
        let cells: Vec<String> = [max, mid, min]
            .into_iter()
            .flatten()
            .map(|d| format!("{d} cm → {:?}", hf.rssi(d / 100.0)))
            .collect();
        println!("RSSI {rssi}: {}", cells.join(", "));
    }
    println!();

    println!("XBee, seed 003 Table 4.1 vs eq. 2.7 (P_ref −29 dBm, η 2)");
    let x = XbeeModel::default();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    println!(
        "| r [m] | measured | model mean | Δ | simulated mean of 40 | simulated min..max of 40 |"
    );
    for (r, z) in TABLE_4_1 {
        let s: Vec<f64> = (0..40)
            .filter_map(|_| x.sample_rssi(r, 0.0, &mut rng))
            .collect();
        let mean = s.iter().sum::<f64>() / s.len() as f64;
        let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let m = x.mean_rssi(r, 0.0);
        println!(
            "| {r} | {z} | {m:.2} | {:+.2} | {mean:.2} | {lo}..{hi} |",
            z - m
        );
    }
    println!();

    println!("XBee, seed 003 Table 4.2 bearing test (robot (1, 1, 0), 40 × 9° sweep), 200 sweeps per beacon");
    let robot = Pose2::new(1.0, 1.0, 0.0);
    for ((bx, by), actual, measured) in TABLE_4_2 {
        let b = Point::new(bx, by);
        let truth = (by - 1.0).atan2(bx - 1.0);
        let errs: Vec<f64> = (0..200)
            .filter_map(|_| argmax_bearing(&x.sweep(&robot, &b, 40, &mut rng)))
            .map(|a| angle_diff(a, truth).abs().to_degrees())
            .collect();
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        let max = errs.iter().copied().fold(0.0, f64::max);
        println!(
            "beacon ({bx}, {by}): true {:.1}° (table {actual}°), seed error {:.0}°, model mean |error| {mean:.1}°, max {max:.1}°",
            truth.to_degrees().rem_euclid(360.0),
            (actual - measured).abs()
        );
    }
}
