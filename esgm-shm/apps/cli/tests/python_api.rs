//! The `esgm` Python package (esgm-shm/python): built into the test venv with maturin
//! (`maturin develop`, so the tests run the code of this checkout), then its pytest
//! suite runs against a coordinator this test starts in a domain of its own: every
//! semantic test on both runtimes, the zero-copy and lifetime test of images across
//! processes, and Python units supervised in a system of their own (through the
//! `esgm` command, `ESGM_BIN`).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

/// The test venv (`target/py-venv`), with maturin and pytest.
#[path = "../../../../esgm-core/recording/tests/common/python.rs"]
mod python;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Mutex;

use common::{StopOnDrop, ok};

/// One maturin build at a time: both tests build the package in the same target
/// directory, and a second cargo would wait on the first's lock anyway.
static MATURIN: Mutex<()> = Mutex::new(());

fn said(out: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

#[test]
fn the_python_package_passes_its_tests_on_both_runtimes() {
    let python = python::venv_python();
    let venv = python.parent().and_then(|bin| bin.parent()).unwrap().to_path_buf();
    let package = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../python");
    let building = MATURIN.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
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
    drop(building);

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

/// The README's install lines for a robot without Rust: `maturin build` makes a wheel,
/// `pip install esgm-*.whl` puts it into a fresh venv (nothing of this checkout on its
/// path), and that Python reaches a running domain: it creates a trajectory and adds,
/// and the `esgm` command reads what it added.
#[test]
fn a_built_wheel_installs_into_a_fresh_venv_and_reaches_a_domain() {
    let venv = python::venv_python().parent().and_then(Path::parent).unwrap().to_path_buf();
    let package = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../python");
    let scratch = std::env::temp_dir().join(format!("esgm-wheel-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    let wheels = scratch.join("wheels");
    let building = MATURIN.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let built = Command::new(venv.join("bin/maturin"))
        .args(["build", "--quiet", "-m"])
        .arg(package.join("Cargo.toml"))
        .arg("--out")
        .arg(&wheels)
        .output()
        .unwrap();
    drop(building);
    assert!(built.status.success(), "maturin build failed:\n{}", said(&built));
    let wheel: Vec<PathBuf> = std::fs::read_dir(&wheels)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "whl"))
        .collect();
    assert_eq!(wheel.len(), 1, "one wheel: {wheel:?}");
    let name = wheel[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with("esgm-") && name.contains("abi3"), "a stable-ABI wheel: {name}");

    // A venv of its own, as on a robot: only the wheel and what it depends on.
    let fresh = scratch.join("venv");
    let made = Command::new("python3").args(["-m", "venv"]).arg(&fresh).output().unwrap();
    assert!(made.status.success(), "python3 -m venv failed:\n{}", said(&made));
    let python = fresh.join("bin/python");
    let installed = Command::new(&python)
        .args(["-m", "pip", "install", "--quiet", "--disable-pip-version-check"])
        .arg(&wheel[0])
        .output()
        .unwrap();
    assert!(installed.status.success(), "pip install of the wheel failed:\n{}", said(&installed));

    let domain = esgm_shm::unique_domain("wheel");
    ok(&["--domain", &domain, "up", "--detach"]);
    let _stop = StopOnDrop(domain.clone());
    let script = r#"
import sys, esgm
assert "site-packages" in esgm.__file__, esgm.__file__
system = esgm.connect(sys.argv[1])
t = system.create_primitive_entity_trajectory_structure("from_wheel", "RobotState")
t.add("robot", 42, {"x": 1.5, "y": 2.0, "dir": 90.0})
system.flush(10)
print("latest", t.get_latest()["x"])
"#;
    let ran = Command::new(&python)
        .args(["-c", script, &domain])
        .current_dir(&scratch)
        .env_remove("PYTHONPATH")
        .output()
        .unwrap();
    assert!(ran.status.success(), "the installed package failed:\n{}", said(&ran));
    assert!(String::from_utf8_lossy(&ran.stdout).contains("latest 1.5"), "{}", said(&ran));
    let read = ok(&["--domain", &domain, "--json", "latest", "from_wheel"]);
    assert!(read.contains("1.5") && read.contains("\"valid_time\":42"), "{read}");
    let _ = std::fs::remove_dir_all(&scratch);
}
