//! `octolinear binvox`: OctoMap's `binvox2bt` — voxel grids written by
//! Patrick Min's binvox into a `.bt` map.

use super::common::{point_arg, save_map};
use anyhow::{bail, Context, Result};
use octolinear::formats::binvox::{self, Binvox};
use octolinear::formats::bounded;
use octolinear::{InnerNodes, OccupancyTree, Point3};
use std::path::{Path, PathBuf};

/// Convert binvox voxel grids into a map (OctoMap's binvox2bt).
///
/// The voxel size is scale / largest dimension,
/// voxels with value 1 are marked occupied (the others stay unknown unless
/// --mark-free). Several inputs are merged into one map; the options apply
/// to all of them. The `.bt` output is byte-identical to binvox2bt's.
///
/// Example: octolinear binvox chair.binvox -o chair.bt --mark-free --offset 1 0 0
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// Input `.binvox` files.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Output map (.bt or .ot; default: first input + .bt).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Mark voxels that are not occupied as free (default: unknown).
    #[arg(long)]
    mark_free: bool,
    /// Rotate by 90 degrees about x (fixes files exported from Webots).
    #[arg(long)]
    rotate: bool,
    /// Keep only voxels inside this box.
    #[arg(long, num_args = 6, allow_negative_numbers = true,
          value_names = ["MINX", "MINY", "MINZ", "MAXX", "MAXY", "MAXZ"])]
    bb: Option<Vec<f64>>,
    /// Add this offset to every voxel coordinate.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    offset: Option<Vec<f64>>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Default)]
struct Counts {
    voxels: usize,
    out_of_box: usize,
}

/// Adds one grid to the tree (creating it at the grid's resolution).
fn insert(tree: &mut Option<OccupancyTree>, bv: &Binvox, a: &Args, path: &Path, counts: &mut Counts) -> Result<()> {
    let max_side = bv.dim.into_iter().max().unwrap_or(1) as i32;
    let res = f64::from(bv.scale) / f64::from(max_side);
    let t = tree.get_or_insert(OccupancyTree::new(res)?);
    let offset = match &a.offset {
        Some(o) => Some(point_arg(o, "--offset")?),
        None => None,
    };
    let [tx, ty, tz] = bv.translate.map(f64::from);
    let mut add = |value: u8, voxels: std::ops::Range<usize>| {
        if value != 0 {
            counts.voxels += voxels.len();
        }
        for j in voxels {
            let [x, y, z] = bv.coords(j);
            let mut p = Point3::new(
                (x as f64 * res + tx + 0.000001) as f32,
                (y as f64 * res + ty + 0.000001) as f32,
                (z as f64 * res + tz + 0.000001) as f32,
            );
            if a.rotate {
                p.rotate_ip(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
            }
            if let Some(o) = offset {
                p += o;
            }
            let inside = a.bb.as_ref().is_none_or(|b| {
                let c = p.to_array().map(f64::from);
                (0..3).all(|i| c[i] <= b[3 + i] && c[i] >= b[i])
            });
            if inside {
                if a.mark_free || value == 1 {
                    // points outside the map are skipped, as updateNode does
                    let _ = t.update_point(p, value == 1, InnerNodes::Defer);
                }
            } else {
                counts.out_of_box += 1;
            }
        }
    };
    bv.for_each_run(&mut add).with_context(|| format!("{}: not a valid binvox file", path.display()))?;
    Ok(())
}

pub fn run(a: Args) -> Result<()> {
    if let Some(b) = &a.bb {
        if b.iter().any(|v| !v.is_finite()) || (0..3).any(|i| b[i] > b[3 + i]) {
            bail!("--bb needs finite MIN <= MAX on every axis, got {b:?}");
        }
    }
    let output = a.output.clone().unwrap_or_else(|| {
        let mut s = a.inputs[0].clone().into_os_string();
        s.push(".bt");
        s.into()
    });
    super::common::MapFormat::from_path(&output)?;
    super::input::check_read_once(&a.inputs, "binvox")?;
    let mut tree = None;
    let mut counts = Counts::default();
    for path in &a.inputs {
        let bv = binvox::read_file(path).map_err(|e| match e {
            binvox::BinvoxError::Read(bounded::WholeError::Io(e)) => {
                anyhow::Error::new(e).context(format!("cannot open {}", path.display()))
            }
            e => anyhow::Error::new(e).context(format!("{}: not a binvox file", path.display())),
        })?;
        insert(&mut tree, &bv, &a, path, &mut counts)?;
    }
    let mut tree = tree.context("no input")?;
    tree.update_inner_occupancy();
    tree.prune();
    save_map(&tree, &output)?;
    if a.json {
        let out = serde_json::json!({
            "output": output, "resolution": tree.resolution(),
            "voxels": counts.voxels, "skipped_out_of_box": counts.out_of_box,
            "nodes": tree.size(),
        });
        println!("{out}");
    } else {
        println!(
            "read {} voxels, skipped {} (out of bounding box); resolution {}; wrote {}",
            counts.voxels,
            counts.out_of_box,
            super::common::human_number(tree.resolution()),
            output.display()
        );
    }
    Ok(())
}
