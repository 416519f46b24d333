//! Map hierarchies: OctoMap's `MapCollection` of submaps, each a tree with
//! a 6-DoF pose, queried together (paper Sect. 3.5.2).
//!
//! The collection file is text: per submap three lines `MAPNODEID id`,
//! `MAPNODEFILENAME file.bt` (relative to the collection file) and
//! `MAPNODEPOSE x y z roll pitch yaw`; empty lines and lines starting with
//! `#` are skipped. Submaps are `.bt` files, as OctoMap's `MapNode` reads them.

use crate::formats::{bt, format_double, write_atomically, TreeFileError};
use crate::geometry::{Point3, Pose6D};
use crate::ray::{CastOptions, CastOutcome};
use crate::tree::OccupancyTree;
use std::io::{self, BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

/// One submap and where it sits in the collection's frame.
#[derive(Clone, Debug)]
pub struct MapNode {
    /// The submap's identifier (`MAPNODEID`).
    pub id: String,
    /// Submap frame in the collection frame.
    pub pose: Pose6D,
    /// The submap's tree.
    pub map: OccupancyTree,
}

/// A set of posed submaps.
#[derive(Clone, Debug, Default)]
pub struct MapCollection {
    /// The submaps, in file order.
    pub nodes: Vec<MapNode>,
}

/// Why a collection could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CollectionError {
    /// A file could not be opened, read or written.
    #[error("I/O error on {path}")]
    Io {
        /// The collection file or submap file concerned.
        path: PathBuf,
        /// The underlying I/O error.
        source: io::Error,
    },
    /// The collection file is malformed.
    #[error("{path} line {line}: {reason}")]
    Syntax {
        /// The collection file.
        path: PathBuf,
        /// 1-based line number; 0 when a submap's entry ends with the file.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A submap's `.bt` file could not be decoded.
    #[error("submap {path} refused")]
    Submap {
        /// The submap file.
        path: PathBuf,
        /// Why it was refused.
        source: TreeFileError,
    },
    /// No submap has the given id.
    #[error("no submap with id `{0}`")]
    UnknownId(String),
}

/// OctoMap's `readTagValue`: the next line that is neither empty nor a
/// comment, and what follows its first space.
fn next_value(
    lines: &mut impl Iterator<Item = (usize, io::Result<String>)>,
    path: &Path,
) -> Result<Option<(usize, String)>, CollectionError> {
    for (n, line) in lines {
        let line = line.map_err(|source| CollectionError::Io { path: path.into(), source })?;
        let line = line.trim_end_matches('\r');
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        return match line.split_once(' ') {
            Some((_, v)) if !v.is_empty() => Ok(Some((n + 1, v.to_string()))),
            _ => Err(CollectionError::Syntax {
                path: path.into(),
                line: n + 1,
                reason: format!("`{line}` has no value"),
            }),
        };
    }
    Ok(None)
}

impl MapCollection {
    /// Reads a collection file and the `.bt` submaps it names.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, CollectionError> {
        let path = path.as_ref();
        let file = std::fs::File::open(path).map_err(|source| CollectionError::Io { path: path.into(), source })?;
        let dir = path.parent().unwrap_or(Path::new(""));
        let mut lines = BufReader::new(file).lines().enumerate();
        let mut nodes = Vec::new();
        while let Some((_, id)) = next_value(&mut lines, path)? {
            let missing = |what: &str| CollectionError::Syntax {
                path: path.into(),
                line: 0,
                reason: format!("submap `{id}` has no {what} line"),
            };
            let (_, file) = next_value(&mut lines, path)?.ok_or_else(|| missing("MAPNODEFILENAME"))?;
            let (line, pose) = next_value(&mut lines, path)?.ok_or_else(|| missing("MAPNODEPOSE"))?;
            let v: Vec<f64> = pose.split_whitespace().map_while(|t| t.parse().ok()).collect();
            if v.len() < 6 {
                let reason = format!("pose `{pose}` needs x y z roll pitch yaw");
                return Err(CollectionError::Syntax { path: path.into(), line, reason });
            }
            let pose = Pose6D::from_euler(v[0] as f32, v[1] as f32, v[2] as f32, v[3], v[4], v[5]);
            let map_path = dir.join(&file);
            let map = std::fs::File::open(&map_path)
                .map_err(|source| CollectionError::Io { path: map_path.clone(), source })
                .and_then(|f| {
                    bt::read(BufReader::new(f)).map_err(|source| CollectionError::Submap { path: map_path, source })
                })?;
            nodes.push(MapNode { id, pose, map });
        }
        Ok(MapCollection { nodes })
    }

    /// Writes the collection file and each submap as `nodemap_<id>.bt`
    /// next to it, as OctoMap's `write` names them.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), CollectionError> {
        let path = path.as_ref();
        let dir = path.parent().unwrap_or(Path::new(""));
        fn io_err(p: &Path) -> impl FnOnce(io::Error) -> CollectionError + '_ {
            move |source| CollectionError::Io { path: p.into(), source }
        }
        for n in &self.nodes {
            let map_path = dir.join(format!("nodemap_{}.bt", n.id));
            write_atomically(&map_path, |w| bt::write(&n.map, w)).map_err(io_err(&map_path))?;
        }
        write_atomically(path, |w| {
            w.write_all(b"#This file was generated by the write-method of MapCollection\n")?;
            for n in &self.nodes {
                let t = n.pose.translation;
                let f = |x: f64| format_double(x);
                writeln!(w, "MAPNODEID {}\nMAPNODEFILENAME nodemap_{}.bt", n.id, n.id)?;
                writeln!(
                    w,
                    "MAPNODEPOSE {} {} {} {} {} {}",
                    f(t.x.into()),
                    f(t.y.into()),
                    f(t.z.into()),
                    f(n.pose.roll()),
                    f(n.pose.pitch()),
                    f(n.pose.yaw())
                )?;
            }
            Ok(())
        })
        .map_err(io_err(path))
    }

    /// The submap with the given id, if any (the first one when ids repeat).
    pub fn node(&self, id: &str) -> Option<&MapNode> {
        self.nodes.iter().find(|n| n.id == id)
    }

    /// Moves a submap to a new pose.
    pub fn move_node(&mut self, id: &str, pose: Pose6D) -> Result<(), CollectionError> {
        let n = self.nodes.iter_mut().find(|n| n.id == id).ok_or_else(|| CollectionError::UnknownId(id.into()))?;
        n.pose = pose;
        Ok(())
    }

    /// The first submap in which `p` (collection frame) is occupied (`queryNode`).
    pub fn query_node(&self, p: Point3) -> Option<&MapNode> {
        self.nodes.iter().find(|n| {
            let local = n.pose.inv().transform(p);
            matches!(n.map.search_point(local, 0), Ok(Some(f)) if n.map.is_occupied(f.value))
        })
    }

    /// Is `p` occupied in any submap?
    pub fn is_occupied(&self, p: Point3) -> bool {
        self.query_node(p).is_some()
    }

    /// The highest occupancy probability any submap knows for `p`; 0.5
    /// when no submap knows it (`getOccupancy`).
    pub fn occupancy(&self, p: Point3) -> f64 {
        let mut best: Option<f64> = None;
        for n in &self.nodes {
            let local = n.pose.inv().transform(p);
            if let Ok(Some(f)) = n.map.search_point(local, 0) {
                let occ = crate::sensor::probability(f64::from(f.value));
                best = Some(best.map_or(occ, |b: f64| if occ > b { occ } else { b }));
            }
        }
        match best {
            None => 0.5,
            Some(b) => b.max(0.0),
        }
    }

    /// Casts the ray in every submap and returns the nearest occupied hit
    /// in the collection frame (`castRay`).
    pub fn cast_ray(&self, origin: Point3, direction: Point3, opts: CastOptions) -> Option<Point3> {
        let mut best: Option<(f64, Point3)> = None;
        for n in &self.nodes {
            let inv = n.pose.inv();
            let o = inv.transform(origin);
            let d = inv.rot().rotate(direction);
            if let Ok(CastOutcome::Occupied { end }) = n.map.cast_ray(o, d, opts) {
                let dist = o.distance(end);
                if dist < best.map_or(1e6, |b| b.0) {
                    best = Some((dist, n.pose.transform(end)));
                }
            }
        }
        best.map(|b| b.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::InnerNodes;

    fn wall_map() -> OccupancyTree {
        let mut t = OccupancyTree::new(0.1).unwrap();
        for i in 0..10 {
            for j in 0..10 {
                let p = Point3::new(1.0, -0.5 + 0.1 * i as f32, -0.5 + 0.1 * j as f32);
                t.update_point(p, true, InnerNodes::Update).unwrap();
            }
        }
        t
    }

    #[test]
    fn posed_submaps_answer_in_the_collection_frame() {
        let shifted = Pose6D::from_euler(5.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let mut c = MapCollection {
            nodes: vec![
                MapNode { id: "a".into(), pose: Pose6D::from_euler(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), map: wall_map() },
                MapNode { id: "b".into(), pose: shifted, map: wall_map() },
            ],
        };
        assert!(c.is_occupied(Point3::new(1.05, 0.05, 0.05)));
        assert!(c.is_occupied(Point3::new(6.05, 0.05, 0.05)));
        assert!(!c.is_occupied(Point3::new(3.05, 0.05, 0.05)));
        assert_eq!(c.occupancy(Point3::new(3.05, 0.05, 0.05)), 0.5);
        let hit = c.cast_ray(
            Point3::new(3.0, 0.05, 0.05),
            Point3::new(1.0, 0.0, 0.0),
            CastOptions { ignore_unknown: true, max_range: None },
        );
        assert!((hit.unwrap().x - 6.05).abs() < 1e-4, "{hit:?}");
        c.move_node("b", Pose6D::from_euler(8.0, 0.0, 0.0, 0.0, 0.0, 0.0)).unwrap();
        assert!(c.is_occupied(Point3::new(9.05, 0.05, 0.05)));
        assert!(c.move_node("zz", shifted).is_err());

        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("collection.txt");
        c.write(&file).unwrap();
        let back = MapCollection::read(&file).unwrap();
        assert_eq!(back.nodes.len(), 2);
        assert_eq!(back.node("b").unwrap().pose.translation.x, 8.0);
        assert!(back.is_occupied(Point3::new(9.05, 0.05, 0.05)));
        let text = std::fs::read_to_string(&file).unwrap();
        assert!(text.contains("MAPNODEFILENAME nodemap_b.bt\nMAPNODEPOSE 8 0 0 "), "{text}");
    }
}
