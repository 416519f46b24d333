//! Port of OctoMap's `octomap/src/testing/test_raycasting.cpp`.
//!
//! The `.bt` files the program writes are written to memory; the node
//! counts OctoMap reports writing them (Debian's liboctomap 1.9.7) are
//! asserted too (`writeBinary` writes the maximum-likelihood, pruned tree).

mod octomap_port;

use octolinear::formats::bt;
use octolinear::{CastOptions, InnerNodes, OccupancyTree, Point3, ScanOptions};
use octomap_port::{assert_octomap_file, deg2rad, expect_float_eq, expect_near, float_steps};
use std::f64::consts::PI;

/// `writeBinary` to memory, checked against what OctoMap writes as
/// `name`; returns the number of nodes written.
fn write_binary(tree: &OccupancyTree, name: &str, sha256: &str) -> usize {
    let mut file = Vec::new();
    bt::write(tree, &mut file).expect("writeBinary");
    assert_octomap_file(&file, name, sha256);
    let mut ml = tree.clone();
    ml.to_max_likelihood();
    ml.prune();
    let read = bt::read(file.as_slice()).expect("written .bt reads");
    assert_eq!(read.size(), ml.size());
    ml.size()
}

fn cast(
    tree: &OccupancyTree,
    origin: Point3,
    direction: Point3,
    ignore_unknown: bool,
    max_range: f64,
) -> (bool, Point3) {
    let max_range = (max_range > 0.0).then_some(max_range);
    let r = tree.cast_ray(origin, direction, CastOptions { ignore_unknown, max_range }).expect("ray cast");
    (r.hit(), r.end())
}

#[test]
fn sphere_and_single_beams() {
    let mut tree = OccupancyTree::new(0.05).unwrap();
    let origin = Point3::new(0.01, 0.01, 0.02);
    let mut point_on_surface = Point3::new(2.01, 0.01, 0.01);

    let sphere_beams = 500u32;
    let angle = 2.0 * PI / f64::from(sphere_beams);
    let mut p = Vec::with_capacity((sphere_beams * sphere_beams) as usize);
    for _ in 0..sphere_beams {
        for _ in 0..sphere_beams {
            p.push(origin + point_on_surface);
            point_on_surface.rotate_ip(0.0, 0.0, angle);
        }
        point_on_surface.rotate_ip(0.0, angle, 0.0);
    }
    tree.insert_point_cloud(&p, origin, &ScanOptions::default()).expect("scan inserted");
    assert_eq!(
        write_binary(&tree, "sphere.bt", "259289fdadef9bc1ab44e420985ff728c6f44fa893ee527d7df5cfcaa1fa8f6a"),
        54800
    );

    // casting rays in the sphere
    let mut sampled_surface = OccupancyTree::new(0.05).unwrap();
    let mut direction = Point3::new(1.0, 0.0, 0.0);
    let (mut hit, mut miss, mut unknown) = (0u32, 0u32, 0u32);
    let mut mean_dist = 0.0f64;
    for _ in 0..sphere_beams {
        for _ in 0..sphere_beams {
            let (hit_occupied, obstacle) = cast(&tree, origin, direction, false, 3.0);
            if !hit_occupied {
                if tree.search_point(obstacle, 0).unwrap().is_none() {
                    unknown += 1;
                } else {
                    miss += 1;
                }
            } else {
                hit += 1;
                mean_dist += (obstacle - origin).norm();
                sampled_surface.update_point(obstacle, true, InnerNodes::Update).unwrap();
            }
            direction.rotate_ip(0.0, 0.0, angle);
        }
        direction.rotate_ip(0.0, angle, 0.0);
    }
    assert_eq!(
        write_binary(
            &sampled_surface,
            "sampled_surface.bt",
            "590a574debb7f1817e74a78a19eae40d91f948588c006c6367809be45bec4e17"
        ),
        24743
    );
    mean_dist /= f64::from(hit);
    expect_near(mean_dist, 2.0, 0.05);
    expect_near(mean_dist, 1.99789, 1e-5); // as OctoMap prints it
    assert_eq!(hit, sphere_beams * sphere_beams);
    assert_eq!(miss, 0);
    assert_eq!(unknown, 0);

    // single rays
    let mut single_beams = OccupancyTree::new(0.03333).unwrap();
    let num_beams = 17;
    let beam_length = 10.0f32;
    let single_origin = Point3::new(1.0, 0.45, 0.45);
    let mut single_endpoint = Point3::new(beam_length, 0.0, 0.0);
    for _ in 0..num_beams {
        for _ in 0..num_beams {
            single_beams
                .insert_ray(single_origin, single_origin + single_endpoint, None, InnerNodes::Update)
                .expect("ray inserted");
            single_endpoint.rotate_ip(0.0, 0.0, deg2rad(360.0 / f64::from(num_beams)));
        }
        single_endpoint.rotate_ip(0.0, deg2rad(360.0 / f64::from(num_beams)), 0.0);
    }
    assert_eq!(
        write_binary(&single_beams, "beams.bt", "6c3321cac6c521424cb0f2e914e10f41ee94f985e113cb9400082e1ddbd62f82"),
        235406
    );
}

