//! `octolinear render`: pictures of a map without a GPU — a top-down
//! height map, or a perspective view ray-cast through the tree.

use super::common::{depth_arg, extension, load_map, point_arg, write_output};
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use octolinear::{CastOptions, CastOutcome, InnerNodes, OccupancyTree, Point3};
use rayon::prelude::*;
use std::path::PathBuf;

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum View {
    Top,
    Perspective,
}

/// Render a map to a PNG image.
///
/// `top`: looking down, each pixel coloured by the highest occupied voxel
/// in its column (blue low .. red high), free space tinted with --free,
/// unknown dark. `perspective`: one ray cast per pixel from the camera
/// (OctoMap's castRay through unknown space), hits coloured by height and
/// shaded by the angle to the voxel face hit and by distance; the camera
/// defaults to a view from above one corner of the occupied bounds.
///
/// Example: octolinear render map.bt -o view.png --view perspective --width 640 --height 480
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    map: PathBuf,
    /// Output image (.png).
    #[arg(short, long)]
    output: PathBuf,
    #[arg(long, value_enum, default_value = "top")]
    view: View,
    /// Camera position (perspective view).
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    camera: Option<Vec<f64>>,
    /// Point the camera looks at (perspective view; default: map centre).
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    look_at: Option<Vec<f64>>,
    /// Vertical field of view in degrees (perspective view).
    #[arg(long, default_value_t = 60.0)]
    fov: f64,
    /// Image width in pixels (1 to 16384; width × height at most 2^26).
    #[arg(long, default_value_t = 800)]
    width: u32,
    /// Image height in pixels (1 to 16384; default: 3/4 of the width for
    /// the perspective view, from the map's aspect for the top view).
    #[arg(long)]
    height: Option<u32>,
    /// Tint free space (top view).
    #[arg(long)]
    free: bool,
    /// Draw nodes of this depth (1 to 16: 16 = full resolution, lower = coarser).
    #[arg(long, default_value_t = 16)]
    depth: u8,
}

const UNKNOWN: [u8; 3] = [16, 16, 16];
const FREE: [u8; 3] = [70, 84, 110];
const MAX_SIDE: u32 = 16384;
/// Pixels of an image: the top view holds 12 bytes a pixel while drawing
/// (768 MiB at this limit, 8192 x 8192).
const MAX_PIXELS: u64 = 1 << 26;

/// Blue (low) .. cyan .. green .. yellow .. red (high).
pub fn height_colour(t: f64) -> [f64; 3] {
    const STOPS: [[f64; 3]; 5] =
        [[30.0, 90.0, 255.0], [0.0, 210.0, 230.0], [40.0, 220.0, 60.0], [250.0, 230.0, 30.0], [255.0, 50.0, 20.0]];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.5 } * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    [0, 1, 2].map(|c| STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f)
}

/// Bounds of the leaves `want` selects, at `depth`.
fn leaf_bounds(tree: &OccupancyTree, depth: u8, want: impl Fn(f32) -> bool) -> Option<([f64; 3], [f64; 3])> {
    let mut b: Option<([f64; 3], [f64; 3])> = None;
    for leaf in tree.leaves(depth) {
        if !want(leaf.value) {
            continue;
        }
        let (c, h) = (leaf.center(), leaf.size() / 2.0);
        let (lo, hi) = b.get_or_insert(([f64::MAX; 3], [f64::MIN; 3]));
        for i in 0..3 {
            lo[i] = lo[i].min(c[i] - h);
            hi[i] = hi[i].max(c[i] + h);
        }
    }
    b
}

