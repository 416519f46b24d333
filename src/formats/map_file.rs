//! A map file's format ([`MapFormat`]), by its name or its first bytes,
//! and reading an occupancy map whatever its format: what a program that
//! only consumes maps (a planner, an exporter) needs, without a match over
//! the formats of its own. Every front end names formats through these.

use super::header::{BT_FIRST_LINE, OT_FIRST_LINE};
use super::{bt, ot, TreeFileError};
use crate::{mapped, OccupancyTree, OlmError};
use std::path::{Path, PathBuf};

/// Why [`read_map_file`] could not read a map; each variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MapFileError {
    /// The extension is none of `.bt`, `.ot` and `.olm`.
    #[error("{}: unknown map format: the name must end in .bt, .ot or .olm", .0.display())]
    UnknownFormat(PathBuf),
    /// The `.bt` or `.ot` file is unreadable or malformed.
    #[error("{}: {source}", .path.display())]
    Tree {
        /// The map file.
        path: PathBuf,
        /// What the reader found.
        source: TreeFileError,
    },
    /// The `.olm` file is unreadable, malformed or damaged.
    #[error("{}: {source}", .path.display())]
    Olm {
        /// The map file.
        path: PathBuf,
        /// What the reader found.
        source: OlmError,
    },
    /// The `.ot` file holds a counting tree (hit counts), not occupancy.
    #[error("{}: the map holds hit counts, not occupancy", .0.display())]
    Counting(PathBuf),
}

/// The formats of a map file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MapFormat {
    /// OctoMap's `.bt`: maximum-likelihood occupancy bits.
    Bt,
    /// OctoMap's `.ot`: the full tree of any kind.
    Ot,
    /// octolinear's memory-mapped `.olm`.
    Olm,
}

impl MapFormat {
    /// The format the extension of `path` names (case-insensitive), if any.
    pub fn from_extension(path: &Path) -> Option<MapFormat> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "bt" => Some(MapFormat::Bt),
            "ot" => Some(MapFormat::Ot),
            "olm" => Some(MapFormat::Olm),
            _ => None,
        }
    }

    /// The format the extension of `path` names, or
    /// [`MapFileError::UnknownFormat`].
    pub fn from_path(path: &Path) -> Result<MapFormat, MapFileError> {
        Self::from_extension(path).ok_or_else(|| MapFileError::UnknownFormat(path.to_path_buf()))
    }

    /// The bytes every file of the format begins with: OctoMap's first
    /// header line (without its newline) or the `.olm` magic.
    pub fn signature(self) -> &'static [u8] {
        match self {
            MapFormat::Bt => BT_FIRST_LINE.as_bytes(),
            MapFormat::Ot => OT_FIRST_LINE.as_bytes(),
            MapFormat::Olm => &mapped::format::MAGIC,
        }
    }

    /// The format whose [signature](Self::signature) a file's first bytes
    /// (32 suffice) begin with, if any.
    pub fn sniff(head: &[u8]) -> Option<MapFormat> {
        [MapFormat::Bt, MapFormat::Ot, MapFormat::Olm].into_iter().find(|f| head.starts_with(f.signature()))
    }

    /// The extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            MapFormat::Bt => "bt",
            MapFormat::Ot => "ot",
            MapFormat::Olm => "olm",
        }
    }
}

/// Reads an occupancy map into memory by its extension (case-insensitive):
/// `.bt` ([`bt::read_file`]), `.ot` ([`ot::read_file`]) or `.olm`
/// ([`mapped::read_file`], checked whole before it is converted).
pub fn read_map_file(path: impl AsRef<Path>) -> Result<OccupancyTree, MapFileError> {
    let path = path.as_ref();
    let tree_error = |source| MapFileError::Tree { path: path.to_path_buf(), source };
    match MapFormat::from_path(path)? {
        MapFormat::Bt => bt::read_file(path).map_err(tree_error),
        MapFormat::Ot => {
            ot::read_file(path).map_err(tree_error)?.into_occupancy().ok_or(MapFileError::Counting(path.to_path_buf()))
        }
        MapFormat::Olm => {
            mapped::read_file(path).map_err(|source| MapFileError::Olm { path: path.to_path_buf(), source })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_format_reads_to_the_same_map_and_bad_names_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/indoor.bt");
        let tree = read_map_file(&sample).unwrap();
        let ot_bytes = |t: &OccupancyTree| {
            let mut out = Vec::new();
            ot::write(t, &mut out).unwrap();
            out
        };
        let (ot_path, olm_path) = (dir.path().join("m.OT"), dir.path().join("m.olm"));
        ot::write_file(&tree, &ot_path).unwrap();
        mapped::write_file(&tree, &olm_path).unwrap();
        for path in [&ot_path, &olm_path] {
            assert!(ot_bytes(&read_map_file(path).unwrap()) == ot_bytes(&tree), "{}", path.display());
        }
        for (path, format) in [(&sample, MapFormat::Bt), (&ot_path, MapFormat::Ot), (&olm_path, MapFormat::Olm)] {
            assert_eq!(MapFormat::from_path(path).unwrap(), format);
            let head = std::fs::read(path).unwrap();
            assert_eq!(MapFormat::sniff(&head[..32]), Some(format), "{}", path.display());
            assert_eq!(MapFormat::from_extension(Path::new(&format!("x.{}", format.extension()))), Some(format));
        }
        assert_eq!(MapFormat::sniff(b"ply\n"), None);
        let txt = dir.path().join("m.txt");
        let err = read_map_file(&txt).unwrap_err().to_string();
        assert!(err.contains("m.txt: unknown map format") && err.contains(".bt, .ot or .olm"), "{err}");
        let missing = dir.path().join("none.bt");
        assert!(read_map_file(&missing).unwrap_err().to_string().starts_with(&missing.display().to_string()));
    }
}
