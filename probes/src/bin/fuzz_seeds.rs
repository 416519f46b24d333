//! Seed corpora for the fuzz targets: `cargo run --release -p
//! octolinear-probes --bin fuzz_seeds -- [GOLDEN_DIR]` writes
//! `fuzz/corpus/<target>/` seeds. The small golden `.ot`, `.bt` and
//! `.graph` files (default `tests/golden`)
//! are copied, and the small `.ot` files also converted to `.olm` (full,
//! maximum likelihood, pointer index, with the search-blocks section). Small PLY (ascii, binary of both byte orders), PCD
//! (ascii, binary, compressed) and binvox files are made here. The corpus
//! directory is not committed; `docs/architecture.md` lists the campaign that
//! used these seeds.

use octolinear::formats::{ot, ply};
use octolinear::{mapped, Point3};
use std::path::{Path, PathBuf};

/// Golden files smaller than this are copied (libFuzzer's inputs stay small).
const MAX_SEED: u64 = 20_000;

fn main() {
    let golden = std::env::args()
        .nth(1)
        .map_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/golden"), PathBuf::from);
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus");
    let write = |target: &str, name: &str, bytes: &[u8]| {
        let dir = corpus.join(target);
        std::fs::create_dir_all(&dir).expect("corpus directory");
        std::fs::write(dir.join(name), bytes).expect("seed written");
    };
    let mut golden_files = Vec::new();
    collect(&golden, &mut golden_files);
    golden_files.sort();
    for path in golden_files {
        let Some(ext) = path.extension().and_then(|e| e.to_str()) else { continue };
        if !matches!(ext, "ot" | "bt" | "graph") || path.metadata().map_or(true, |m| m.len() > MAX_SEED) {
            continue;
        }
        let bytes = std::fs::read(&path).expect("golden file");
        let name = path.strip_prefix(&golden).unwrap_or(&path).to_string_lossy().replace('/', "_");
        write(ext, &name, &bytes);
        if ext == "ot" {
            if let Ok(ot::AnyTree::Occupancy(tree)) = ot::read(&bytes[..]) {
                let layouts = [
                    ("full", mapped::WriteOptions::default()),
                    ("ml", mapped::WriteOptions::max_likelihood()),
                    ("pointers", mapped::WriteOptions { index: mapped::Index::Pointers, ..Default::default() }),
                    (
                        "blocks",
                        mapped::WriteOptions {
                            search_blocks: mapped::SearchBlocksSection::Always,
                            ..Default::default()
                        },
                    ),
                ];
                for (suffix, opts) in layouts {
                    if let Ok(olm) = mapped::to_bytes(&tree, opts) {
                        write("olm", &format!("{name}.{suffix}.olm"), &olm);
                    }
                }
            }
        }
    }
    let points = [Point3::new(0.05, 0.05, 0.05), Point3::new(1.0, -0.3, 0.2), Point3::new(-2.0, 0.4, -0.1)];
    for ascii in [false, true] {
        let mut out = Vec::new();
        ply::write(&points, ascii, &mut out).expect("in memory");
        write("ply", if ascii { "ascii.ply" } else { "binary.ply" }, &out);
    }
    let mut big_endian = b"ply\nformat binary_big_endian 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
        element vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n\
        property uchar green\nproperty uchar blue\nend_header\n\x03"
        .to_vec();
    (0..3i32).for_each(|i| big_endian.extend_from_slice(&i.to_be_bytes()));
    for p in &points {
        p.to_array().iter().for_each(|c| big_endian.extend_from_slice(&c.to_be_bytes()));
        big_endian.extend_from_slice(&[200, 7, 9]);
    }
    write("ply", "big_endian_colored.ply", &big_endian);
    let head = |kind: &str| {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n\
             WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA {kind}\n"
        )
        .into_bytes()
    };
    let rgb = |i: usize| 0x0010_2030u32 + i as u32;
    let mut ascii = head("ascii");
    let mut binary = head("binary");
    let mut fields: [Vec<u8>; 4] = Default::default();
    for (i, p) in points.iter().enumerate() {
        ascii.extend_from_slice(format!("{} {} {} {}\n", p.x, p.y, p.z, rgb(i)).as_bytes());
        let values = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), rgb(i)];
        for (f, v) in values.iter().enumerate() {
            binary.extend_from_slice(&v.to_le_bytes());
            fields[f].extend_from_slice(&v.to_le_bytes());
        }
    }
    // binary_compressed: the fields one after the other, as LZF literal runs
    let raw = fields.concat();
    let mut lzf = Vec::new();
    for run in raw.chunks(32) {
        lzf.push(run.len() as u8 - 1);
        lzf.extend_from_slice(run);
    }
    let mut compressed = head("binary_compressed");
    compressed.extend_from_slice(&(lzf.len() as u32).to_le_bytes());
    compressed.extend_from_slice(&(raw.len() as u32).to_le_bytes());
    compressed.extend_from_slice(&lzf);
    write("pcd", "ascii.pcd", &ascii);
    write("pcd", "binary.pcd", &binary);
    write("pcd", "compressed.pcd", &compressed);
    let mut grid = b"#binvox 1\ndim 6 5 4\ntranslate -0.5 0.25 1\nscale 1.5\ndata\n".to_vec();
    grid.extend_from_slice(&[0, 17, 1, 40, 0, 3, 1, 60]);
    write("binvox", "grid.binvox", &grid);
    println!("seeds written to {}", corpus.display());
}

fn collect(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            collect(&p, out);
        } else {
            out.push(p);
        }
    }
}
