//! Gives the shared library its name at run time (its ELF SONAME), `libesgm_c.so`:
//! without one, a program linked against it by path records that path, and would look
//! for the library only there once installed elsewhere.

fn main() {
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os == "linux" {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libesgm_c.so");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
