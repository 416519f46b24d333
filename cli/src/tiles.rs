//! Tile sets (`NAME.tiles/`) on the command line: `octolinear tiles
//! manifest`, and what `build`, `info`, `query`, `verify` and the map
//! readers do with a tile set (formats/tiles.md).

use super::common::{human_number, LoadedMap};
use anyhow::{bail, Context, Result};
use octolinear::tiles::{combine_parts, TaskPart, TileCheck, TileSet, MANIFEST_FILE};
use octolinear::Key;
use std::path::{Path, PathBuf};

/// Work on tile sets (NAME.tiles directories, see `build --tile-depth`).
///
/// `manifest` combines the parts that `build --task K/N` runs wrote into
/// the set's manifest, once every part is there.
///
/// Example: octolinear tiles manifest map.tiles
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: TilesCommand,
}

#[derive(clap::Subcommand)]
enum TilesCommand {
    /// Write the manifest of a tile set built in parts (`build --task K/N`),
    /// from the parts' task-K-of-N.manifest files, which are then removed.
    /// Parts built with other options or from another input (each part
    /// records them) are refused, the first difference named.
    Manifest {
        /// The tile set's directory.
        dir: PathBuf,
    },
}

pub fn run(a: Args) -> Result<()> {
    match a.command {
        TilesCommand::Manifest { dir } => {
            // takes the set's lock itself: not beside a build into the set
            let manifest = combine_parts(&dir)?;
            let nodes: u64 = manifest.tiles.iter().map(|t| t.nodes).sum();
            eprintln!(
                "wrote {} ({} tiles at depth {}, {nodes} nodes in tile files)",
                dir.join(MANIFEST_FILE).display(),
                manifest.tiles.len(),
                manifest.depth
            );
            let merged = TileSet::open(&dir)?.node_count();
            if let Some(over) = octolinear::tiles::oversize(&manifest, merged) {
                eprintln!("octolinear: warning: {}: {over} (see build --help, --tile-depth)", dir.display());
            }
            Ok(())
        }
    }
}

/// True when `path` names a tile set (extension `.tiles`, the library's
/// [`octolinear::tiles::is_tile_set_name`]).
pub fn is_tile_set(path: &Path) -> bool {
    octolinear::tiles::is_tile_set_name(path)
}

/// Opens a tile set (its manifest only).
pub fn open(path: &Path) -> Result<TileSet> {
    Ok(TileSet::open(path)?)
}

/// A tile set merged into one tree, for the commands that work on whole maps.
pub fn load(path: &Path) -> Result<LoadedMap> {
    let set = open(path)?;
    let tree = set.merge()?;
    let kind = match set.manifest().kind {
        octolinear::TreeKind::OcTreeStamped => "OcTreeStamped (tile set, merged)",
        _ => "OcTree (tile set, merged)",
    };
    Ok(LoadedMap { tree, kind })
}

/// `info` of a tile set: the manifest's numbers, without reading a tile.
pub fn info(path: &Path, json: bool) -> Result<()> {
    let set = open(path)?;
    let m = set.manifest();
    let bytes: u64 = m.tiles.iter().map(|t| t.bytes).sum();
    let edge = set.key_space().node_size(m.depth);
    let (mut min, mut max) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for t in &m.tiles {
        let b = t.id.bounds(set.key_space());
        for i in 0..3 {
            min[i] = min[i].min(b.min[i]);
            max[i] = max[i].max(b.max[i]);
        }
    }
    let s = serde_json::json!({
        "kind": m.kind.name(), "resolution": m.resolution, "tile_depth": m.depth, "tile_edge_m": edge,
        "tiles": m.tiles.len(), "pruned_tiles": m.tiles.iter().filter(|t| t.root.is_leaf).count(),
        "tile_bytes": bytes, "nodes": set.node_count(),
        "tiles_min": (!m.tiles.is_empty()).then_some(min), "tiles_max": (!m.tiles.is_empty()).then_some(max),
    });
    if json {
        println!("{s}");
        return Ok(());
    }
    let point = |p: [f64; 3]| format!("({})", p.map(human_number).join(", "));
    println!("{}: {} tile set", path.display(), m.kind.name());
    println!("resolution:  {} m", human_number(m.resolution));
    println!(
        "tiles:       {} at depth {} ({} m a side), {} pruned whole",
        s["tiles"],
        m.depth,
        human_number(edge),
        s["pruned_tiles"]
    );
    println!("nodes:       {} (merged map), {bytes} bytes of tile files", s["nodes"]);
    if !m.tiles.is_empty() {
        println!("tiles span:  {} .. {} m", point(min), point(max));
    }
    Ok(())
}

