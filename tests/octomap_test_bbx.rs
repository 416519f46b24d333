//! Port of OctoMap's `octomap/src/testing/test_bbx.cpp` (OctoMap 1.10's
//! bounding-box-limited `insertPointCloud`; Debian's 1.9.7 fails this
//! program, its insertion ignores the box).

mod octomap_port;

use octolinear::sensor::{SensorModel, SensorProbabilities};
use octolinear::{CastOptions, OccupancyTree, Point3, ScanOptions, UpdateBox};
use octomap_port::expect_near;

#[test]
fn test_bbx() {
    let resolution = 0.2f32;
    let mut tree = OccupancyTree::new(resolution.into()).unwrap();

    // the bounding box
    let bbx_limit = 10.1f32;
    let bbx_min = Point3::new(-bbx_limit, -bbx_limit, -bbx_limit);
    let bbx_max = Point3::new(bbx_limit, bbx_limit, bbx_limit);
    let bbx = UpdateBox::new(&tree, bbx_min, bbx_max).expect("box inside the map");

    // the point cloud; the origin is offset by half a voxel to use a voxel centre
    let origin = Point3::new(resolution / 2.0, 5.0 + resolution / 2.0, resolution / 2.0);
    let maxrange = 8.0f32;
    // inside the bounding box and max range
    let point0 = origin + Point3::new(5.0, 0.0, 0.0);
    // outside the bounding box, within max range
    let point1 = origin + Point3::new(0.0, 7.0, 0.0);
    // inside the bounding box, beyond max range
    let point2 = origin + Point3::new(0.0, 0.0, 9.0);
    let cloud = [point0, point1, point2];
    let opts = ScanOptions::default().with_max_range(Some(maxrange.into())).with_bbx(Some(bbx));
    tree.insert_point_cloud(&cloud, origin, &opts).expect("scan inserted");

    // check the insertion by ray casting (setOccupancyThres(0.5))
    let sensor =
        SensorModel::from_probabilities(&SensorProbabilities { occupancy_threshold: 0.5, ..Default::default() })
            .unwrap();
    tree.set_sensor(sensor);
    let eps = 1e-3;
    let cast = |dir: Point3| tree.cast_ray(origin, dir, CastOptions::default()).expect("ray cast");

    // along x the first point is found
    let r = cast(Point3::new(1.0, 0.0, 0.0));
    assert!(r.hit());
    let end = r.end();
    expect_near(end.x.into(), point0.x.into(), eps);
    expect_near(end.y.into(), point0.y.into(), eps);
    expect_near(end.z.into(), point0.z.into(), eps);

    // along y the ray ends just outside the bounding box
    let r = cast(Point3::new(0.0, 1.0, 0.0));
    assert!(!r.hit());
    let end = r.end();
    expect_near(end.x.into(), point1.x.into(), eps);
    expect_near(end.y.into(), f64::from(bbx_limit + resolution), eps);
    expect_near(end.z.into(), point1.z.into(), eps);

    // along z the ray ends at the max range
    let r = cast(Point3::new(0.0, 0.0, 1.0));
    assert!(!r.hit());
    let end = r.end();
    expect_near(end.x.into(), point2.x.into(), eps);
    expect_near(end.y.into(), point2.y.into(), eps);
    expect_near(end.z.into(), f64::from(origin.z + maxrange), eps);
}
