//! The `esgm` Python package (esgm-shm/python): built into the test venv with maturin
//! (`maturin develop`, so the tests run the code of this checkout), then its pytest
//! suite runs against a coordinator this test starts in a domain of its own: every
//! semantic test on both runtimes, the zero-copy and lifetime test of images across
//! processes, and Python units supervised in a system of their own (through the
//! `esgm` command, `ESGM_BIN`).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

/// The test venv (`target/py-venv`), with maturin and pytest.
#[path = "../../../esgm-core/recording/tests/common/python.rs"]
mod python;

use std::path::PathBuf;
use std::process::Command;

use common::{StopOnDrop, ok};

#[test]
fn the_python_package_passes_its_tests_on_both_runtimes() {
    let python = python::venv_python();
    let venv = python.parent().and_then(|bin| bin.parent()).unwrap().to_path_buf();
    let package = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../python");
    let built = Command::new(venv.join("bin/maturin"))
        .args(["develop", "--quiet", "-m"])
        .arg(package.join("Cargo.toml"))
        .env("VIRTUAL_ENV", &venv)
        .output()
        .unwrap();
    assert!(
        built.status.success(),
        "maturin develop failed:\n{}\n{}",
        String::from_utf8_lossy(&built.stdout),
        String::from_utf8_lossy(&built.stderr)
    );

    let domain = esgm_shm::unique_domain("python");
    ok(&["--domain", &domain, "up", "--detach"]);
    let _stop = StopOnDrop(domain.clone());
    let out = Command::new(python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(package.join("tests"))
        .env("ESGM_TEST_DOMAIN", &domain)
        .env("ESGM_BIN", env!("CARGO_BIN_EXE_esgm"))
        .output()
        .unwrap();
    let said = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "pytest failed:\n{said}");
    assert!(said.contains(" passed") && !said.contains("skipped"), "{said}");
}
