//! Helpers shared by the subcommands: map loading by extension, progress bars.

use anyhow::{bail, Context, Result};
use octolinear::formats::{bt, ot, write_atomically};
use octolinear::OccupancyTree;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

/// Map formats recognised by file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapFormat {
    Bt,
    Ot,
}

impl MapFormat {
    pub fn of(path: &Path) -> Result<MapFormat> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("bt") => Ok(MapFormat::Bt),
            Some("ot") => Ok(MapFormat::Ot),
            _ => bail!("{}: unknown map format (expected .bt or .ot)", path.display()),
        }
    }
}

/// A map read from disk, with what it was.
pub struct LoadedMap {
    pub tree: OccupancyTree,
    pub kind: &'static str,
}

pub fn load_map(path: &Path) -> Result<LoadedMap> {
    let format = MapFormat::of(path)?;
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let r = BufReader::with_capacity(1 << 16, file);
    Ok(match format {
        MapFormat::Bt => LoadedMap {
            tree: bt::read(r).with_context(|| format!("{}: not a valid .bt map", path.display()))?,
            kind: "OcTree (.bt, maximum likelihood)",
        },
        MapFormat::Ot => {
            let t = ot::read(r).with_context(|| format!("{}: not a valid .ot map", path.display()))?;
            let kind = t.kind().id();
            let tree = t
                .into_occupancy()
                .ok_or_else(|| anyhow::anyhow!("{}: a counting tree holds no occupancy", path.display()))?;
            LoadedMap { kind, tree }
        }
    })
}

/// Writes a map by extension, atomically.
pub fn save_map(tree: &OccupancyTree, path: &Path) -> Result<()> {
    let format = MapFormat::of(path)?;
    write_atomically(path, |w| match format {
        MapFormat::Bt => bt::write(tree, w),
        MapFormat::Ot => ot::write(tree, w),
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

/// A progress bar on a terminal, hidden otherwise.
pub fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