fn top_view(tree: &OccupancyTree, a: &Args, depth: u8) -> Result<(u32, u32, Vec<u8>)> {
    let sensor = *tree.sensor();
    let occupied = leaf_bounds(tree, depth, |v| sensor.is_occupied(v));
    let frame = if a.free { leaf_bounds(tree, depth, |_| true) } else { occupied };
    let (lo, hi) = frame.context("the map has no occupied voxels to draw")?;
    let (zlo, zhi) = occupied.map_or((lo[2], hi[2]), |(l, h)| (l[2], h[2]));
    let (dx, dy) = (hi[0] - lo[0], hi[1] - lo[1]);
    let w = a.width;
    let most = (4 * w).min(MAX_SIDE).min((MAX_PIXELS / u64::from(w)) as u32);
    let h = a.height.unwrap_or_else(|| ((f64::from(w) * dy / dx).round() as u32).clamp(1, most));
    let s = (dx / f64::from(w)).max(dy / f64::from(h));
    let (cx, cy) = ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0);
    let (ox, oy) = (cx - s * f64::from(w) / 2.0, cy + s * f64::from(h) / 2.0);
    let (wu, hu) = (w as usize, h as usize);
    let mut top = vec![f64::NEG_INFINITY; wu * hu];
    let mut free = bitvec::bitvec![0; wu * hu];
    let span = |a: f64, b: f64, n: usize| -> Option<(usize, usize)> {
        let (i0, i1) = (a.floor(), (b.ceil() - 1.0).max(a.floor()));
        if i1 < 0.0 || i0 >= n as f64 {
            return None;
        }
        Some((i0.max(0.0) as usize, (i1 as usize).min(n - 1)))
    };
    for leaf in tree.leaves(depth) {
        let occ = sensor.is_occupied(leaf.value);
        if !occ && !a.free {
            continue;
        }
        let (c, half) = (leaf.center(), leaf.size() / 2.0);
        let Some((c0, c1)) = span((c[0] - half - ox) / s, (c[0] + half - ox) / s, wu) else {
            continue;
        };
        let Some((r0, r1)) = span((oy - c[1] - half) / s, (oy - c[1] + half) / s, hu) else {
            continue;
        };
        for r in r0..=r1 {
            for col in c0..=c1 {
                let i = r * wu + col;
                if occ {
                    top[i] = top[i].max(c[2] + half);
                } else {
                    free.set(i, true);
                }
            }
        }
    }
    let mut img = Vec::with_capacity(wu * hu * 3);
    for i in 0..wu * hu {
        let px = if top[i] > f64::NEG_INFINITY {
            height_colour((top[i] - zlo) / (zhi - zlo)).map(|c| c.round() as u8)
        } else if free[i] {
            FREE
        } else {
            UNKNOWN
        };
        img.extend_from_slice(&px);
    }
    Ok((w, h, img))
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn normalised(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    (n > 1e-12).then(|| a.map(|c| c / n))
}

/// A tree whose voxels are the occupied depth-`depth` nodes of `tree`
/// (resolution scaled by 2^(16 - depth); the voxel centres coincide with
/// the nodes' centres), for casting rays at a coarser level.
pub fn coarse_occupied(tree: &OccupancyTree, depth: u8) -> Result<OccupancyTree> {
    let factor = f64::from(1u32 << (16 - u32::from(depth)));
    let mut coarse = OccupancyTree::with_sensor(tree.resolution() * factor, *tree.sensor())?;
    let sensor = *tree.sensor();
    // a coarse leaf stands for 8^(depth - d) nodes at `depth`
    tree.voxels_within(depth, |v| sensor.is_occupied(v), octolinear::tree::OUTPUT_LIMIT, "render")
        .map_err(|e| anyhow::anyhow!("{e}; a lower --depth gives fewer"))?;
    let mut failed = None;
    super::points::for_each_voxel(
        tree,
        depth,
        |v| sensor.is_occupied(v),
        |_, p, v| match coarse.key(p) {
            Ok(k) => {
                coarse.set_value(k, v, InnerNodes::Defer);
            }
            Err(e) => failed = Some(e),
        },
    );
    if let Some(e) = failed {
        bail!("cannot coarsen the map: {e}");
    }
    coarse.update_inner_occupancy();
    coarse.prune();
    Ok(coarse)
}

/// The perspective view's default height: a 4:3 image.
fn perspective_height(width: u32) -> u32 {
    (width * 3 / 4).max(1)
}

