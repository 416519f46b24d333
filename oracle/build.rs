//! Build script of the OctoMap oracle.
//!
//! Probes for the system OctoMap library (pkg-config `octomap`, falling back to
//! well-known header/library locations). When it is found, the C++ shim in
//! `shim/octomap_shim.cpp` is compiled with `cc`, a tiny program is linked
//! against it as a final check, and `cfg(octomap_available)` is set. When it
//! is not found (or `OCTOLINEAR_ORACLE_DISABLE=1`, which shows what a
//! machine without OctoMap does), nothing is compiled, a single
//! `cargo:warning` is printed and the crate builds as a stub.

use std::env;
use std::path::PathBuf;
use std::process::Command;

const SHIM: &str = "shim/octomap_shim.cpp";

struct Found {
    include_dirs: Vec<PathBuf>,
    lib_dirs: Vec<PathBuf>,
    version: String,
    how: &'static str,
}

fn main() {
    println!("cargo::rustc-check-cfg=cfg(octomap_available)");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-changed={SHIM}");
    for var in ["OCTOLINEAR_ORACLE_DISABLE", "PKG_CONFIG_PATH", "OCTOMAP_DIR"] {
        println!("cargo::rerun-if-env-changed={var}");
    }

    if env::var("OCTOLINEAR_ORACLE_DISABLE").is_ok_and(|v| v == "1" || v == "true") {
        unavailable("disabled by OCTOLINEAR_ORACLE_DISABLE");
        return;
    }
    let Some(found) = probe_pkg_config().or_else(probe_paths) else {
        unavailable("liboctomap not found (no pkg-config `octomap`, no octomap/octomap.h + liboctomap.so)");
        return;
    };
    match build_shim(&found) {
        Ok(()) => {
            println!("cargo::rustc-cfg=octomap_available");
            println!("cargo::rustc-env=OCTOLINEAR_ORACLE_OCTOMAP_VERSION={}", found.version);
            println!("cargo::rustc-env=OCTOLINEAR_ORACLE_PROBE={}", found.how);
        }
        Err(e) => unavailable(&format!("OctoMap found via {} but the shim did not build/link: {e}", found.how)),
    }
}

fn unavailable(why: &str) {
    println!(
        "cargo::warning=octolinear-oracle: OctoMap oracle disabled ({why}); \
         the tests that compare against it are skipped, or fail where CI=true. \
         Install with: apt-get install -y liboctomap-dev"
    );
}

fn probe_pkg_config() -> Option<Found> {
    let run = |args: &[&str]| -> Option<String> {
        let out = Command::new("pkg-config").args(args).output().ok()?;
        out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
    };
    let version = run(&["--modversion", "octomap"])?;
    let cflags = run(&["--cflags", "octomap"])?;
    let libs = run(&["--libs-only-L", "octomap"])?;
    let mut include_dirs: Vec<PathBuf> =
        cflags.split_whitespace().filter_map(|f| f.strip_prefix("-I")).map(PathBuf::from).collect();
    let lib_dirs: Vec<PathBuf> =
        libs.split_whitespace().filter_map(|f| f.strip_prefix("-L")).map(PathBuf::from).collect();
    if include_dirs.is_empty() {
        include_dirs.push(PathBuf::from("/usr/include"));
    }
    // pkg-config may list an include dir that does not hold the headers; insist on them.
    if !include_dirs.iter().any(|d| d.join("octomap/octomap.h").is_file()) {
        return None;
    }
    Some(Found { include_dirs, lib_dirs, version, how: "pkg-config" })
}

fn probe_paths() -> Option<Found> {
    let mut prefixes: Vec<PathBuf> = Vec::new();
    if let Ok(dir) = env::var("OCTOMAP_DIR") {
        prefixes.push(PathBuf::from(dir));
    }
    prefixes.extend(["/usr", "/usr/local"].map(PathBuf::from));
    for prefix in prefixes {
        let inc = prefix.join("include");
        if !inc.join("octomap/octomap.h").is_file() {
            continue;
        }
        let multiarch = format!("lib/{}-linux-gnu", env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default());
        for sub in [multiarch.as_str(), "lib64", "lib"] {
            let lib = prefix.join(sub);
            if lib.join("liboctomap.so").exists() && lib.join("liboctomath.so").exists() {
                return Some(Found {
                    include_dirs: vec![inc],
                    lib_dirs: vec![lib],
                    version: "unknown".into(),
                    how: "header/library paths",
                });
            }
        }
    }
    None
}

fn build_shim(found: &Found) -> Result<(), String> {
    let out_dir = PathBuf::from(env::var("OUT_DIR").map_err(|e| e.to_string())?);
    let mut build = cc::Build::new();
    build.cpp(true).file(SHIM).std("c++14").opt_level(2).debug(false).warnings(true).cargo_metadata(false);
    for dir in &found.include_dirs {
        build.include(dir);
    }
    build.try_compile("octolinear_oracle_shim").map_err(|e| e.to_string())?;

    // Final check: link a tiny C++ program against the shim and the libraries,
    // so a broken installation degrades to "unavailable" instead of a link error.
    let compiler = build.try_get_compiler().map_err(|e| e.to_string())?;
    let test_src = out_dir.join("olo_link_check.cpp");
    std::fs::write(
        &test_src,
        "extern \"C\" void* olo_tree_new(double);\n\
         extern \"C\" void olo_tree_free(void*);\n\
         int main() { olo_tree_free(olo_tree_new(0.1)); return 0; }\n",
    )
    .map_err(|e| e.to_string())?;
    let mut cmd = compiler.to_command();
    cmd.arg(&test_src).arg("-o").arg(out_dir.join("olo_link_check")).arg(out_dir.join("liboctolinear_oracle_shim.a"));
    for dir in &found.lib_dirs {
        cmd.arg(format!("-L{}", dir.display()));
    }
    cmd.args(["-loctomap", "-loctomath"]);
    let out = cmd.output().map_err(|e| format!("running the C++ compiler: {e}"))?;
    if !out.status.success() {
        return Err(format!("link check failed: {}", String::from_utf8_lossy(&out.stderr).trim()));
    }

    // Link order: the static shim first, then OctoMap, then the C++ runtime.
    println!("cargo::rustc-link-search=native={}", out_dir.display());
    println!("cargo::rustc-link-lib=static=octolinear_oracle_shim");
    for dir in &found.lib_dirs {
        println!("cargo::rustc-link-search=native={}", dir.display());
    }
    println!("cargo::rustc-link-lib=dylib=octomap");
    println!("cargo::rustc-link-lib=dylib=octomath");
    println!("cargo::rustc-link-lib=dylib=stdc++");
    Ok(())
}
