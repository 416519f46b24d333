//! `octolinear info`, `convert` and `query`: inspect, convert and query maps.

use super::common::{load_any, load_map, save_counting, save_map, AnyMap, MapFormat};
use anyhow::{bail, Context, Result};
use octolinear::formats::xyz;
use octolinear::{BoundsRule, Key, KeySpace, NodeKind, OccupancyTree, Point3};
use std::path::PathBuf;

/// Print the kind, resolution and statistics of a map (.bt or .ot).
///
/// Example: octolinear info map.ot --json
#[derive(clap::Args)]
pub struct Args {
    map: PathBuf,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

fn summary(tree: &OccupancyTree, kind: &str) -> serde_json::Value {
    let sensor = tree.sensor();
    let b = tree.bounds(BoundsRule::CenterHalfSize);
    let mut depth_histogram = [0usize; 17];
    let (mut occupied, mut free, mut occupied_volume, mut free_volume) = (0usize, 0usize, 0.0, 0.0);
    for leaf in tree.leaves(0) {
        depth_histogram[leaf.depth as usize] += 1;
        let v = leaf.size().powi(3);
        if sensor.is_occupied(leaf.value) {
            occupied += 1;
            occupied_volume += v;
        } else {
            free += 1;
            free_volume += v;
        }
    }
    serde_json::json!({
        "kind": kind,
        "resolution": tree.resolution(),
        "nodes": tree.size(),
        "leaves": tree.num_leaves(),
        "occupied_leaves": occupied,
        "free_leaves": free,
        "occupied_volume_m3": occupied_volume,
        "free_volume_m3": free_volume,
        "bounds_min": if tree.is_empty() { None } else { Some(b.min) },
        "bounds_max": if tree.is_empty() { None } else { Some(b.max) },
        "memory_bytes": tree.memory_usage(),
        "octomap_memory_bytes": tree.octomap_memory_usage(),
        "leaves_per_depth": depth_histogram,
    })
}

pub fn run(a: Args) -> Result<()> {
    let m = load_map(&a.map)?;
    let s = summary(&m.tree, m.kind);
    if a.json {
        println!("{s}");
        return Ok(());
    }
    println!("{}: {}", a.map.display(), s["kind"].as_str().unwrap_or(""));
    println!("resolution:  {} m", s["resolution"]);
    println!(
        "nodes:       {} ({} leaves: {} occupied, {} free)",
        s["nodes"], s["leaves"], s["occupied_leaves"], s["free_leaves"]
    );
    println!(
        "volume:      {:.3} m^3 occupied, {:.3} m^3 free",
        s["occupied_volume_m3"].as_f64().unwrap_or(0.0),
        s["free_volume_m3"].as_f64().unwrap_or(0.0)
    );
    if !m.tree.is_empty() {
        println!("bounds:      {} .. {}", s["bounds_min"], s["bounds_max"]);
    }
    println!("memory:      {} bytes here, {} bytes in OctoMap", s["memory_bytes"], s["octomap_memory_bytes"]);
    let hist: Vec<String> = s["leaves_per_depth"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
        .filter(|(_, v)| v.as_u64() != Some(0))
        .map(|(d, v)| format!("{d}:{v}"))
        .collect();
    println!("leaves by depth: {}", hist.join(" "));
    Ok(())
}

/// Convert a map between formats, chosen by extension (.bt, .ot, .olm).
///
/// Colour and stamped trees keep their colours and stamps in .ot and .olm;
/// .bt holds occupancy only. Counting trees convert between .ot and .olm.
/// An .olm output holds every node's log-odds unless --ml asks for the
/// maximum-likelihood variant (what .bt stores, several times smaller).
///
/// Example: octolinear convert map.ot map.bt
#[derive(clap::Args)]
pub struct ConvertArgs {
    input: PathBuf,
    output: PathBuf,
    /// Write the maximum-likelihood variant of .olm (occupancy maps only).
    #[arg(long)]
    ml: bool,
    /// Add the search-blocks section to a full .olm of an occupancy map
    /// (about a fifth more file; full-depth searches of maps with millions
    /// of nodes about 1.6x faster).
    #[arg(long, conflicts_with = "ml")]
    search_blocks: bool,
}

pub fn convert(a: ConvertArgs) -> Result<()> {
    if (a.ml || a.search_blocks) && MapFormat::of(&a.output)? != MapFormat::Olm {
        let flag = if a.ml { "--ml" } else { "--search-blocks" };
        bail!("{flag} applies to .olm output, not {}", a.output.display());
    }
    match load_any(&a.input)? {
        AnyMap::Occupancy(m) if a.ml => {
            let opts = octolinear::mapped::WriteOptions::max_likelihood();
            octolinear::mapped::write_file_with(&m.tree, &a.output, opts)
                .with_context(|| format!("cannot write {}", a.output.display()))
        }
        AnyMap::Occupancy(m) if a.search_blocks => {
            let opts = octolinear::mapped::WriteOptions {
                search_blocks: octolinear::mapped::SearchBlocksSection::Always,
                ..Default::default()
            };
            octolinear::mapped::write_file_with(&m.tree, &a.output, opts)
                .with_context(|| format!("cannot write {}", a.output.display()))
        }
        AnyMap::Occupancy(m) => save_map(&m.tree, &a.output),
        AnyMap::Counting(_) if a.ml => bail!("{}: a counting tree has no maximum-likelihood form", a.input.display()),
        AnyMap::Counting(t) => save_counting(&t, &a.output),
    }
}

/// Look up points in a map: prints `x,y,z,state,logodds_bits` per point.
///
/// `state` is occupied, free or unknown; `logodds_bits` the f32 bits in hex
/// (empty when unknown). Colour maps (ColorOcTree) add `,r,g,b` (decimal,
/// white when never set) and stamped maps (OcTreeStamped) `,stamp`; these
/// fields are empty when unknown. Counting trees (CountingOcTree, `.ot` or
/// `.olm`) print `x,y,z,state,count` instead, with state `counted` or
/// `unknown` and the decimal hit count of the node found (empty when
/// unknown).
///
/// Example: octolinear query map.bt --points points.xyz
#[derive(clap::Args)]
pub struct QueryArgs {
    map: PathBuf,
    /// Text file with one `x y z` per line.
    #[arg(long)]
    points: PathBuf,
}

pub fn query(a: QueryArgs) -> Result<()> {
    use std::io::Write;
    let pts = xyz::read_file(&a.points).with_context(|| format!("cannot read {}", a.points.display()))?;
    if pts.points.is_empty() {
        bail!("{}: no points", a.points.display());
    }
    // `.olm` maps are queried where they lie, without a parse step; both
    // answer the whole batch with `search_many` (eight descents in flight);
    // points outside the map (or not finite) are unknown
    let keys_of = |ks: &KeySpace| -> Vec<Option<Key>> { pts.points.iter().map(|p| ks.key(*p).ok()).collect() };
    let valid = |k: &[Option<Key>]| -> Vec<Key> { k.iter().flatten().copied().collect() };
    let (loaded, mapped);
    let mut answers = Vec::new();
    let (kind, point_keys, occupied): (_, _, Box<dyn Fn(f32) -> bool>) = if MapFormat::of(&a.map)? == MapFormat::Olm {
        mapped =
            octolinear::mapped::open(&a.map).with_context(|| format!("{}: not a valid .olm map", a.map.display()))?;
        let view = mapped.view();
        let point_keys = keys_of(view.key_space());
        let Some(kind) = view.kind().node_kind() else {
            let counts = point_keys.iter().map(|k| k.and_then(|k| view.count(k, 0)));
            return print_counts(&pts.points, counts);
        };
        mapped.search_many(&valid(&point_keys), 0, &mut answers);
        (kind, point_keys, Box::new(|v| mapped.view().is_occupied(v)))
    } else {
        loaded = match load_any(&a.map)? {
            AnyMap::Occupancy(m) => m,
            AnyMap::Counting(t) => {
                let counts = pts.points.iter().map(|p| t.key_space().key(*p).ok().and_then(|k| t.count(k, 0)));
                return print_counts(&pts.points, counts);
            }
        };
        let point_keys = keys_of(loaded.tree.key_space());
        loaded.tree.search_many(&valid(&point_keys), 0, &mut answers);
        (loaded.tree.kind(), point_keys, Box::new(|v| loaded.tree.is_occupied(v)))
    };
    let mut answers = answers.into_iter();
    let lookup = |k: &Option<Key>| match k.and_then(|_| answers.next().flatten()) {
        Some(f) => (Some(f), occupied(f.value)),
        None => (None, false),
    };
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let mut lookup = lookup;
    for (p, k) in pts.points.iter().zip(&point_keys) {
        let found = lookup(k);
        let (state, bits) = match found {
            (Some(f), true) => ("occupied", format!("{:08x}", f.value.to_bits())),
            (Some(f), false) => ("free", format!("{:08x}", f.value.to_bits())),
            (None, _) => ("unknown", String::new()),
        };
        let extra = match (kind, found.0) {
            (NodeKind::Plain, _) => String::new(),
            (NodeKind::Color, Some(f)) => {
                let [r, g, b] = octolinear::tree::unpack_rgb(f.extra);
                format!(",{r},{g},{b}")
            }
            (NodeKind::Color, None) => ",,,".to_string(),
            (NodeKind::Stamped, Some(f)) => format!(",{}", f.extra),
            (NodeKind::Stamped, None) => ",".to_string(),
        };
        writeln!(out, "{},{},{},{state},{bits}{extra}", p.x, p.y, p.z)?;
    }
    out.flush()?;
    Ok(())
}

/// `x,y,z,counted,COUNT` or `x,y,z,unknown,` per point.
fn print_counts(points: &[Point3], counts: impl Iterator<Item = Option<u32>>) -> Result<()> {
    use std::io::Write;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for (p, c) in points.iter().zip(counts) {
        match c {
            Some(c) => writeln!(out, "{},{},{},counted,{c}", p.x, p.y, p.z)?,
            None => writeln!(out, "{},{},{},unknown,", p.x, p.y, p.z)?,
        }
    }
    out.flush()?;
    Ok(())
}

/// Check every byte of a memory-mapped `.olm` map: child indices, order,
/// counts and checksums.
///
/// Example: octolinear verify map.olm
#[derive(clap::Args)]
pub struct VerifyArgs {
    map: PathBuf,
}

pub fn verify(a: VerifyArgs) -> Result<()> {
    let m = octolinear::mapped::open(&a.map).with_context(|| format!("{}: not a valid .olm map", a.map.display()))?;
    let report = m.verify().with_context(|| format!("{}: damaged", a.map.display()))?;
    println!("{}: ok ({report:?})", a.map.display());
    Ok(())
}
