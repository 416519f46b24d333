//! The spinning lidar: ray patterns, the size limits of a request, and
//! scanning a scene along a path into a scan graph.

use crate::math::*;
use crate::random::*;
use crate::scene::*;
use octolinear::formats::graph::ScanGraph;
use octolinear::geometry::{Point3, PointCloud, Pose6D, Quaternion};
use rayon::prelude::*;

/// Spinning multi-beam lidar (VLP-16-like by default).
#[derive(Clone, Debug, PartialEq)]
pub struct LidarConfig {
    /// Vertical channels.
    pub beams: u32,
    /// Firings per revolution.
    pub horizontal_steps: u32,
    /// Returns closer than this are dropped (metres).
    pub min_range: f64,
    /// Returns beyond this are dropped (metres); `f64::INFINITY` keeps
    /// every return, however far (the scene is finite: a ray that hits
    /// nothing still gives no point).
    pub max_range: f64,
    /// Lowest and highest beam elevation in degrees.
    pub vertical_fov: (f64, f64),
    /// Standard deviation of the range noise (metres).
    pub noise_sigma: f64,
    /// Probability that a return is lost.
    pub dropout: f64,
}

impl Default for LidarConfig {
    fn default() -> Self {
        Self::indoor()
    }
}

impl LidarConfig {
    pub fn indoor() -> Self {
        Self {
            beams: 16,
            horizontal_steps: 360,
            min_range: 0.3,
            max_range: 30.0,
            vertical_fov: (-15.0, 15.0),
            noise_sigma: 0.01,
            dropout: 0.01,
        }
    }

    /// Longer range for open scenes.
    pub fn outdoor() -> Self {
        Self { max_range: 100.0, noise_sigma: 0.02, ..Self::indoor() }
    }

    fn validate(&self) -> Result<(), SimError> {
        let bad = |field: &'static str, value: String| Err(SimError::InvalidConfig { field, value });
        if self.beams == 0 {
            return bad("beams", self.beams.to_string());
        }
        if self.horizontal_steps == 0 {
            return bad("horizontal_steps", self.horizontal_steps.to_string());
        }
        if !(self.min_range >= 0.0 && self.min_range.is_finite()) {
            return bad("min_range", self.min_range.to_string());
        }
        if self.max_range.is_nan() || self.max_range <= self.min_range {
            return bad("max_range", self.max_range.to_string());
        }
        let (lo, hi) = self.vertical_fov;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo >= -90.0 && hi <= 90.0) {
            return bad("vertical_fov", format!("{lo}..{hi}"));
        }
        if !(self.noise_sigma >= 0.0 && self.noise_sigma.is_finite()) {
            return bad("noise_sigma", self.noise_sigma.to_string());
        }
        if !(0.0..=1.0).contains(&self.dropout) {
            return bad("dropout", self.dropout.to_string());
        }
        Ok(())
    }

    /// Unit directions in the sensor frame, column-major (azimuth, then beam bottom-up).
    fn directions(&self) -> Vec<V3> {
        let deg = std::f64::consts::PI / 180.0;
        let (lo, hi) = self.vertical_fov;
        let elev: Vec<(f64, f64)> = (0..self.beams)
            .map(|b| {
                let f = if self.beams == 1 { 0.5 } else { b as f64 / (self.beams - 1) as f64 };
                sin_cos((lo + (hi - lo) * f) * deg)
            })
            .collect();
        let mut dirs = Vec::with_capacity(self.beams as usize * self.horizontal_steps as usize);
        for col in 0..self.horizontal_steps {
            let (sa, ca) = sin_cos(std::f64::consts::TAU * col as f64 / self.horizontal_steps as f64);
            for &(se, ce) in &elev {
                dirs.push([ce * ca, ce * sa, se]);
            }
        }
        dirs
    }
}

/// Rays one scan may cast: their directions are held in memory (24 bytes
/// each), and the largest real lidars cast a few hundred thousand.
pub const MAX_RAYS_PER_SCAN: u64 = 1 << 24;

/// Rays of all scans together: every point is held in memory (12 bytes
/// each, so at most 3 GiB) until the graph is returned.
pub const MAX_RAYS: u64 = 1 << 28;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("invalid lidar config: {field} = {value}")]
    InvalidConfig { field: &'static str, value: String },
    #[error("{beams} beams × {steps} steps = {rays} rays per scan exceeds the limit of {MAX_RAYS_PER_SCAN} (2^24)")]
    TooManyRaysPerScan { beams: u32, steps: u32, rays: u64 },
    #[error(
        "{scans} scans × {per_scan} rays = {total} rays exceeds the limit of {MAX_RAYS} \
         (2^28: every point is held in memory, 12 bytes each)"
    )]
    TooManyRays { scans: usize, per_scan: u64, total: u128 },
}

