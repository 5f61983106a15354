//! One particle-filter update with 1000 particles, and one A* on a 50×50 grid.

use criterion::{criterion_group, criterion_main, Criterion};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rfloc_emitter::{
    differential_range_bearing, plan_path, CostMap, DirectionalArrayModel, EmitterParticleFilter,
    GridCell, Heading4, OccupancyGrid, OccupancyGridConfig, ParticleFilterConfig, PathCosts,
    Point2,
};
use rfloc_pose::Pose2;

fn pf_update(c: &mut Criterion) {
    let model = DirectionalArrayModel::default();
    let cal = model.matching_calibration();
    let robot = Pose2::new(0.0, 0.0, 0.0);
    let emitter = Point2::new(4.0, 1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let Ok(mut pf) = EmitterParticleFilter::new(ParticleFilterConfig::default(), &robot, 1) else {
        return;
    };
    c.bench_function("pf_update_1000_particles", |b| {
        b.iter(|| {
            let rss = model.sample(&robot, &emitter, &mut rng);
            if let Ok(rb) = differential_range_bearing(&rss, &cal) {
                std::hint::black_box(pf.update(&robot, &rb, 0.5).ok());
            }
        });
    });
}

fn astar_50x50(c: &mut Criterion) {
    let Ok(mut grid) = OccupancyGrid::new(OccupancyGridConfig {
        width: 50,
        height: 50,
        origin: Point2::new(0.0, 0.0),
        ..OccupancyGridConfig::default()
    }) else {
        return;
    };
    // Free space with two staggered walls, so the path has to weave.
    for iy in 0..50 {
        for ix in 0..50 {
            let cell = GridCell::new(ix, iy);
            if (ix == 16 && iy < 40) || (ix == 33 && iy > 10) {
                grid.mark_occupied(cell);
            } else {
                grid.mark_free(cell);
            }
        }
    }
    let costs = PathCosts::default();
    c.bench_function("astar_50x50_with_costmap", |b| {
        b.iter(|| {
            let map = CostMap::from_grid(&grid, &costs);
            std::hint::black_box(plan_path(
                &map,
                GridCell::new(2, 2),
                GridCell::new(47, 47),
                Some(Heading4::East),
                &costs,
            ))
        });
    });
    let map = CostMap::from_grid(&grid, &costs);
    c.bench_function("astar_50x50_search_only", |b| {
        b.iter(|| {
            std::hint::black_box(plan_path(
                &map,
                GridCell::new(2, 2),
                GridCell::new(47, 47),
                Some(Heading4::East),
                &costs,
            ))
        });
    });
}

criterion_group!(benches, pf_update, astar_50x50);
criterion_main!(benches);
