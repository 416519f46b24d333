//! `octolinear edit` and `crop`: OctoMap's `edit_octree` (resolution
//! change) plus cropping to a box, expansion, pruning and conversion to
//! maximum likelihood.

use super::common::{load_map, point_arg, save_map, OutputArg};
use anyhow::{bail, Context, Result};
use octolinear::key::KeySpace;
use octolinear::sensor::SensorModel;
use octolinear::tree::{NodeRef, PreorderBuilder};
use octolinear::{Key, KeyBox, OccupancyTree, Point3};
use std::path::PathBuf;

/// Crop, rescale (like OctoMap's edit_octree), expand, threshold or prune a map.
///
/// Crop to a box, change the resolution (edit_octree --res / --scale),
/// expand, convert to maximum likelihood, prune. Operations run in that order; the output format follows the
/// extension (.bt is always written maximum-likelihood and pruned, as
/// OctoMap's writeBinary does).
///
/// Example: octolinear edit map.bt -o small.bt --min -2 -2 0 --max 2 2 1.5 --scale 2
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// Input map (.bt, .ot or .olm).
    input: PathBuf,
    #[command(flatten)]
    output: OutputArg,
    #[command(flatten)]
    crop: CropBox,
    /// New voxel size in metres (the tree structure is kept, the map scaled).
    #[arg(long, conflicts_with = "scale")]
    res: Option<f64>,
    /// Multiply the resolution by this factor.
    #[arg(long)]
    scale: Option<f64>,
    /// Expand every pruned node to full depth (kept in .ot output only).
    /// A leaf at depth d becomes 8^(16-d) voxels: the nodes to add are
    /// counted first, and more than --max-nodes are refused.
    #[arg(long)]
    expand: bool,
    /// Most nodes --expand may add, and most nodes the crop may make by
    /// splitting pruned nodes that straddle the box.
    #[arg(long, value_name = "N", default_value_t = octolinear::tree::OUTPUT_LIMIT)]
    max_nodes: u64,
    /// Set every node to its clamping bound (occupied or free).
    #[arg(long)]
    max_likelihood: bool,
    /// Merge groups of eight equal leaves.
    #[arg(long)]
    prune: bool,
}

/// Optional crop box flags.
#[derive(clap::Args)]
pub struct CropBox {
    /// Lower corner of the box to keep.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, requires = "max")]
    min: Option<Vec<f64>>,
    /// Upper corner of the box to keep.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, requires = "min")]
    max: Option<Vec<f64>>,
}

/// Crop a map to an axis-aligned box.
///
/// Keeps exactly the voxels whose keys
/// lie between the keys of the two corners (the voxels containing the
/// corners included, as OctoMap's bounding-box iterators count them).
/// Pruned nodes straddling the border are split; inner nodes are
/// recomputed as the maximum of their kept children.
///
/// Example: octolinear crop map.ot -o room.ot --min -2 -2 0 --max 2 2 1.5
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct CropArgs {
    /// Input map (.bt, .ot or .olm).
    input: PathBuf,
    #[command(flatten)]
    output: OutputArg,
    /// Lower corner of the box to keep.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, required = true)]
    min: Vec<f64>,
    /// Upper corner of the box to keep.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true, required = true)]
    max: Vec<f64>,
    /// Most nodes the crop may make by splitting pruned nodes that
    /// straddle the box (each split node's children down to the box's
    /// faces).
    #[arg(long, value_name = "N", default_value_t = octolinear::tree::OUTPUT_LIMIT)]
    max_nodes: u64,
}

/// The key box of two metric corners; coordinates beyond the map are
/// clamped to its edge.
pub fn key_box(keys: &KeySpace, min: Point3, max: Point3) -> Result<KeyBox> {
    let (lo, hi) = (min.to_array(), max.to_array());
    for i in 0..3 {
        if lo[i] > hi[i] {
            bail!("crop box: --min {:?} is above --max {:?} on axis {}", lo, hi, ["x", "y", "z"][i]);
        }
    }
    let key = |c: f32| -> u16 { keys.coord_to_key(f64::from(c)).unwrap_or(if c < 0.0 { 0 } else { u16::MAX }) };
    Ok(KeyBox { min: Key(lo.map(key)), max: Key(hi.map(key)) })
}

/// A node of the source, real or the virtual child of a pruned leaf.
#[derive(Clone, Copy)]
enum Src<'a> {
    Node(NodeRef<'a>),
    Leaf(f32),
}