/// Checks what `scans` scans of `cfg` would hold against [`MAX_RAYS_PER_SCAN`]
/// and [`MAX_RAYS`] before anything is allocated for them.
pub fn check_size(scans: usize, cfg: &LidarConfig) -> Result<(), SimError> {
    let per_scan = u64::from(cfg.beams) * u64::from(cfg.horizontal_steps);
    if per_scan > MAX_RAYS_PER_SCAN {
        return Err(SimError::TooManyRaysPerScan { beams: cfg.beams, steps: cfg.horizontal_steps, rays: per_scan });
    }
    let total = scans as u128 * u128::from(per_scan);
    if total > u128::from(MAX_RAYS) {
        return Err(SimError::TooManyRays { scans, per_scan, total });
    }
    Ok(())
}

/// Generates `kind` from `seed` and scans it `scans` times along its path.
pub fn simulate(kind: SceneKind, scans: usize, seed: u64, cfg: &LidarConfig) -> Result<ScanGraph, SimError> {
    cfg.validate()?;
    check_size(scans, cfg)?;
    let scene = Scene::generate(kind, seed);
    let poses = scene.trajectory(scans);
    simulate_scene(&scene, &poses, seed, cfg)
}

/// Scans `scene` from each pose. Points are in the sensor frame (graph2tree
/// puts them in the world); rays without a return inside the range produce no
/// point. Parallel over scans and columns, identical for any thread count.
pub fn simulate_scene(scene: &Scene, poses: &[Pose6D], seed: u64, cfg: &LidarConfig) -> Result<ScanGraph, SimError> {
    cfg.validate()?;
    check_size(poses.len(), cfg)?;
    let dirs = cfg.directions();
    let beams = cfg.beams as usize;
    let clouds: Vec<PointCloud> = poses
        .par_iter()
        .enumerate()
        .map(|(scan, pose)| {
            let r = rotation_matrix(pose.rotation);
            let t = pose.translation;
            let o = [t.x as f64, t.y as f64, t.z as f64];
            let cols: Vec<Vec<Point3>> = dirs
                .par_chunks(beams)
                .enumerate()
                .map(|(col, col_dirs)| {
                    let mut rng = SplitMix64(mix(seed, &[3, scan as u64, col as u64]));
                    let mut out = Vec::with_capacity(col_dirs.len());
                    for &ds in col_dirs {
                        // Fixed number of draws per ray keeps streams aligned.
                        let (drop, noise) = (rng.next_f64(), rng.normalish());
                        let dw = [
                            r[0][0] * ds[0] + r[0][1] * ds[1] + r[0][2] * ds[2],
                            r[1][0] * ds[0] + r[1][1] * ds[1] + r[1][2] * ds[2],
                            r[2][0] * ds[0] + r[2][1] * ds[1] + r[2][2] * ds[2],
                        ];
                        let Some(hit) = scene.raycast(o, dw, cfg.max_range) else {
                            continue;
                        };
                        let range = hit.t + cfg.noise_sigma * noise;
                        if drop < cfg.dropout || range < cfg.min_range || range > cfg.max_range {
                            continue;
                        }
                        let p = scale(ds, range);
                        out.push(Point3::new(p[0] as f32, p[1] as f32, p[2] as f32));
                    }
                    out
                })
                .collect();
            cols.into_iter().flatten().collect()
        })
        .collect();
    let mut graph = ScanGraph::new();
    for (cloud, pose) in clouds.into_iter().zip(poses) {
        graph.add_node(cloud, *pose);
        graph.connect_previous();
    }
    Ok(graph)
}

/// Rotation matrix of the stored float quaternion (normalised in double), so
/// the simulated rays agree with what graph2tree will do with the points.
fn rotation_matrix(q: Quaternion) -> [[f64; 3]; 3] {
    let (mut w, mut x, mut y, mut z) = (q.u as f64, q.x as f64, q.y as f64, q.z as f64);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    if n > 0.0 {
        (w, x, y, z) = (w / n, x / n, y / n, z / n);
    }
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_checked_before_anything_is_allocated() {
        let cfg = |beams, horizontal_steps| LidarConfig { beams, horizontal_steps, ..LidarConfig::indoor() };
        let err = simulate(SceneKind::Indoor, 1, 1, &cfg(100_000_000, 360)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "100000000 beams × 360 steps = 36000000000 rays per scan exceeds the limit of 16777216 (2^24)"
        );
        let err = simulate(SceneKind::Indoor, 1, 1, &cfg(16, u32::MAX)).unwrap_err();
        assert!(matches!(err, SimError::TooManyRaysPerScan { rays: 68719476720, .. }), "{err}");
        let err = simulate(SceneKind::Indoor, usize::MAX, 1, &cfg(16, 360)).unwrap_err();
        assert!(err.to_string().starts_with(&format!("{} scans × 5760 rays = ", usize::MAX)), "{err}");
        assert!(err.to_string().contains("exceeds the limit of 268435456"), "{err}");
        // the limits themselves are allowed
        assert!(check_size(1, &cfg(1 << 12, 1 << 12)).is_ok());
        assert!(check_size(16, &cfg(1 << 12, 1 << 12)).is_ok());
        assert!(check_size(17, &cfg(1 << 12, 1 << 12)).is_err());
    }
}