fn perspective(tree: &OccupancyTree, a: &Args, depth: u8) -> Result<(u32, u32, Vec<u8>)> {
    if a.free {
        bail!("--free applies to --view top only");
    }
    let coarse;
    let tree = if depth < 16 {
        coarse = coarse_occupied(tree, depth)?;
        &coarse
    } else {
        tree
    };
    if !(a.fov.is_finite() && a.fov > 0.0 && a.fov < 180.0) {
        bail!("--fov must be between 0 and 180 degrees, got {}", a.fov);
    }
    let sensor = *tree.sensor();
    let (lo, hi) =
        leaf_bounds(tree, 16, |v| sensor.is_occupied(v)).context("the map has no occupied voxels to draw")?;
    let centre = [0, 1, 2].map(|i| (lo[i] + hi[i]) / 2.0);
    let diag = sub(hi, lo).iter().map(|d| d * d).sum::<f64>().sqrt();
    let target = match &a.look_at {
        Some(v) => point_arg(v, "--look-at")?.to_array().map(f64::from),
        None => centre,
    };
    let eye = match &a.camera {
        Some(v) => point_arg(v, "--camera")?.to_array().map(f64::from),
        None => {
            let d = normalised([-0.55, -0.75, 0.5]).expect("non-zero");
            [0, 1, 2].map(|i| target[i] + d[i] * diag * 1.1)
        }
    };
    let forward = normalised(sub(target, eye)).context("--camera and --look-at are the same point")?;
    let right = normalised(cross(forward, [0.0, 0.0, 1.0]))
        .or_else(|| normalised(cross(forward, [0.0, 1.0, 0.0])))
        .expect("one of two axes is not parallel");
    let up = cross(right, forward);
    let (w, h) = (a.width, a.height.unwrap_or(perspective_height(a.width)));
    let tan = (a.fov.to_radians() / 2.0).tan();
    let aspect = f64::from(w) / f64::from(h);
    let origin = Point3::new(eye[0] as f32, eye[1] as f32, eye[2] as f32);
    // rays only run through the occupied bounds (widened by a voxel)
    let pad = tree.resolution();
    let (blo, bhi) = (lo.map(|c| c - pad), hi.map(|c| c + pad));
    let span = sub(bhi, blo).iter().map(|d| d * d).sum::<f64>().sqrt();
    let far = sub(centre, eye).iter().map(|d| d * d).sum::<f64>().sqrt() + span;
    let (zlo, zhi) = (lo[2], hi[2]);
    let mut img = vec![0u8; w as usize * h as usize * 3];
    img.par_chunks_mut(w as usize * 3).enumerate().for_each(|(row, line)| {
        let v = (1.0 - 2.0 * (row as f64 + 0.5) / f64::from(h)) * tan;
        for col in 0..w as usize {
            let u = (2.0 * (col as f64 + 0.5) / f64::from(w) - 1.0) * tan * aspect;
            let d = [0, 1, 2].map(|i| forward[i] + u * right[i] + v * up[i]);
            let dir = Point3::new(d[0] as f32, d[1] as f32, d[2] as f32);
            let Some(unit) = normalised(d) else {
                line[col * 3..col * 3 + 3].copy_from_slice(&UNKNOWN);
                continue;
            };
            // slab test against the bounds: where the ray enters and leaves
            let (mut t0, mut t1) = (0.0f64, f64::MAX);
            for i in 0..3 {
                let inv = 1.0 / unit[i];
                let (a, b) = ((blo[i] - eye[i]) * inv, (bhi[i] - eye[i]) * inv);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
            let cast = if t0 <= t1 {
                let start = Point3::new(
                    (eye[0] + unit[0] * t0) as f32,
                    (eye[1] + unit[1] * t0) as f32,
                    (eye[2] + unit[2] * t0) as f32,
                );
                let opts = CastOptions { ignore_unknown: true, max_range: Some(t1 - t0 + pad) };
                tree.cast_ray(start, dir, opts).ok()
            } else {
                None
            };
            let px = match cast {
                Some(CastOutcome::Occupied { end }) => {
                    let unit = dir.normalized();
                    let entry = tree.ray_intersection(origin, unit, end, 0.0).unwrap_or(end);
                    let off = (entry - end).to_array().map(f32::abs);
                    let axis = (0..3).fold(0, |m, i| if off[i] > off[m] { i } else { m });
                    let facing = f64::from(unit.to_array()[axis].abs());
                    let dist = (entry - origin).norm();
                    let shade = (0.45 + 0.55 * facing) * (1.0 - 0.35 * (dist / far).min(1.0));
                    let t = (f64::from(end.z) - zlo) / (zhi - zlo);
                    height_colour(t).map(|c| (c * shade).round() as u8)
                }
                _ => UNKNOWN,
            };
            line[col * 3..col * 3 + 3].copy_from_slice(&px);
        }
    });
    Ok((w, h, img))
}

pub fn run(a: Args) -> Result<()> {
    extension(&a.output, &["png"])?;
    let depth = depth_arg(a.depth)?;
    if a.width == 0 || a.width > MAX_SIDE || a.height.is_some_and(|h| h == 0 || h > MAX_SIDE) {
        bail!("--width and --height must be between 1 and {MAX_SIDE}");
    }
    let height = match (a.height, a.view) {
        (Some(h), _) => Some((h, "--height")),
        (None, View::Perspective) => Some((perspective_height(a.width), "the default --height")),
        (None, View::Top) => None, // from the map's aspect, within the limit
    };
    if let Some((h, name)) = height {
        let pixels = u64::from(a.width) * u64::from(h);
        if pixels > MAX_PIXELS {
            bail!(
                "--width {} × {name} {h} = {pixels} pixels exceeds the limit of {MAX_PIXELS} (2^26, 8192 × 8192)",
                a.width
            );
        }
    }
    let tree = load_map(&a.map)?.tree;
    let (w, h, img) = match a.view {
        View::Top => top_view(&tree, &a, depth)?,
        View::Perspective => perspective(&tree, &a, depth)?,
    };
    write_output(&a.output, |out| {
        let mut enc = png::Encoder::new(out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(std::io::Error::other)?;
        writer.write_image_data(&img).map_err(std::io::Error::other)?;
        writer.finish().map_err(std::io::Error::other)
    })?;
    eprintln!("wrote {w}x{h} image to {}", a.output.display());
    Ok(())
}
