//! `octolinear mesh`: occupied voxels as cubes in a PLY mesh.

use super::common::{depth_arg, extension, load_map, write_output};
use super::render::height_colour;
use anyhow::{Context, Result};
use octolinear::{OccupancyTree, Point3};
use std::io::Write;
use std::path::PathBuf;

/// Export the occupied voxels as a mesh of cubes (PLY).
///
/// Quad faces with per-vertex colours by height, for MeshLab, Blender and
/// the like. Faces
/// shared with an occupied neighbour of at least the same size are left
/// out unless --all-faces.
///
/// Example: octolinear mesh map.bt -o map.ply --depth 15
#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    map: PathBuf,
    /// Output mesh (.ply).
    #[arg(short, long)]
    output: PathBuf,
    /// Cubes of this depth (1 to 16: 16 = full resolution, lower = coarser).
    #[arg(long, default_value_t = 16)]
    depth: u8,
    /// Text PLY instead of binary little endian.
    #[arg(long)]
    ascii: bool,
    /// Keep faces hidden between two occupied voxels.
    #[arg(long)]
    all_faces: bool,
}

/// Corner indices (bit 0 = +x, 1 = +y, 2 = +z) of each face, wound
/// counter-clockwise seen from outside, with the face's outward axis.
const FACES: [([usize; 4], usize, f32); 6] = [
    ([0, 4, 6, 2], 0, -1.0),
    ([1, 3, 7, 5], 0, 1.0),
    ([0, 1, 5, 4], 1, -1.0),
    ([2, 6, 7, 3], 1, 1.0),
    ([0, 2, 3, 1], 2, -1.0),
    ([4, 5, 7, 6], 2, 1.0),
];

/// A mesh of cubes: 8 vertices each, quads indexing them.
#[derive(Default)]
pub struct CubeMesh {
    pub vertices: Vec<(Point3, [u8; 3])>,
    pub faces: Vec<[u32; 4]>,
}

pub fn cubes(tree: &OccupancyTree, depth: u8, all_faces: bool) -> CubeMesh {
    let sensor = *tree.sensor();
    let occupied: Vec<_> = tree.leaves(depth).filter(|l| sensor.is_occupied(l.value)).collect();
    let (zlo, zhi) = occupied.iter().fold((f64::MAX, f64::MIN), |(lo, hi), l| {
        let (z, h) = (l.center()[2], l.size() / 2.0);
        (lo.min(z - h), hi.max(z + h))
    });
    let mut m = CubeMesh::default();
    for leaf in &occupied {
        let c = leaf.center_point();
        let size = leaf.size() as f32;
        let visible: Vec<_> = FACES
            .iter()
            .filter(|(_, axis, sign)| {
                if all_faces {
                    return true;
                }
                let mut n = c.to_array();
                n[*axis] += sign * size;
                !matches!(
                    tree.search_point(Point3::from_array(n), depth),
                    Ok(Some(f)) if sensor.is_occupied(f.value) && f.depth <= leaf.depth
                )
            })
            .collect();
        if visible.is_empty() {
            continue;
        }
        let base = m.vertices.len() as u32;
        let colour = height_colour((leaf.center()[2] - zlo) / (zhi - zlo)).map(|v| v.round() as u8);
        let h = size / 2.0;
        for corner in 0..8 {
            let o = [0, 1, 2].map(|i| if corner & (1 << i) != 0 { h } else { -h });
            m.vertices.push((c + Point3::from_array(o), colour));
        }
        for (idx, _, _) in visible {
            m.faces.push(idx.map(|i| base + i as u32));
        }
    }
    m
}

pub fn run(a: Args) -> Result<()> {
    extension(&a.output, &["ply"])?;
    let depth = depth_arg(a.depth)?;
    let tree = load_map(&a.map)?.tree;
    let m = cubes(&tree, depth, a.all_faces);
    if m.vertices.is_empty() {
        eprintln!("note: the map has no occupied voxels; writing an empty mesh");
    }
    u32::try_from(m.vertices.len()).ok().context("too many vertices for PLY")?;
    write_output(&a.output, |w| write_ply(&m, a.ascii, w))?;
    eprintln!("wrote {} vertices, {} faces to {}", m.vertices.len(), m.faces.len(), a.output.display());
    Ok(())
}

fn write_ply(m: &CubeMesh, ascii: bool, mut w: impl Write) -> std::io::Result<()> {
    let format = if ascii { "ascii" } else { "binary_little_endian" };
    write!(
        w,
        "ply\nformat {format} 1.0\ncomment written by octolinear\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.vertices.len(),
        m.faces.len()
    )?;
    for (p, c) in &m.vertices {
        if ascii {
            use octolinear::formats::xyz::format_f32 as f;
            writeln!(w, "{} {} {} {} {} {}", f(p.x), f(p.y), f(p.z), c[0], c[1], c[2])?;
        } else {
            for v in p.to_array() {
                w.write_all(&v.to_le_bytes())?;
            }
            w.write_all(c)?;
        }
    }
    for f in &m.faces {
        if ascii {
            writeln!(w, "4 {} {} {} {}", f[0], f[1], f[2], f[3])?;
        } else {
            w.write_all(&[4])?;
            for i in f {
                w.write_all(&(*i as i32).to_le_bytes())?;
            }
        }
    }
    Ok(())
}