impl<'a> Src<'a> {
    /// Child `pos` (a pruned leaf's children all hold its value).
    fn child(self, pos: usize) -> Option<Src<'a>> {
        match self {
            Src::Node(n) if n.has_children() => n.child(pos).map(Src::Node),
            Src::Node(n) => Some(Src::Leaf(n.value())),
            Src::Leaf(v) => Some(Src::Leaf(v)),
        }
    }
}

/// The smallest key of child `pos` of a node whose smallest key is `min`
/// and whose children have edge `half`.
fn child_min(min: [u32; 3], pos: usize, half: u32) -> [u32; 3] {
    [0, 1, 2].map(|a| min[a] + if pos & (1 << a) != 0 { half } else { 0 })
}

/// Where a node of edge `size` (smallest key `min`) lies against `kb`:
/// `None` outside it, `Some(true)` wholly inside, `Some(false)` across a face.
fn against_box(min: [u32; 3], size: u32, kb: &KeyBox) -> Option<bool> {
    let mut inside = true;
    for (i, &a) in min.iter().enumerate() {
        let (lo, hi) = (u32::from(kb.min.0[i]), u32::from(kb.max.0[i]));
        let b = a + size - 1;
        if b < lo || a > hi {
            return None;
        }
        inside &= a >= lo && b <= hi;
    }
    Some(inside)
}

/// How many nodes [`crop_node`] makes by splitting leaves (nodes that are
/// not in the source), counted without making them (saturating): a leaf
/// at depth `d` straddling a face of the box splits into up to
/// `4^(16 - d)` nodes along it, a count the map's extent drives.
fn split_nodes(src: Src<'_>, min: [u32; 3], depth: u8, kb: &KeyBox) -> u64 {
    let size = 1u32 << (16 - u32::from(depth));
    let Some(inside) = against_box(min, size, kb) else { return 0 };
    let own = u64::from(matches!(src, Src::Leaf(_)));
    if inside {
        return own;
    }
    if own == 1 {
        return 1u64.saturating_add(split_leaf_nodes(min, depth, kb));
    }
    let half = size / 2;
    let mut count = own;
    for pos in 0..8 {
        let Some(child) = src.child(pos) else { continue };
        let cmin = child_min(min, pos, half);
        count = count.saturating_add(split_nodes(child, cmin, depth + 1, kb));
    }
    count
}

/// The nodes [`crop_node`] makes below a leaf at `depth` (smallest key
/// `min`) that straddles the box, from the box's geometry: at each depth
/// below, the nodes that overlap the box, less the children of those
/// fully inside it one level up (which are kept whole).
fn split_leaf_nodes(min: [u32; 3], depth: u8, kb: &KeyBox) -> u64 {
    let size = 1u32 << (16 - u32::from(depth));
    // the box's part of the leaf on each axis, inclusive
    let span: [(u32, u32); 3] =
        std::array::from_fn(|i| (u32::from(kb.min.0[i]).max(min[i]), u32::from(kb.max.0[i]).min(min[i] + size - 1)));
    let product = |f: &dyn Fn(u32, u32) -> u64| span.iter().map(|&(lo, hi)| f(lo, hi)).fold(1u64, u64::saturating_mul);
    let mut total = 0u64;
    let mut inside_above = 0u64;
    for d in depth + 1..=16 {
        let w = 1u32 << (16 - u32::from(d));
        let overlapping = product(&|lo, hi| u64::from(hi / w - lo / w + 1));
        let inside = product(&|lo, hi| u64::from(((hi + 1) / w).saturating_sub(lo.div_ceil(w))));
        total = total.saturating_add(overlapping.saturating_sub(inside_above.saturating_mul(8)));
        inside_above = inside;
    }
    total
}

/// Appends the pre-order (value, child mask) of the part of a node inside
/// `kb`; `min` is the node's smallest key, `depth` its depth. Returns the
/// kept node's value, `None` when nothing of it is inside.
fn crop_node(src: Src<'_>, min: [u32; 3], depth: u8, kb: &KeyBox, out: &mut Vec<(f32, u8)>) -> Option<f32> {
    let size = 1u32 << (16 - u32::from(depth));
    let inside = against_box(min, size, kb)?;
    if inside {
        let v = match src {
            Src::Node(n) => {
                copy_preorder(n, out);
                n.value()
            }
            Src::Leaf(v) => {
                out.push((v, 0));
                v
            }
        };
        return Some(v);
    }
    // partly inside: a node above depth 16, split into its children
    let at = out.len();
    out.push((0.0, 0));
    let half = size / 2;
    let mut mask = 0u8;
    let mut max = -f32::MAX;
    for pos in 0..8 {
        let Some(child) = src.child(pos) else { continue };
        let cmin = child_min(min, pos, half);
        if let Some(v) = crop_node(child, cmin, depth + 1, kb, out) {
            mask |= 1 << pos;
            if v > max {
                max = v;
            }
        }
    }
    if mask == 0 {
        out.truncate(at);
        return None;
    }
    out[at] = (max, mask);
    Some(max)
}

