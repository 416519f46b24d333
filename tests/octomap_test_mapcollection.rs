//! Port of OctoMap's `octomap/src/testing/test_mapcollection.cpp`.
//!
//! OctoMap's test reads `share/data/mapcoll.txt` (three submaps, all the
//! `geb079.bt` map of OctoMap's data directory, under one pose), writes the
//! collection back, asks `isOccupied`/`getOccupancy` for seven points and
//! casts three rays; it only checks that something was read. Its commented-out
//! first half builds two sphere maps with `insertRay` and reads a written
//! collection back.
//!
//! Here the data is our own: sphere maps made with `insert_ray` (a different
//! set of directions than OctoMap's `rotate_IP` walk, which does not matter
//! for the scenario), written as `.bt`, and a collection file laid out like
//! `mapcoll.txt` (comments between the tags, one pose shared by several
//! submaps, the same pose numbers). The same points and rays as OctoMap's
//! test, plus random ones around the spheres, are asked of octolinear's
//! collection and, when the oracle is available, of OctoMap's own
//! `MapCollection<MapNode<OcTree>>` reading the same files: answers must be
//! identical (probabilities and hit points to the bit). `geb079.bt` itself is
//! not used (it is not part of this repository).

use octolinear::formats::bt;
use octolinear::{CastOptions, InnerNodes, MapCollection, OccupancyTree, Point3, Pose6D};
use octolinear_oracle::{map_collection_query, require_or_skip, CollectionRay};
use octolinear_sim::SplitMix64;
use std::path::Path;

/// A hollow sphere of occupied voxels around `origin`, free inside, from
/// rays on a grid of directions (OctoMap's `generateSphereTree`, coarser).
fn sphere_tree(origin: Point3, radius: f32) -> OccupancyTree {
    let mut t = OccupancyTree::new(0.05).unwrap();
    for i in 0..90 {
        let yaw = f64::from(i) * 4.0_f64.to_radians();
        for j in 0..45 {
            let pitch = (f64::from(j) * 4.0 - 88.0).to_radians();
            let d = Point3::new((yaw.cos() * pitch.cos()) as f32, (yaw.sin() * pitch.cos()) as f32, pitch.sin() as f32);
            let end = Point3::new(origin.x + d.x * radius, origin.y + d.y * radius, origin.z + d.z * radius);
            t.insert_ray(origin, end, None, InnerNodes::Update).unwrap();
        }
    }
    t
}

