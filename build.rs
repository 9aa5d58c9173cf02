//! Whether the machine that builds the tests can run the CUDA kernel's checks without a GPU: a
//! C++ compiler for tests/cuda_host.rs (the kernel built for the host), NVRTC for the test that
//! compiles it to PTX. Where one is missing, those tests are built `#[ignore]`d with the reason,
//! so that `cargo test` reports them as ignored, never as passed; where one is found, a test that
//! cannot use it at run time fails. `VSHAKE_REQUIRE_CXX` and `VSHAKE_REQUIRE_NVRTC` (CI sets both)
//! keep the tests on whatever is found. Nothing of `study` depends on it: a GPU is found at run
//! time.

use std::path::Path;
use std::process::Command;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(vshake_no_cxx)");
    println!("cargo::rustc-check-cfg=cfg(vshake_no_nvrtc)");
    println!("cargo::rerun-if-changed=build.rs");
    for var in [
        "CXX",
        "VSHAKE_REQUIRE_CXX",
        "VSHAKE_REQUIRE_NVRTC",
        "LD_LIBRARY_PATH",
    ] {
        println!("cargo::rerun-if-env-changed={var}");
    }
    if std::env::var_os("VSHAKE_REQUIRE_CXX").is_none() && !has_cxx() {
        println!("cargo::rustc-cfg=vshake_no_cxx");
    }
    if std::env::var_os("VSHAKE_REQUIRE_NVRTC").is_none() && !has_nvrtc() {
        println!("cargo::rustc-cfg=vshake_no_nvrtc");
    }
}

/// `$CXX`, else `c++`, answers `--version`.
fn has_cxx() -> bool {
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".into());
    Command::new(cxx)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// A `libnvrtc.so*` in `LD_LIBRARY_PATH` or a usual library folder (where the loader finds it).
fn has_nvrtc() -> bool {
    let from_env = std::env::var("LD_LIBRARY_PATH").unwrap_or_default();
    let usual = [
        "/usr/local/cuda/lib64",
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
        "/usr/lib64",
        "/usr/lib",
    ];
    let found = from_env
        .split(':')
        .filter(|d| !d.is_empty())
        .chain(usual)
        .filter_map(|d| Path::new(d).read_dir().ok())
        .flatten()
        .flatten()
        .any(|f| f.file_name().to_string_lossy().starts_with("libnvrtc.so"));
    found
}
