//! The committed C header, `include/esgm.h`, is the one cbindgen generates from this
//! crate: a change to the ABI that is not in the header (or the other way round) fails
//! here, so the header a C program compiles against is always the library's.
//! `ESGM_BLESS=1 cargo test -p esgm-c --test header` writes the generated one.

use std::path::Path;

#[test]
fn the_committed_header_is_the_generated_one() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config =
        cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("read cbindgen.toml");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("generate the header from the crate")
        .write(&mut generated);
    let generated = String::from_utf8(generated).expect("the header is UTF-8");
    let path = crate_dir.join("include/esgm.h");
    if std::env::var_os("ESGM_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("write include/esgm.h");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    if committed != generated {
        let first = committed
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or_else(|| committed.lines().count().min(generated.lines().count()));
        panic!(
            "include/esgm.h differs from the header generated from the crate (from line {}): \
             run `ESGM_BLESS=1 cargo test -p esgm-c --test header` and commit it",
            first + 1
        );
    }
}