fn write_bt(t: &OccupancyTree, path: &Path) {
    let mut bytes = Vec::new();
    bt::write(t, &mut bytes).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// The seven query points of OctoMap's test.
const QUERIES: [[f32; 3]; 7] = [
    [0.0, 0.0, 0.0],
    [2.0, 0.0, 0.0],
    [2.0, 0.0, 2.0],
    [1.99, 0.0, 0.0],
    [0.0, 0.0, 3.0],
    [3.0, 7.0, 13.5],
    [0.0, -1.0, -1.0],
];

/// Its three rays: origin, direction, max range (-1: none).
const RAYS: [([f32; 3], [f32; 3], f64); 3] = [
    ([0.0, 0.0, 10.0], [0.0, 0.0, -10.0], -1.0),
    ([0.0, 0.0, -10.0], [0.0, 0.0, 10.0], -1.0),
    ([0.0, -1.5, -3.0], [0.0, 0.0, 1.0], 5.0),
];

fn p3(p: [f32; 3]) -> Point3 {
    Point3::new(p[0], p[1], p[2])
}

#[test]
fn map_collection_scenario() {
    let dir = tempfile::tempdir().unwrap();
    write_bt(&sphere_tree(Point3::new(0.01, 0.01, 0.01), 2.0), &dir.path().join("sphere2.bt"));
    write_bt(&sphere_tree(Point3::new(0.01, 0.01, 0.01), 3.5), &dir.path().join("sphere35.bt"));
    // laid out like OctoMap's mapcoll.txt
    let text = "#a comment\n#a comment\nMAPNODEID cup0815\n#a further comment\n#a further comment\n\
                MAPNODEFILENAME sphere2.bt\n#a further comment\nMAPNODEPOSE 1 2 3 4.56 67.3 1.24\n#a further comment\n\
                MAPNODEID glass\nMAPNODEFILENAME sphere35.bt\nMAPNODEPOSE 3 7 10 0 0 0\n\
                MAPNODEID cup08w5\nMAPNODEFILENAME sphere2.bt\nMAPNODEPOSE 0 0 0 0.1 -0.2 0.3";
    let file = dir.path().join("mapcoll.txt");
    std::fs::write(&file, text).unwrap();

    let coll = MapCollection::read(&file).unwrap();
    assert!(!coll.nodes.is_empty());
    assert_eq!(coll.nodes.iter().map(|n| n.id.as_str()).collect::<Vec<_>>(), ["cup0815", "glass", "cup08w5"]);

    // written and read back: the same submaps under the same poses
    let out = dir.path().join("writeout.txt");
    coll.write(&out).unwrap();
    let back = MapCollection::read(&out).unwrap();
    assert_eq!(back.nodes.len(), coll.nodes.len());
    for (a, b) in coll.nodes.iter().zip(&back.nodes) {
        assert_eq!(a.id, b.id);
        assert_eq!(a.pose.translation, b.pose.translation);
        let (ea, eb) = (a.pose.rot().to_euler(), b.pose.rot().to_euler());
        let d = [ea.x - eb.x, ea.y - eb.y, ea.z - eb.z];
        assert!(d.iter().all(|v| v.abs() < 1e-5), "{} {ea:?} {eb:?}", a.id);
        let (la, lb): (Vec<_>, Vec<_>) = (a.map.leaves(0).collect(), b.map.leaves(0).collect());
        assert_eq!(la.len(), lb.len());
    }

    // the queries of OctoMap's test, and random ones near the spheres
    let mut rng = SplitMix64(0x3a9c011);
    let mut points = QUERIES.to_vec();
    for _ in 0..300 {
        // near the sphere surfaces (each submap's centre and radius), or anywhere around
        let (c, r) = match rng.below(4) {
            0 => ([1.0, 2.0, 3.0], 2.0 + rng.range(-0.03, 0.03)),
            1 => ([3.0, 7.0, 10.0], 3.5 + rng.range(-0.03, 0.03)),
            2 => ([0.0, 0.0, 0.0], 2.0 + rng.range(-0.03, 0.03)),
            _ => ([1.0, 2.0, 3.0], rng.range(0.5, 5.0)),
        };
        let (a, b) = (rng.range(-3.2, 3.2), rng.range(-1.5, 1.5));
        points.push([
            (c[0] + r * a.cos() * b.cos()) as f32,
            (c[1] + r * a.sin() * b.cos()) as f32,
            (c[2] + r * b.sin()) as f32,
        ]);
    }
    let mut rays: Vec<CollectionRay> =
        RAYS.iter().map(|&(origin, direction, max_range)| CollectionRay { origin, direction, max_range }).collect();
    for _ in 0..60 {
        let o = [rng.range(-1.0, 4.0) as f32, rng.range(0.0, 8.0) as f32, rng.range(1.0, 11.0) as f32];
        let d = [rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32];
        let max_range = if rng.below(3) == 0 { rng.range(1.0, 8.0) } else { -1.0 };
        rays.push(CollectionRay { origin: o, direction: d, max_range });
    }
    let ours_points: Vec<(bool, f64)> =
        points.iter().map(|&p| (coll.is_occupied(p3(p)), coll.occupancy(p3(p)))).collect();
    let ours_rays: Vec<Option<Point3>> = rays
        .iter()
        .map(|r| {
            let max_range = (r.max_range > 0.0).then_some(r.max_range);
            coll.cast_ray(p3(r.origin), p3(r.direction), CastOptions { ignore_unknown: true, max_range })
        })
        .collect();
    // the spheres are there: some queries hit, some rays hit
    assert!(ours_points.iter().any(|p| p.0) && ours_points.iter().any(|p| !p.0));
    assert!(ours_rays.iter().any(Option::is_some));
    assert!(!coll.is_occupied(Point3::new(1.0, 2.0, 3.0)), "a sphere's centre is free");
    assert!(coll.occupancy(Point3::new(1.0, 2.0, 3.0)) < 0.5);
    assert_eq!(coll.occupancy(Point3::new(100.0, 100.0, 100.0)), 0.5, "unknown everywhere");
    // a submap moved away takes its answers along
    let mut moved = back;
    let far = Pose6D::from_euler(100.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    moved.move_node("glass", far).unwrap();
    moved.move_node("cup0815", far).unwrap();
    moved.move_node("cup08w5", far).unwrap();
    assert!(points.iter().all(|&p| !moved.is_occupied(p3(p))));

    if !require_or_skip("map_collection_scenario (against OctoMap)") {
        return;
    }
    let theirs = map_collection_query(&file, &points, &rays, true).unwrap();
    assert_eq!(theirs.submaps, 3);
    for (i, (a, b)) in ours_points.iter().zip(&theirs.points).enumerate() {
        assert_eq!(a, b, "point {i} {:?}: (isOccupied, getOccupancy)", points[i]);
    }
    for (i, (a, b)) in ours_rays.iter().zip(&theirs.rays).enumerate() {
        let ours = a.map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]);
        let theirs = b.0.then(|| b.1.map(f32::to_bits));
        assert_eq!(ours, theirs, "ray {i} {:?}: {a:?} vs {b:?}", rays[i]);
    }
}
