//! The procedural lidar simulator: determinism, ranges and plausibility.

use octolinear::formats::graph;
use octolinear::ScanGraph;
use octolinear_sim::{simulate, LidarConfig, Scene, SceneKind, Surface};

fn bytes(g: &ScanGraph) -> Vec<u8> {
    let mut out = Vec::new();
    graph::write(g, &mut out).unwrap();
    out
}

fn small() -> LidarConfig {
    LidarConfig { horizontal_steps: 180, ..LidarConfig::indoor() }
}

#[test]
fn same_seed_same_bytes_any_thread_count() {
    for (kind, cfg) in [(SceneKind::Indoor, small()), (SceneKind::Outdoor, LidarConfig::outdoor())] {
        let a = bytes(&simulate(kind, 6, 42, &cfg).unwrap());
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let b = one.install(|| bytes(&simulate(kind, 6, 42, &cfg).unwrap()));
        let three = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let c = three.install(|| bytes(&simulate(kind, 6, 42, &cfg).unwrap()));
        assert!(a == b && a == c, "{kind:?} output depends on threads");
        let d = bytes(&simulate(kind, 6, 43, &cfg).unwrap());
        assert!(a != d, "{kind:?}: seeds 42 and 43 give the same output");
    }
}

#[test]
fn points_finite_within_range_and_graph_well_formed() {
    for (kind, cfg) in [(SceneKind::Indoor, small()), (SceneKind::Outdoor, LidarConfig::outdoor())] {
        let g = simulate(kind, 5, 7, &cfg).unwrap();
        assert_eq!(g.nodes.len(), 5);
        assert_eq!(g.edges.len(), 4);
        let rays = (cfg.beams * cfg.horizontal_steps) as usize;
        for (i, n) in g.nodes.iter().enumerate() {
            assert_eq!(n.id, i as u32);
            assert!(n.scan.len() > rays / 4, "{kind:?} scan {i}: only {} points", n.scan.len());
            assert!(n.scan.len() <= rays);
            for p in &n.scan {
                assert!(p.is_finite());
                let r = p.norm();
                assert!(r >= cfg.min_range - 1e-4 && r <= cfg.max_range + 1e-4, "range {r}");
            }
            let q = n.pose.rotation;
            assert!((q.norm() - 1.0).abs() < 1e-6);
        }
        // Survives the file format.
        let b = bytes(&g);
        assert_eq!(graph::read_bytes(&b).unwrap(), g);
    }
}

/// An infinite range keeps the returns beyond the default 100 m (the
/// terrain's far side) and every point stays finite; rays that hit nothing
/// still give no point.
#[test]
fn an_unlimited_range_keeps_every_return() {
    let limited = LidarConfig { horizontal_steps: 90, ..LidarConfig::outdoor() };
    let unlimited = LidarConfig { max_range: f64::INFINITY, ..limited.clone() };
    let (a, b) = (
        simulate(SceneKind::Outdoor, 2, 7, &limited).unwrap(),
        simulate(SceneKind::Outdoor, 2, 7, &unlimited).unwrap(),
    );
    let far = |g: &ScanGraph| g.nodes.iter().flat_map(|n| &n.scan).filter(|p| p.norm() > 100.0).count();
    assert_eq!(far(&a), 0);
    assert!(far(&b) > 0, "no return beyond 100 m");
    assert!(b.nodes.iter().flat_map(|n| &n.scan).all(|p| p.is_finite()));
    let rays = 2 * (limited.beams * limited.horizontal_steps) as usize;
    assert!(b.num_points() < rays, "every ray gave a point: {}", b.num_points());
}

#[test]
fn indoor_points_lie_on_walls_and_floor() {
    let cfg = LidarConfig { noise_sigma: 0.0, dropout: 0.0, ..small() };
    let seed = 3;
    let g = simulate(SceneKind::Indoor, 4, seed, &cfg).unwrap();
    let scene = Scene::generate(SceneKind::Indoor, seed);
    let (mut total, mut structure, mut off) = (0usize, 0usize, 0usize);
    for n in &g.nodes {
        let (world, _) = n.graph2tree();
        for p in &world {
            total += 1;
            match scene.surface_near([p.x as f64, p.y as f64, p.z as f64], 0.01) {
                Some(Surface::Wall | Surface::Floor | Surface::Ceiling) => structure += 1,
                Some(_) => {}
                None => off += 1,
            }
        }
    }
    assert!(total > 5000);
    assert_eq!(off, 0, "{off} of {total} points are not on any surface");
    assert!(structure * 10 > total * 6, "{structure} of {total} on walls/floor/ceiling");
}

