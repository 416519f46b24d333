//! Writes the occupied voxels of a map, each with its centre, edge length
//! and probability of occupancy, to a CSV or PLY file for other tools
//! (a spreadsheet, numpy, CloudCompare, MeshLab).
//!
//! ```sh
//! cargo run --release --example export_voxels -- [MAP.bt|MAP.ot|MAP.olm [OUT.csv|OUT.ply]]
//! ```
//!
//! Without arguments it reads the bundled `samples/indoor.bt` and writes
//! `occupied.csv`.
//!
//! A map merges eight children that agree into their parent ("pruning"),
//! so a leaf is a voxel of the map's resolution or a cube 2, 4, 8, ...
//! times as wide; each leaf is one row, with its own edge length. The CSV
//! file has the header `x,y,z,size,probability`; the PLY file is ASCII,
//! with the float properties `x`, `y`, `z`, `size` and `probability` per
//! vertex (every PLY reader gets the points from it, and CloudCompare shows
//! the other two as scalar fields).

use octolinear::formats::{read_map_file, write_atomically, xyz::format_f32};
use octolinear::sensor::probability;
use std::io::Write;
use std::path::Path;

type Error = Box<dyn std::error::Error>;

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (input, output) = match &args[..] {
        [] => (concat!(env!("CARGO_MANIFEST_DIR"), "/samples/indoor.bt"), "occupied.csv"),
        [map] => (map.as_str(), "occupied.csv"),
        [map, out] => (map.as_str(), out.as_str()),
        _ => return Err("usage: export_voxels [MAP.bt|MAP.ot|MAP.olm [OUT.csv|OUT.ply]]".into()),
    };
    let ply = match Path::new(output).extension().and_then(|e| e.to_str()) {
        Some("csv") => false,
        Some("ply") => true,
        _ => return Err(format!("{output}: the output's name must end in .csv or .ply").into()),
    };
    let tree = read_map_file(input).map_err(|e| e.to_string())?;

    // every leaf (depth 0: down to the finest level) that is occupied: its
    // log-odds value is above the sensor model's occupancy threshold
    let occupied: Vec<_> = tree.leaves(0).filter(|leaf| tree.is_occupied(leaf.value)).collect();

    // written into a temporary file renamed into place once complete: an
    // error leaves no half-written file
    write_atomically(Path::new(output), |w| {
        if ply {
            write!(
                w,
                "ply\nformat ascii 1.0\ncomment occupied voxels of an occupancy map\nelement vertex {}\n\
                 property float x\nproperty float y\nproperty float z\n\
                 property float size\nproperty float probability\nend_header\n",
                occupied.len()
            )?;
        } else {
            writeln!(w, "x,y,z,size,probability")?;
        }
        let separator = if ply { " " } else { "," };
        for leaf in &occupied {
            let centre = leaf.center_point();
            // each float in the shortest form that reads back to the same bits
            let row = [centre.x, centre.y, centre.z, leaf.size() as f32, probability(f64::from(leaf.value)) as f32]
                .map(format_f32)
                .join(separator);
            writeln!(w, "{row}")?;
        }
        Ok(())
    })
    .map_err(|e| format!("{output}: {e}"))?;
    println!("{} occupied voxels of {input} written to {output}", occupied.len());
    Ok(())
}
