//! Fuzz target: the `.graph` reader (`cargo +nightly fuzz run graph`).
//!
//! [`check`] must never panic. The streaming reader and the in-memory one
//! (which checks counts against the length) agree on success, and a graph
//! read writes to bytes that read back and rewrite identically. Built
//! without cargo-fuzz this replays the files named on its command line;
//! `tests/corruption.rs` compiles it as a module.
#![cfg_attr(fuzzing, no_main)]

use octolinear::formats::graph;

#[cfg(fuzzing)]
libfuzzer_sys::fuzz_target!(|data: &[u8]| check(data));

#[cfg(not(fuzzing))]
#[allow(dead_code)]
fn main() {
    for path in std::env::args_os().skip(1) {
        check(&std::fs::read(&path).expect("readable input"));
    }
}

fn write(g: &graph::ScanGraph) -> Vec<u8> {
    let mut out = Vec::new();
    graph::write(g, &mut out).expect("writing to memory");
    out
}

pub fn check(data: &[u8]) {
    let in_memory = graph::read_bytes(data);
    let streamed = graph::read(data);
    let g = match (in_memory, streamed) {
        (Ok(a), Ok(b)) => {
            let once = write(&a);
            assert_eq!(once, write(&b), "streaming and in-memory readers disagree");
            a
        }
        (Err(_), Err(_)) => return,
        (a, b) => panic!("one reader failed: in memory {:?}, streamed {:?}", a.err(), b.err()),
    };
    let once = write(&g);
    let back = graph::read_bytes(&once).expect("a written graph reads back");
    assert_eq!(write(&back), once);
    for node in &g.nodes {
        let _ = node.graph2tree();
    }
}
