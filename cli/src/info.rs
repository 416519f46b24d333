//! `octolinear info`, `convert`, `query` and `verify`: inspect, convert,
//! query and check maps.

use super::common::{
    human_number, load_any, load_map, open_olm, save_counting, save_map, verify_olm, AnyMap, MapFormat, OutputArg,
};
use super::tiles;
use anyhow::{bail, Context, Result};
use octolinear::formats::{bt, ot, write_atomically, xyz};
use octolinear::mapped::{Index, MappedMap, SectionKind, TreeKind, Variant};
use octolinear::sensor::probability;
use octolinear::{BoundsRule, Key, KeySpace, NodeKind, OccupancyTree, Point3};
use std::path::{Path, PathBuf};

/// Print the kind, resolution and statistics of a map (.bt, .ot or .olm),
/// or of a tile set (NAME.tiles: its manifest's numbers, no tile read).
///
/// Numbers are printed in their shortest form at the map's f32 precision;
/// --json gives them in full.
///
/// Example: octolinear info map.ot --json
#[derive(clap::Args)]
pub struct Args {
    /// The map (.bt, .ot or .olm; an .olm map is verified first), or a
    /// tile set (NAME.tiles).
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
    if tiles::is_tile_set(&a.map) {
        return tiles::info(&a.map, a.json);
    }
    let m = load_map(&a.map)?;
    let s = summary(&m.tree, m.kind);
    if a.json {
        println!("{s}");
        return Ok(());
    }
    println!("{}: {}", a.map.display(), s["kind"].as_str().unwrap_or(""));
    let number = |v: &serde_json::Value| human_number(v.as_f64().unwrap_or(f64::NAN));
    let point = |v: &serde_json::Value| {
        let xyz: Vec<String> = v.as_array().into_iter().flatten().map(number).collect();
        format!("({})", xyz.join(", "))
    };
    println!("resolution:  {} m", number(&s["resolution"]));
    println!(
        "nodes:       {} ({} leaves: {} occupied, {} free)",
        s["nodes"], s["leaves"], s["occupied_leaves"], s["free_leaves"]
    );
    println!(
        "volume:      {} m^3 occupied, {} m^3 free",
        number(&s["occupied_volume_m3"]),
        number(&s["free_volume_m3"])
    );
    if !m.tree.is_empty() {
        println!("bounds:      {} .. {} m", point(&s["bounds_min"]), point(&s["bounds_max"]));
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
/// An .olm input is verified first. Prints one line on stderr saying what
/// was written.
///
/// Example: octolinear convert map.ot map.bt
#[derive(clap::Args)]
pub struct ConvertArgs {
    /// The map to read (.bt, .ot or .olm), or a tile set (NAME.tiles):
    /// written to .ot or .bt tile by tile, one tile in memory at a time;
    /// merged into one map in memory for .olm, whose layout needs the
    /// whole tree.
    input: PathBuf,
    #[command(flatten)]
    output: OutputArg,
    /// Write the maximum-likelihood variant of .olm (occupancy maps only).
    #[arg(long)]
    ml: bool,
    /// Add the search-blocks section to a full .olm of an occupancy map
    /// (about a fifth more file, for faster full-depth searches of maps
    /// with millions of nodes; docs/benchmarks.md, "Memory-mapped maps").
    #[arg(long, conflicts_with = "ml")]
    search_blocks: bool,
}

pub fn convert(a: ConvertArgs) -> Result<()> {
    let format = MapFormat::from_path(a.output.path())?;
    if (a.ml || a.search_blocks) && format != MapFormat::Olm {
        let flag = if a.ml { "--ml" } else { "--search-blocks" };
        bail!("{flag} applies to .olm output, not {}", a.output.path().display());
    }
    let write_olm = |tree: &OccupancyTree, opts| {
        octolinear::mapped::write_file_with(tree, a.output.path(), opts)
            .with_context(|| format!("cannot write {}", a.output.path().display()))
    };
    let streamed = super::tiles::is_tile_set(&a.input) && format != MapFormat::Olm;
    let (kind, nodes) = if streamed {
        // the tiles walked one at a time, straight into the file
        let set = super::tiles::open(&a.input)?;
        // a tile set may be larger than memory: .bt records wait on disk
        let dir = a.output.path().parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let mut scratch = (format == MapFormat::Bt).then(|| super::build::scratch_file(dir)).transpose()?;
        write_atomically(a.output.path(), |w| match scratch.take() {
            Some(file) => bt::write_map_observed_with_scratch(&set, w, &mut (), file).map(|_| ()),
            None => ot::write_map(&set, w),
        })
        .with_context(|| format!("cannot write {}", a.output.path().display()))?;
        (set.manifest().kind, set.node_count() as usize)
    } else {
        match load_any(&a.input)? {
            AnyMap::Occupancy(m) => {
                if a.ml {
                    write_olm(&m.tree, octolinear::mapped::WriteOptions::max_likelihood())?;
                } else if a.search_blocks {
                    let search_blocks = octolinear::mapped::SearchBlocksSection::Always;
                    write_olm(&m.tree, octolinear::mapped::WriteOptions { search_blocks, ..Default::default() })?;
                } else {
                    save_map(&m.tree, a.output.path())?;
                }
                (TreeKind::of(m.tree.kind()), m.tree.size())
            }
            AnyMap::Counting(_) if a.ml => {
                bail!("{}: a counting tree has no maximum-likelihood form", a.input.display())
            }
            AnyMap::Counting(t) => {
                save_counting(&t, a.output.path())?;
                (TreeKind::CountingOcTree, t.size())
            }
        }
    };
    let what = match format {
        MapFormat::Bt => "OcTree, maximum likelihood".to_string(),
        MapFormat::Olm if a.ml => format!("{}, maximum likelihood", kind.name()),
        MapFormat::Olm if a.search_blocks => format!("{}, with search blocks", kind.name()),
        _ => kind.name().to_string(),
    };
    // the maximum-likelihood tree that .bt and `--ml` store is pruned: an
    // .olm header says its count, a .bt file would have to be read back
    let nodes = match format {
        MapFormat::Olm => {
            let written = octolinear::mapped::open(a.output.path())
                .with_context(|| format!("cannot read {}", a.output.path().display()))?;
            format!(", {} nodes", written.header().node_count)
        }
        MapFormat::Ot => format!(", {nodes} nodes"),
        MapFormat::Bt => String::new(),
    };
    let bytes =
        std::fs::metadata(a.output.path()).with_context(|| format!("cannot read {}", a.output.path().display()))?.len();
    eprintln!("wrote {} ({what}{nodes}, {bytes} bytes)", a.output.path().display());
    Ok(())
}

/// What `query` prints per point of an occupancy map.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum QueryFormat {
    /// `x,y,z,state,logodds_bits`: the log-odds as f32 bits in hex.
    Bits,
    /// `x,y,z,state,logodds,probability`: decimal numbers.
    Decimal,
}

/// Look up points in a map: one comma-separated line per point.
///
/// `--format bits` (the default) prints `x,y,z,state,logodds_bits`: `state`
/// is occupied, free or unknown, `logodds_bits` the f32 bits in hex.
/// `--format decimal` prints `x,y,z,state,logodds,probability` instead, the
/// log-odds and the occupancy probability in their shortest decimal form
/// at f32 precision. The value fields are empty when unknown.
///
/// Colour maps (ColorOcTree) add `,r,g,b` (decimal, white when never set)
/// and stamped maps (OcTreeStamped) `,stamp`; these fields are empty when
/// unknown. Counting trees (CountingOcTree, `.ot` or `.olm`) print
/// `x,y,z,state,count` in either format, with state `counted` or `unknown`
/// and the decimal hit count of the node found (empty when unknown).
///
/// An `.olm` map is queried in place after a check of all its bytes
/// (checksums and structure, as `verify`); a damaged map is an error.
///
/// Example: octolinear query map.olm --points points.xyz --format decimal
#[derive(clap::Args)]
pub struct QueryArgs {
    /// The map (.bt, .ot or .olm), or a tile set (NAME.tiles: only the
    /// tiles the points reach are mapped, each checked as an .olm map is).
    map: PathBuf,
    /// Text file with one `x y z` per line (a pipe such as /dev/stdin works:
    /// the map is opened first).
    #[arg(long)]
    points: PathBuf,
    /// Output columns (see above).
    #[arg(long, value_enum, default_value_t = QueryFormat::Bits)]
    format: QueryFormat,
    /// Skip the check of an .olm map's bytes (it reads the whole file: for
    /// huge maps you trust). A damaged map then answers without an error,
    /// and wrongly where it is damaged: a flipped bit can turn free space
    /// occupied or known space unknown. .bt and .ot maps are read whole
    /// either way.
    #[arg(long)]
    no_verify: bool,
}

/// The map a query reads: mapped in place, or read into memory.
// one per command run: the size difference costs nothing
#[allow(clippy::large_enum_variant)]
enum QueryMap {
    Mapped(MappedMap<memmap2::Mmap>),
    Loaded(AnyMap),
    /// Tiles mapped as the points reach them.
    Tiles(octolinear::tiles::TileSet),
}

pub fn query(a: QueryArgs) -> Result<()> {
    use std::io::Write;
    // the map first: its errors come before a long read of points, and the
    // points may come from a pipe
    let map = if tiles::is_tile_set(&a.map) {
        QueryMap::Tiles(tiles::open_for_queries(&a.map, a.no_verify)?)
    } else if MapFormat::from_path(&a.map)? == MapFormat::Olm {
        let map = open_olm(&a.map)?;
        if !a.no_verify {
            verify_olm(&a.map, &map)?;
        }
        QueryMap::Mapped(map)
    } else {
        QueryMap::Loaded(load_any(&a.map)?)
    };
    let pts = xyz::read_file(&a.points).with_context(|| format!("cannot read {}", a.points.display()))?;
    if pts.points.is_empty() {
        bail!("{}: no points", a.points.display());
    }
    // both answer the whole batch with `search_many` (eight descents in
    // flight); points outside the map (or not finite) are unknown
    let keys_of = |ks: &KeySpace| -> Vec<Option<Key>> { pts.points.iter().map(|p| ks.key(*p).ok()).collect() };
    let valid = |k: &[Option<Key>]| -> Vec<Key> { k.iter().flatten().copied().collect() };
    let mut answers = Vec::new();
    let (kind, point_keys, sensor) = match &map {
        QueryMap::Mapped(map) => {
            let view = map.view();
            let point_keys = keys_of(view.key_space());
            let Some(kind) = view.kind().node_kind() else {
                let counts = point_keys.iter().map(|k| k.and_then(|k| view.count(k, 0)));
                return print_counts(&pts.points, counts);
            };
            view.search_many(&valid(&point_keys), 0, &mut answers);
            (kind, point_keys, view.sensor())
        }
        QueryMap::Loaded(AnyMap::Counting(t)) => {
            let counts = pts.points.iter().map(|p| t.key_space().key(*p).ok().and_then(|k| t.count(k, 0)));
            return print_counts(&pts.points, counts);
        }
        QueryMap::Tiles(set) => {
            let point_keys = keys_of(set.key_space());
            answers = tiles::search_all(set, &valid(&point_keys))?;
            (set.manifest().node_kind(), point_keys, set.sensor())
        }
        QueryMap::Loaded(AnyMap::Occupancy(m)) => {
            let point_keys = keys_of(m.tree.key_space());
            m.tree.search_many(&valid(&point_keys), 0, &mut answers);
            (m.tree.kind(), point_keys, m.tree.sensor())
        }
    };
    let mut answers = answers.into_iter();
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for (p, k) in pts.points.iter().zip(&point_keys) {
        let found = k.and_then(|_| answers.next().flatten());
        let state = match found {
            Some(f) if sensor.is_occupied(f.value) => "occupied",
            Some(_) => "free",
            None => "unknown",
        };
        let value = match (a.format, found) {
            (QueryFormat::Bits, Some(f)) => format!("{:08x}", f.value.to_bits()),
            (QueryFormat::Bits, None) => String::new(),
            (QueryFormat::Decimal, Some(f)) => {
                let logodds = f64::from(f.value);
                format!("{},{}", human_number(logodds), human_number(probability(logodds)))
            }
            (QueryFormat::Decimal, None) => ",".to_string(),
        };
        let extra = match (kind, found) {
            (NodeKind::Plain, _) => String::new(),
            (NodeKind::Color, Some(f)) => {
                let [r, g, b] = octolinear::tree::unpack_rgb(f.extra);
                format!(",{r},{g},{b}")
            }
            (NodeKind::Color, None) => ",,,".to_string(),
            (NodeKind::Stamped, Some(f)) => format!(",{}", f.extra),
            (NodeKind::Stamped, None) => ",".to_string(),
        };
        writeln!(out, "{},{},{},{state},{value}{extra}", p.x, p.y, p.z)?;
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

/// Check every byte of a memory-mapped `.olm` map: header and section
/// checksums, zero padding, the child index and the tree structure. Of a
/// tile set (NAME.tiles): its manifest, then every tile file so, with its
/// length, CRC-32 and root node against the manifest.
///
/// Prints what was checked and the map's node counts (--json: one JSON
/// object). A damaged map is an error naming the first problem found.
///
/// Example: octolinear verify map.olm
#[derive(clap::Args)]
pub struct VerifyArgs {
    /// The map (.olm), or a tile set (NAME.tiles).
    map: PathBuf,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
}

pub fn verify(a: VerifyArgs) -> Result<()> {
    if tiles::is_tile_set(&a.map) {
        return tiles::verify(&a.map, a.json);
    }
    if matches!(MapFormat::from_path(&a.map), Ok(MapFormat::Bt | MapFormat::Ot)) {
        bail!("{}: verify checks .olm maps (.bt and .ot carry no checksums)", a.map.display());
    }
    let map = open_olm(&a.map)?;
    let report = verify_olm(&a.map, &map)?;
    let h = map.header();
    let sections: Vec<&str> =
        h.sections.iter().map(|s| SectionKind::from_id(s.kind).map_or("optional", SectionKind::name)).collect();
    let variant = match h.variant {
        Variant::Full => "full",
        Variant::MaxLikelihood => "maximum-likelihood",
    };
    let (index, index_text) = match h.index {
        Index::Rank => ("rank", "rank directory"),
        Index::Pointers => ("pointers", "first-child pointers"),
    };
    if a.json {
        let out = serde_json::json!({
            "map": a.map, "ok": true, "kind": h.kind.name(), "variant": variant, "index": index,
            "resolution": h.resolution, "file_bytes": h.file_length, "checked_bytes": report.checked_bytes,
            "sections": sections, "nodes": report.nodes, "inner_nodes": report.inner_nodes,
            "leaves": report.leaves, "max_depth": report.max_depth,
        });
        println!("{out}");
        return Ok(());
    }
    println!("{}: ok", a.map.display());
    println!(
        "map:         {}, {variant} variant, resolution {} m, {} bytes",
        h.kind.name(),
        human_number(h.resolution),
        h.file_length
    );
    println!(
        "checksums:   header and {} sections ({}): {} bytes",
        sections.len(),
        sections.join(", "),
        report.checked_bytes
    );
    println!(
        "structure:   zero padding, {index_text}, one tree of {} nodes ({} inner, {} leaves), depth {}",
        report.nodes, report.inner_nodes, report.leaves, report.max_depth
    );
    Ok(())
}