/// `verify` of a tile set: the manifest, then every tile fully.
pub fn verify(path: &Path, json: bool) -> Result<()> {
    let set = open(path)?;
    let report = set.verify()?;
    let m = set.manifest();
    if json {
        let out = serde_json::json!({
            "map": path, "ok": true, "kind": m.kind.name(), "resolution": m.resolution, "tile_depth": m.depth,
            "tiles": report.tiles, "checked_bytes": report.bytes, "nodes": report.nodes,
        });
        println!("{out}");
        return Ok(());
    }
    println!("{}: ok", path.display());
    println!(
        "map:         {} tile set, resolution {} m, tile depth {}",
        m.kind.name(),
        human_number(m.resolution),
        m.depth
    );
    println!(
        "tiles:       {} files, {} bytes: lengths, CRC-32s, .olm checksums and structure, tile roots",
        report.tiles, report.bytes
    );
    println!("merged map:  {} nodes", report.nodes);
    Ok(())
}

/// A tile set for queries: tiles are mapped as points reach them, each
/// checked fully unless `no_verify` (then its header only).
pub fn open_for_queries(path: &Path, no_verify: bool) -> Result<TileSet> {
    let mut set = open(path)?;
    set.set_check(if no_verify { TileCheck::Header } else { TileCheck::Full });
    Ok(set)
}

/// Answers `keys` on a tile set (`None` keys stay unknown).
pub fn search_all(set: &TileSet, keys: &[Key]) -> Result<Vec<Option<octolinear::Found>>> {
    keys.iter().map(|&k| set.search(k, 0).context("cannot answer from the tile set")).collect()
}

/// `--task K/N`: this process's share of a tile set built in parts.
pub fn task_arg(s: &str) -> Result<TaskPart> {
    let parsed = s.split_once('/').and_then(|(k, n)| Some((k.parse::<u32>().ok()?, n.parse::<u32>().ok()?)));
    match parsed.and_then(|(index, count)| TaskPart::checked(index, count)) {
        Some(task) => Ok(task),
        None => bail!("--task must be K/N with 0 <= K < N <= {}, got {s:?}", octolinear::tiles::MAX_TASKS),
    }
}

/// `--memory-cap SIZE`: bytes, with an optional K, M or G (powers of 1024)
/// and an optional B.
pub fn size_arg(s: &str) -> Result<usize> {
    let t = s.trim();
    let t = t.strip_suffix(['B', 'b']).unwrap_or(t);
    let (digits, unit) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => (&t[..i], c.to_ascii_uppercase()),
        _ => (t, ' '),
    };
    let factor: u64 = match unit {
        ' ' => 1,
        'K' => 1 << 10,
        'M' => 1 << 20,
        'G' => 1 << 30,
        _ => bail!("--memory-cap {s:?}: the unit must be K, M or G"),
    };
    let n: u64 = digits.parse().map_err(|_| anyhow::anyhow!("--memory-cap {s:?} is not a size such as 512M or 2G"))?;
    let bytes = n
        .checked_mul(factor)
        .filter(|&b| b > 0)
        .with_context(|| format!("--memory-cap {s:?} must be positive and fit in memory"))?;
    usize::try_from(bytes).with_context(|| format!("--memory-cap {s:?} is too large"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_tasks_parse() {
        assert_eq!(size_arg("64M").unwrap(), 64 << 20);
        assert_eq!(size_arg("2G").unwrap(), 2 << 30);
        assert_eq!(size_arg("512k").unwrap(), 512 << 10);
        assert_eq!(size_arg("1000").unwrap(), 1000);
        assert_eq!(size_arg("3MB").unwrap(), 3 << 20);
        for bad in ["", "M", "0", "-1M", "1T", "1.5G", "12X"] {
            assert!(size_arg(bad).is_err(), "{bad}");
        }
        assert_eq!(task_arg("2/3").unwrap(), TaskPart::hashed(2, 3));
        for bad in ["3/3", "1/0", "1", "a/b", "-1/2"] {
            assert!(task_arg(bad).is_err(), "{bad}");
        }
    }
}
