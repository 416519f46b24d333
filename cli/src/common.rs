//! Helpers shared by the subcommands: map loading by extension, progress
//! bars, numbers for people, and the report of a mapped file truncated
//! under the reader.

use anyhow::{bail, Context, Result};
use octolinear::formats::{bt, ot, write_atomically, xyz};
use octolinear::mapped::{MappedMap, TreeKind, VerifyReport};
use octolinear::{CountingTree, OccupancyTree};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// A command's output file: `-o PATH`, or the last positional argument
/// where OctoMap's tool takes it so (`convert`, `edit`, `crop`,
/// `to-points`).
#[derive(clap::Args)]
pub struct OutputArg {
    /// Output file (or give it as the last positional argument).
    #[arg(short, long = "output", value_name = "OUT", required_unless_present = "output_positional")]
    output: Option<PathBuf>,
    /// The output file, when not given with -o.
    #[arg(value_name = "OUT", conflicts_with = "output")]
    output_positional: Option<PathBuf>,
}

impl OutputArg {
    /// The output path, however it was given.
    pub fn path(&self) -> &Path {
        self.output.as_deref().or(self.output_positional.as_deref()).expect("clap requires one of the two")
    }
}

pub use octolinear::formats::MapFormat;

/// A map read from disk, with what it was.
pub struct LoadedMap {
    pub tree: OccupancyTree,
    pub kind: &'static str,
}

/// An occupancy map or a counting tree, as read from disk.
// one per command run: the size difference costs nothing
#[allow(clippy::large_enum_variant)]
pub enum AnyMap {
    Occupancy(LoadedMap),
    Counting(CountingTree),
}

/// Reads an occupancy map; a counting tree is an error.
pub fn load_map(path: &Path) -> Result<LoadedMap> {
    match load_any(path)? {
        AnyMap::Occupancy(m) => Ok(m),
        AnyMap::Counting(_) => bail!("{}: a counting tree holds no occupancy", path.display()),
    }
}

/// Reads any map by extension (`.ot` and `.olm` may hold a counting tree).
/// An `.olm` map is verified on the way (checksums and structure); a tile
/// set (`NAME.tiles`) is merged into one tree, each tile verified.
pub fn load_any(path: &Path) -> Result<AnyMap> {
    if super::tiles::is_tile_set(path) {
        return Ok(AnyMap::Occupancy(super::tiles::load(path)?));
    }
    let format = MapFormat::from_path(path)?;
    if format == MapFormat::Olm {
        let mapped = open_olm(path)?;
        let view = mapped.view();
        let invalid = || format!("{}: not a valid .olm map", path.display());
        let kind = match view.kind() {
            TreeKind::CountingOcTree => return Ok(AnyMap::Counting(view.to_counting_tree().with_context(invalid)?)),
            TreeKind::OcTree => "OcTree (.olm, memory-mapped)",
            TreeKind::ColorOcTree => "ColorOcTree (.olm, memory-mapped)",
            TreeKind::OcTreeStamped => "OcTreeStamped (.olm, memory-mapped)",
        };
        let tree = view.to_tree().with_context(invalid)?;
        return Ok(AnyMap::Occupancy(LoadedMap { tree, kind }));
    }
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let r = BufReader::with_capacity(1 << 16, file);
    Ok(match format {
        MapFormat::Bt => AnyMap::Occupancy(LoadedMap {
            tree: bt::read(r).with_context(|| format!("{}: not a valid .bt map", path.display()))?,
            kind: "OcTree (.bt, maximum likelihood)",
        }),
        MapFormat::Olm => unreachable!("handled above"),
        MapFormat::Ot => {
            let t = ot::read(r).with_context(|| format!("{}: not a valid .ot map", path.display()))?;
            let kind = t.kind().id();
            match t {
                ot::AnyTree::Occupancy(tree) => AnyMap::Occupancy(LoadedMap { kind, tree }),
                ot::AnyTree::Counting(t) => AnyMap::Counting(t),
            }
        }
    })
}

/// Memory-maps an `.olm` map and checks its header (O(1); the nodes are
/// checked by [`verify_olm`] or by the conversion to a tree).
pub fn open_olm(path: &Path) -> Result<MappedMap<memmap2::Mmap>> {
    match octolinear::mapped::open(path) {
        Err(octolinear::mapped::OlmError::Io(e)) => Err(e).with_context(|| format!("cannot open {}", path.display())),
        opened => opened.with_context(|| format!("{}: not a valid .olm map", path.display())),
    }
}

/// Checks every byte of a mapped `.olm` map (checksums and structure,
/// O(file size)), so that no answer comes from damaged bytes.
pub fn verify_olm(path: &Path, map: &MappedMap<memmap2::Mmap>) -> Result<VerifyReport> {
    map.verify().with_context(|| format!("{}: not a valid .olm map", path.display()))
}

