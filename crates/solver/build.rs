//! Chooses the ray backend at build time: Intel Embree 3 where its library is installed
//! (Debian's `libembree-dev`; `scripts/embree.sh`), obvhs's BVH otherwise. Embree cast the
//! monastery's rays 1.5x faster end to end (docs/BENCHMARKS.md), with the same answers; a
//! user who installed it expects it used, and a machine without it still builds.
//!
//! The `embree` feature requires it (the link fails without the library); `RADCAST_EMBREE=off`
//! at build time keeps obvhs even where Embree is installed. Installed after a build, Embree
//! is found once the solver is built anew (`cargo clean -p radcast-solver`): watching the
//! system's library folders would rebuild the solver at every package install.

use std::path::Path;

/// Where Debian, Fedora and a local install put the library the linker needs.
const LIBRARY_DIRS: [&str; 5] = [
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
];

fn main() {
    println!("cargo::rustc-check-cfg=cfg(embree)");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=RADCAST_EMBREE");
    let installed = LIBRARY_DIRS
        .iter()
        .map(|dir| Path::new(dir).join("libembree3.so"))
        .find(|library| library.exists());
    if let Some(library) = &installed {
        // Removed, it is no longer there to link.
        println!("cargo::rerun-if-changed={}", library.display());
    }
    let required = std::env::var_os("CARGO_FEATURE_EMBREE").is_some();
    let refused = std::env::var("RADCAST_EMBREE").is_ok_and(|v| v == "off");
    if required || (installed.is_some() && !refused) {
        println!("cargo::rustc-cfg=embree");
    }
}
