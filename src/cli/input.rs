//! Point cloud files for `build --points`: PLY (ASCII, binary little or big
//! endian), PCD (ascii, binary, binary_compressed), LAS/LAZ and plain xyz,
//! each with a sensor pose. Colours (for `build --color`) come from PLY and
//! PCD files (the readers in `octolinear::formats` say how).

use anyhow::{bail, Context, Result};
use octolinear::formats::{pcd, ply, xyz, ColoredCloud as Scan};
use octolinear::{Point3, PointCloud, Pose6D};
use std::path::Path;

/// An RGB colour per point.
pub type Colors = Vec<[u8; 3]>;

/// Reads the points of a file, by extension; with `colors`, also the
/// points' colours where the format has them (PLY, PCD).
pub fn read_scan(path: &Path, colors: bool) -> Result<Scan> {
    let ext = super::common::extension(path, &["ply", "pcd", "las", "laz", "xyz", "txt"])?;
    let ctx = || format!("{}: not a valid .{ext} file", path.display());
    let plain = |cloud| Scan { cloud, colors: None };
    match ext.as_str() {
        "las" | "laz" => return read_las(path).map(plain).with_context(ctx),
        "xyz" | "txt" => {
            let f = std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
            return xyz::read(std::io::BufReader::new(f)).map(plain).with_context(ctx);
        }
        _ => {}
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot open {}", path.display()))?;
    match ext.as_str() {
        "ply" => ply::read(&bytes, colors).map_err(anyhow::Error::from),
        _ => pcd::read(&bytes, colors).map_err(anyhow::Error::from),
    }
    .with_context(ctx)
}

// ----- LAS / LAZ -----------------------------------------------------------

fn read_las(path: &Path) -> Result<PointCloud> {
    let mut reader = las::Reader::from_path(path)?;
    let data = reader.read_all()?;
    let mut cloud = PointCloud::new();
    for p in data.points() {
        let p = p?;
        cloud.push(Point3::new(p.x as f32, p.y as f32, p.z as f32));
    }
    Ok(cloud)
}

// ----- poses ---------------------------------------------------------------

/// A pose from `x y z roll pitch yaw`.
pub fn pose(v: &[f64]) -> Result<Pose6D> {
    if v.len() != 6 || v.iter().any(|c| !c.is_finite()) {
        bail!("a pose needs six finite numbers (x y z roll pitch yaw), got {v:?}");
    }
    Ok(Pose6D::from_euler(v[0] as f32, v[1] as f32, v[2] as f32, v[3], v[4], v[5]))
}

/// A trajectory file: one pose `x y z roll pitch yaw` per line (blank
/// lines and lines starting with `#` skipped).
pub fn read_trajectory(path: &Path) -> Result<Vec<Pose6D>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut poses = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Result<Vec<f64>, _> = line.split_whitespace().map(str::parse).collect();
        let v = v.ok().with_context(|| format!("{} line {}: {line:?} is not six numbers", path.display(), n + 1))?;
        poses.push(pose(&v).with_context(|| format!("{} line {}", path.display(), n + 1))?);
    }
    Ok(poses)
}
