//! Reading an occupancy map whatever its format, chosen by the file's
//! extension: what a program that only consumes maps (a planner, an
//! exporter) needs, without a match over the formats of its own.

use super::{bt, ot, TreeFileError};
use crate::{mapped, OccupancyTree, OlmError};
use std::path::{Path, PathBuf};

/// Why [`read_map_file`] could not read a map; each variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MapFileError {
    /// The extension is none of `.bt`, `.ot` and `.olm`.
    #[error("{}: the map's name must end in .bt, .ot or .olm", .0.display())]
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

/// Reads an occupancy map into memory by its extension (case-insensitive):
/// `.bt` ([`bt::read_file`]), `.ot` ([`ot::read_file`]) or `.olm`
/// ([`mapped::read_file`], checked whole before it is converted).
pub fn read_map_file(path: impl AsRef<Path>) -> Result<OccupancyTree, MapFileError> {
    let path = path.as_ref();
    let tree_error = |source| MapFileError::Tree { path: path.to_path_buf(), source };
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("bt") => bt::read_file(path).map_err(tree_error),
        Some("ot") => {
            ot::read_file(path).map_err(tree_error)?.into_occupancy().ok_or(MapFileError::Counting(path.to_path_buf()))
        }
        Some("olm") => mapped::read_file(path).map_err(|source| MapFileError::Olm { path: path.to_path_buf(), source }),
        _ => Err(MapFileError::UnknownFormat(path.to_path_buf())),
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
        let txt = dir.path().join("m.txt");
        let err = read_map_file(&txt).unwrap_err().to_string();
        assert!(err.contains("m.txt") && err.contains(".bt, .ot or .olm"), "{err}");
        let missing = dir.path().join("none.bt");
        assert!(read_map_file(&missing).unwrap_err().to_string().starts_with(&missing.display().to_string()));
    }
}