#[test]
fn outdoor_sees_terrain_buildings_and_trees() {
    let cfg = LidarConfig { noise_sigma: 0.0, dropout: 0.0, ..LidarConfig::outdoor() };
    let seed = 11;
    let scans = 40;
    let g = simulate(SceneKind::Outdoor, scans, seed, &cfg).unwrap();
    let scene = Scene::generate(SceneKind::Outdoor, seed);
    let mut seen = std::collections::HashMap::new();
    let mut total = 0;
    for n in g.nodes.iter().step_by(4) {
        let (world, origin) = n.graph2tree();
        // The sensor is above the ground.
        let below = scene.raycast([origin.x as f64, origin.y as f64, origin.z as f64], [0.0, 0.0, -1.0], 10.0);
        assert!(matches!(below, Some(h) if h.surface == Surface::Terrain && (h.t - 1.8).abs() < 0.01));
        for p in &world {
            total += 1;
            if let Some(s) = scene.surface_near([p.x as f64, p.y as f64, p.z as f64], 0.02) {
                *seen.entry(s).or_insert(0usize) += 1;
            }
        }
    }
    let on: usize = seen.values().sum();
    assert!(on * 100 >= total * 99, "{on} of {total} on a surface: {seen:?}");
    assert!(seen.get(&Surface::Terrain).copied().unwrap_or(0) * 2 > total, "{seen:?}");
    assert!(seen.contains_key(&Surface::Building) || seen.contains_key(&Surface::Trunk), "{seen:?}");
}

#[test]
fn dropout_and_noise_behave() {
    let base = LidarConfig { noise_sigma: 0.0, dropout: 0.0, ..small() };
    let clean = simulate(SceneKind::Indoor, 2, 5, &base).unwrap();
    let dropped = simulate(SceneKind::Indoor, 2, 5, &LidarConfig { dropout: 0.5, ..base.clone() }).unwrap();
    let (a, b) = (clean.num_points() as f64, dropped.num_points() as f64);
    assert!((b / a - 0.5).abs() < 0.05, "{b} of {a} kept");
    let all = simulate(SceneKind::Indoor, 2, 5, &LidarConfig { dropout: 1.0, ..base.clone() }).unwrap();
    assert_eq!(all.num_points(), 0);
    // Noise moves points along their rays only.
    let noisy =
        simulate(SceneKind::Indoor, 2, 5, &LidarConfig { noise_sigma: 0.05, min_range: 0.0, ..base.clone() }).unwrap();
    let clean0 = simulate(SceneKind::Indoor, 2, 5, &LidarConfig { min_range: 0.0, ..base.clone() }).unwrap();
    assert_eq!(noisy.nodes[0].scan.len(), clean0.nodes[0].scan.len());
    let mut moved = 0;
    for (p, q) in noisy.nodes[0].scan.iter().zip(&clean0.nodes[0].scan) {
        let cross = p.cross(*q).norm() / (p.norm() * q.norm());
        assert!(cross < 1e-5);
        assert!((p.norm() - q.norm()).abs() <= 0.05 * 3.47);
        moved += (p != q) as usize;
    }
    assert!(moved * 10 > clean0.nodes[0].scan.len() * 9);
}

#[test]
fn invalid_configs_are_errors() {
    for cfg in [
        LidarConfig { beams: 0, ..small() },
        LidarConfig { max_range: f64::NAN, ..small() },
        LidarConfig { min_range: 5.0, max_range: 1.0, ..small() },
        LidarConfig { dropout: 1.5, ..small() },
        LidarConfig { vertical_fov: (10.0, -10.0), ..small() },
        LidarConfig { noise_sigma: -1.0, ..small() },
    ] {
        assert!(simulate(SceneKind::Indoor, 1, 0, &cfg).is_err(), "{cfg:?}");
    }
    assert_eq!(simulate(SceneKind::Outdoor, 0, 0, &small()).unwrap().nodes.len(), 0);
}

/// Long runs: the trajectory keeps going (ping-pong / loops) and stays inside free space.
#[test]
fn long_trajectories_stay_in_free_space() {
    for kind in [SceneKind::Indoor, SceneKind::Outdoor] {
        let scene = Scene::generate(kind, 99);
        let poses = scene.trajectory(600);
        for (i, p) in poses.iter().enumerate() {
            let o = p.translation;
            let o = [o.x as f64, o.y as f64, o.z as f64];
            assert!(scene.surface_near(o, 0.25).is_none(), "{kind:?} pose {i} touches a surface");
            if kind == SceneKind::Indoor {
                let up = scene.raycast(o, [0.0, 0.0, 1.0], 10.0).unwrap();
                assert_eq!(up.surface, Surface::Ceiling, "{kind:?} pose {i} under {:?}", up.surface);
            }
        }
    }
}
