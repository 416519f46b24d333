//! The scans of a golden build case, shared by the tests that build them
//! (kept apart from `common`, which the CLI's tests include without bzip2).

use crate::common::{point_from_hex, read_xyz, Golden};
use octolinear::Point3;
use serde_json::Value;
use std::io::Read;

/// A scan: world-frame points and the sensor origin.
pub type Scan = (Vec<Point3>, Point3);

/// The scans of a case: its `.graph` input transformed as graph2tree does,
/// or its plain-text points.
pub fn case_scans(g: &Golden, case: &Value) -> Option<Vec<Scan>> {
    let input = case["input"].as_str()?;
    if input.starts_with("inputs/scan.dat.bz2") {
        let raw = std::fs::read(g.input("inputs/scan.dat.bz2")).unwrap();
        let mut text = String::new();
        bzip2::read::BzDecoder::new(&raw[..]).read_to_string(&mut text).unwrap();
        return Some(vec![(read_xyz(&text), Point3::new(0.0, 0.0, 0.0))]);
    }
    if input.ends_with(".graph") {
        // exactly as graph2tree: each scan transformed by its pose
        let graph = octolinear::formats::graph::read_file(g.input(input)).unwrap();
        let scans = graph.nodes.iter().map(|n| n.graph2tree()).map(|(c, o)| (c.points, o));
        return Some(scans.collect());
    }
    let stem = input.trim_start_matches("inputs/").split('.').next().unwrap();
    let origins = std::fs::read_to_string(g.input(&format!("inputs/{stem}.origins.csv"))).ok()?;
    let mut scans = Vec::new();
    for line in origins.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        let text = std::fs::read_to_string(g.input(&format!("inputs/{}", cols[1]))).unwrap();
        scans.push((read_xyz(&text), point_from_hex(&cols[2..5])));
    }
    Some(scans)
}
