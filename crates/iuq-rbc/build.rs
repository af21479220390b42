//! Enables the AVX-512 fluid kernels (`cfg(iuq_avx512)`) when the compiler has the AVX-512
//! intrinsics (stable since Rust 1.89). Older compilers, down to the workspace's minimum 1.85,
//! build the AVX2 and scalar kernels only.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(iuq_avx512)");
    println!("cargo::rerun-if-changed=build.rs");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let Ok(output) = std::process::Command::new(rustc).arg("--version").output() else {
        return;
    };
    let version = String::from_utf8_lossy(&output.stdout);
    // "rustc 1.95.0 (59807616e 2026-04-14)"
    let minor = version
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.split('.').nth(1))
        .and_then(|m| m.parse::<u32>().ok());
    if minor.is_some_and(|m| m >= 89) {
        println!("cargo::rustc-cfg=iuq_avx512");
    }
}
