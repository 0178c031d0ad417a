//! Gives the `choreo` binary an rpath to libtorch, so it runs without `LD_LIBRARY_PATH`.
//!
//! `LIBTORCH` is set by `.cargo/config.toml` to the PyPI torch wheel that `scripts/setup.sh`
//! installs into `.torchenv`; the wheel's own libraries find their CUDA runtime stubs through
//! their `$ORIGIN` rpath, so only `torch/lib` needs naming here.
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    // `sqlx::migrate!` embeds the migrations at compile time but cannot tell cargo to watch
    // them: without this a new migration file leaves a binary that never runs it.
    println!("cargo:rerun-if-changed=migrations");
    let Ok(libtorch) = std::env::var("LIBTORCH") else {
        println!("cargo:warning=LIBTORCH is not set; run scripts/setup.sh first");
        return;
    };
    let lib = PathBuf::from(&libtorch).join("lib");
    let lib = lib.canonicalize().unwrap_or(lib);
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    // libtorch_cpu.so names libcudart/libcupti; let the linker find them through its rpath.
    println!("cargo:rustc-link-arg=-Wl,-rpath-link,{}", lib.display());
}