#[test]
fn cube() {
    let res = 0.1f64;
    let res_2 = res / 2.0;
    let mut cube_tree = OccupancyTree::new(res).unwrap();
    // fill a cube with "free", the end is "occupied"
    let steps = float_steps(-0.95, 1.0, res as f32);
    for &x in &steps {
        for &y in &steps {
            for &z in &steps {
                let occupied = f64::from(x) >= 0.9;
                cube_tree.update_point(Point3::new(x, y, z), occupied, InnerNodes::Update).expect("node updated");
            }
        }
    }
    // fill some "floor"
    for x in [res_2, 3.0 * res_2, -res_2, -3.0 * res_2] {
        let p = Point3::new(x as f32, res_2 as f32, -res_2 as f32);
        cube_tree.update_point(p, true, InnerNodes::Update).expect("node updated");
    }
    assert_eq!(
        write_binary(
            &cube_tree,
            "raycasting_cube.bt",
            "2f6275cbb9891c117830bf4d90e43a0d8803c305160c8792bfb055a4a8633a45"
        ),
        1649
    );

    let occupied_at = |p: Point3| {
        let node = cube_tree.search_point(p, 0).unwrap().expect("node exists");
        cube_tree.is_occupied(node.value)
    };

    // hit the corner
    let origin = Point3::new(0.0, 0.0, 0.0);
    let (hit, end) = cast(&cube_tree, origin, Point3::new(0.95, 0.95, 0.95), false, -1.0);
    assert!(hit);
    assert!(occupied_at(end));
    assert_eq!(end.to_array(), [0.95f32; 3]);
    let (hit, end) = cast(&cube_tree, origin, Point3::new(1.0, 0.0, 0.0), false, -1.0);
    assert!(hit);
    assert!(occupied_at(end));
    expect_near(1.0, (origin - end).norm(), res_2);

    // hit the bottom
    let origin = Point3::new(res_2 as f32, res_2 as f32, 0.5);
    let (hit, end) = cast(&cube_tree, origin, Point3::new(0.0, 0.0, -1.0), false, -1.0);
    assert!(hit);
    assert!(occupied_at(end));
    expect_float_eq(origin.x.into(), end.x.into());
    expect_float_eq(origin.y.into(), end.y.into());
    expect_float_eq(-res_2, end.z.into());

    // hit the boundary of unknown space
    let origin = Point3::new(0.0, 0.0, 0.0);
    let direction = Point3::new(0.0, 1.0, 0.0);
    let (hit, end) = cast(&cube_tree, origin, direction, false, -1.0);
    assert!(!hit);
    assert!(cube_tree.search_point(end, 0).unwrap().is_none());

    // hit the boundary of the octree
    let (hit, end) = cast(&cube_tree, origin, direction, true, -1.0);
    assert!(!hit);
    assert!(cube_tree.search_point(end, 0).unwrap().is_none());
    expect_float_eq(end.x.into(), res_2);
    expect_float_eq(end.y.into(), f64::from((32768.0 * res - res_2) as f32));
    expect_float_eq(end.z.into(), res_2);
    let direction = Point3::new(-1.0, 0.0, 0.0);
    let (hit, end) = cast(&cube_tree, origin, direction, true, -1.0);
    assert!(!hit);
    assert!(cube_tree.search_point(end, 0).unwrap().is_none());
    expect_float_eq(end.x.into(), f64::from((-32767.0 * res - res_2) as f32));
    expect_float_eq(end.y.into(), res_2);
    expect_float_eq(end.z.into(), res_2);

    // max range
    let (hit, end) = cast(&cube_tree, origin, direction, true, 0.9);
    assert!(!hit);
    let end_pt = cube_tree.search_point(end, 0).unwrap().expect("end point known");
    assert!(!cube_tree.is_occupied(end_pt.value));
    let dist = (origin - end).norm();
    expect_near(0.9, dist, res);
}
