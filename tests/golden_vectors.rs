//! The golden vectors the tests compare against are OctoMap's recorded data,
//! whole and unchanged: every input and every stored output file has the size
//! and sha256 that the recording harness wrote into `manifest.json`, and the
//! directory holds nothing the manifest does not list.

mod common;
use common::*;
use std::collections::BTreeSet;
use std::path::Path;

#[test]
fn every_golden_file_has_its_manifest_digest() {
    let g = golden();
    let mut listed: BTreeSet<String> = ["README.md", "manifest.json"].map(String::from).into();
    let mut f = Failures::default();
    let mut check = |entry: &serde_json::Value| {
        let rel = entry["path"].as_str().expect("a stored file has a path");
        let (sha256, bytes) = (entry["sha256"].as_str().unwrap(), entry["bytes"].as_u64().unwrap());
        listed.insert(rel.to_string());
        let path = g.root.join(rel);
        if !path.is_file() {
            f.0.push(format!("{rel}: missing"));
            return;
        }
        // digest and size are those of the decompressed bytes for `.gz` files
        let data = read_maybe_gz(&path);
        let digest = sha256_hex(&data);
        f.check(digest == sha256 && data.len() as u64 == bytes, || {
            format!("{rel}: {} bytes, sha256 {digest}; the manifest says {bytes} bytes, sha256 {sha256}", data.len())
        });
    };
    for input in g.manifest["inputs"].as_array().unwrap() {
        check(input);
    }
    for case in g.manifest["cases"].as_array().unwrap() {
        for file in case["files"].as_array().unwrap() {
            if matches!(file["stored"].as_str(), Some("plain" | "gzip")) {
                check(file);
            }
        }
    }
    let mut present = Vec::new();
    files_under(&g.root, &g.root, &mut present);
    for rel in &present {
        f.check(listed.contains(rel), || format!("{rel}: not in the manifest"));
    }
    assert!(present.len() > 700, "only {} files in {}", present.len(), g.root.display());
    f.finish("golden vectors");
}

/// Every file below `dir`, as a `/`-separated path relative to `root`.
fn files_under(root: &Path, dir: &Path, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files_under(root, &path, out);
        } else {
            let rel = path.strip_prefix(root).unwrap().components();
            out.push(rel.map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
        }
    }
}