fn copy_preorder(n: NodeRef<'_>, out: &mut Vec<(f32, u8)>) {
    out.push((n.value(), n.child_mask()));
    for (_, c) in n.children() {
        copy_preorder(c, out);
    }
}

/// Builds a tree from pre-order (value, mask) pairs.
fn from_preorder(nodes: &[(f32, u8)], resolution: f64, sensor: SensorModel) -> Result<OccupancyTree> {
    let mut b = PreorderBuilder::new();
    for (i, &(v, m)) in nodes.iter().enumerate() {
        b.push(v, m, i as u64)?;
    }
    b.finish(resolution, sensor)?.context("internal error: incomplete pre-order")
}

/// The part of `tree` inside `kb`, as a new tree, if splitting the pruned
/// nodes that straddle the box makes at most `limit` nodes.
pub fn crop(tree: &OccupancyTree, kb: &KeyBox, limit: u64) -> Result<OccupancyTree> {
    let mut out = Vec::new();
    if let Some(root) = tree.root() {
        let count = split_nodes(Src::Node(root), [0; 3], 0, kb);
        if count > limit {
            bail!(
                "crop: splitting the pruned nodes that straddle the box makes {count} nodes, more than the limit \
                 of {limit}; a higher --max-nodes allows it"
            );
        }
        crop_node(Src::Node(root), [0; 3], 0, kb, &mut out);
    }
    from_preorder(&out, tree.resolution(), *tree.sensor())
}

/// The same tree with another resolution (`setResolution`).
pub fn with_resolution(tree: &OccupancyTree, resolution: f64) -> Result<OccupancyTree> {
    let mut out = Vec::new();
    if let Some(root) = tree.root() {
        copy_preorder(root, &mut out);
    }
    from_preorder(&out, resolution, *tree.sensor())
}

fn positive(v: f64, flag: &str) -> Result<f64> {
    if !(v.is_finite() && v > 0.0) {
        bail!("{flag} must be a positive finite number, got {v}");
    }
    Ok(v)
}

/// The resolution `--res` or `--scale` gives a map of `old` metres, if
/// the library's rule ([`octolinear::key::check_resolution`]) accepts it.
fn new_resolution(old: f64, res: Option<f64>, scale: Option<f64>) -> Result<Option<f64>> {
    let (r, flag) = match (res, scale) {
        (Some(r), _) => (r, format!("--res {r:?}")),
        // edit_octree: --scale multiplies the resolution read from the file
        (None, Some(s)) => (old * s, format!("--scale {s:?} (of resolution {old:?} m)")),
        _ => return Ok(None),
    };
    octolinear::key::check_resolution(r).map(Some).map_err(|e| anyhow::anyhow!("{flag}: {e}"))
}

pub fn run(a: Args) -> Result<()> {
    super::common::MapFormat::from_path(a.output.path())?;
    if let Some(r) = a.res {
        positive(r, "--res")?;
    }
    if let Some(s) = a.scale {
        positive(s, "--scale")?;
    }
    let corners = match (&a.crop.min, &a.crop.max) {
        (Some(lo), Some(hi)) => Some((point_arg(lo, "--min")?, point_arg(hi, "--max")?)),
        _ => None,
    };
    let mut tree = load_map(&a.input)?.tree;
    if let Some((lo, hi)) = corners {
        let kb = key_box(tree.key_space(), lo, hi)?;
        tree = crop(&tree, &kb, a.max_nodes)?;
    }
    if let Some(r) = new_resolution(tree.resolution(), a.res, a.scale)? {
        tree = with_resolution(&tree, r)?;
    }
    if a.expand {
        tree.expand_within(a.max_nodes).map_err(|e| anyhow::anyhow!("--expand: {e} (--max-nodes)"))?;
    }
    if a.max_likelihood {
        tree.to_max_likelihood();
    }
    if a.prune {
        tree.prune();
    }
    save_map(&tree, a.output.path())?;
    let resolution = super::common::human_number(tree.resolution());
    eprintln!("wrote {} ({} nodes, resolution {resolution})", a.output.path().display(), tree.size());
    Ok(())
}

pub fn run_crop(a: CropArgs) -> Result<()> {
    run(Args {
        input: a.input,
        output: a.output,
        crop: CropBox { min: Some(a.min), max: Some(a.max) },
        res: None,
        scale: None,
        expand: false,
        max_nodes: a.max_nodes,
        max_likelihood: false,
        prune: false,
    })
}