/// Writes a map by extension, atomically.
pub fn save_map(tree: &OccupancyTree, path: &Path) -> Result<()> {
    let format = MapFormat::from_path(path)?;
    if format == MapFormat::Olm {
        return octolinear::mapped::write_file(tree, path).with_context(|| format!("cannot write {}", path.display()));
    }
    write_atomically(path, |w| match format {
        MapFormat::Bt => bt::write(tree, w),
        MapFormat::Ot => ot::write(tree, w),
        MapFormat::Olm => unreachable!("handled above"),
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes a counting tree as `.ot` or `.olm`, atomically (`.bt` has no
/// counting form).
pub fn save_counting(tree: &CountingTree, path: &Path) -> Result<()> {
    let written = match MapFormat::from_path(path)? {
        MapFormat::Bt => bail!("{}: a counting tree has no .bt form (write .ot or .olm)", path.display()),
        MapFormat::Ot => write_atomically(path, |w| ot::write_counting(tree, w)),
        MapFormat::Olm => {
            octolinear::mapped::write_counting_file(tree, path, octolinear::mapped::WriteOptions::default())
        }
    };
    written.with_context(|| format!("cannot write {}", path.display()))
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

/// A spinner naming the phase under way (change it with `set_message`)
/// and the time since it appeared, on a terminal; hidden otherwise, so
/// that piped runs stay quiet. Dropped (on an error too), it clears its line.
pub fn spinner(what: &str) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner().with_finish(indicatif::ProgressFinish::AndClear);
    bar.set_style(indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})").expect("valid template"));
    bar.set_message(what.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(100));
    bar
}

/// Three finite numbers from a clap `num_args = 3` flag, as a float point.
pub fn point_arg(v: &[f64], flag: &str) -> Result<octolinear::Point3> {
    if v.len() != 3 || v.iter().any(|c| !c.is_finite()) {
        bail!("{flag} needs three finite numbers, got {v:?}");
    }
    Ok(octolinear::Point3::new(v[0] as f32, v[1] as f32, v[2] as f32))
}

/// Checks a `--depth` value: 1 (the root's children) to 16 (voxels).
pub fn depth_arg(d: u8) -> Result<u8> {
    if !(1..=16).contains(&d) {
        bail!("--depth must be between 1 and 16, got {d}");
    }
    Ok(d)
}

/// Writes a file atomically through `write`, with the path in the error.
pub fn write_output(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<&File>) -> std::io::Result<()>,
) -> Result<()> {
    write_atomically(path, write).with_context(|| format!("cannot write {}", path.display()))
}

/// The lower-case extension of a path, or an error naming the choices.
pub fn extension(path: &Path, choices: &[&str]) -> Result<String> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if choices.contains(&ext.as_str()) {
        Ok(ext)
    } else {
        let list: Vec<String> = choices.iter().map(|c| format!(".{c}")).collect();
        bail!("{}: unknown format (expected {})", path.display(), list.join(", "))
    }
}

/// A number for people: the shortest decimal that reads back as the same
/// `f32` (with an exponent only for extreme magnitudes). Map coordinates
/// are `f32` (OctoMap's `point3d`), so digits past that precision in a
/// bound, size, resolution or volume computed in `f64` are noise
/// (`-6.6000000000000005` prints as `-6.6`). Every human-readable output
/// of map numbers goes through here; `--json` keeps full `f64` precision.
pub fn human_number(v: f64) -> String {
    xyz::format_f32(v as f32)
}

/// C++ `std::ostream << double` with the default precision 6 (`%g`).
pub fn format_g6(v: f64) -> String {
    if v == 0.0 {
        return if v.is_sign_negative() { "-0" } else { "0" }.to_string();
    }
    if !v.is_finite() {
        return if v.is_nan() {
            "nan".into()
        } else if v > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        };
    }
    let sci = format!("{v:.5e}");
    let (mantissa, exp) = sci.split_once('e').expect("exponent");
    let exp: i32 = exp.parse().expect("exponent is a number");
    let trim = |s: String| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    if !(-4..6).contains(&exp) {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim(mantissa.to_string()), exp.abs())
    } else {
        let decimals = (5 - exp).max(0) as usize;
        trim(format!("{v:.decimals$}"))
    }
}

/// Turns `SIGBUS` from a read of a mapped file truncated in place (by
/// another process; the writers here rename a new file over the old one,
/// which is safe) into the tool's error line naming the file and exit code
/// 1, where it would otherwise kill the process without a word. The mapped
/// files are `.olm` maps and `.graph` inputs; the library registers each
/// mapping, so the line names the file the faulting read was in. Installed
/// once, at start.
pub fn report_truncated_files() {
    // without it a truncated file still ends the run, by the signal
    let _ = octolinear::mapped::exit_on_truncated_files("octolinear: error: ");
}
