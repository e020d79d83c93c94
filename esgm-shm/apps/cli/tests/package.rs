//! The Debian package (`packaging/deb.sh`), built from what these tests built (the debug
//! `esgm`, and beside it the external subcommands and the C library when the workspace
//! built them, always in CI): dpkg-deb reads its control file (the package, this
//! version, the glibc the executables need) and its contents (the command and its
//! external subcommands, the C library with its headers, CMake package and pkg-config
//! file, a manual page per subcommand, bash, zsh and fish completions, the copyright);
//! unpacked into a scratch root, its `esgm demo --seconds 3` runs the tutorial. Nothing
//! is installed on the machine. Without dpkg-deb, objdump or CMake the test is skipped,
//! and fails in CI (`CI` set).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const ESGM: &str = env!("CARGO_BIN_EXE_esgm");

fn have(tool: &str, arg: &str) -> bool {
    Command::new(tool).arg(arg).output().is_ok_and(|o| o.status.success())
}

fn text(out: &std::process::Output) -> String {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_debian_package_holds_the_command_its_pages_and_completions() {
    let ci = std::env::var_os("CI").is_some();
    if !have("dpkg-deb", "--version")
        || !have("objdump", "--version")
        || !have("cmake", "--version")
    {
        assert!(!ci, "dpkg-deb, objdump and CMake are needed");
        eprintln!("skipped: no dpkg-deb, objdump or cmake");
        return;
    }
    let out = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("packaging/deb.sh");
    let bin_dir = Path::new(ESGM).parent().unwrap();
    let built = Command::new(&script)
        .arg(out.path())
        .env("ESGM_BIN_DIR", bin_dir)
        // A `cargo test -p esgm-cli` builds only esgm; the workspace's tests build all.
        .env("ESGM_PARTIAL", if ci { "0" } else { "1" })
        .env("ESGM_DEB_COMPRESSION", "none")
        .output()
        .unwrap();
    let deb = text(&built).trim().to_owned();
    let arch = text(&Command::new("dpkg").arg("--print-architecture").output().unwrap());
    let name = format!("esgm_{}_{}.deb", env!("CARGO_PKG_VERSION"), arch.trim());
    assert!(deb.ends_with(&name), "{deb}");

    let info = text(&Command::new("dpkg-deb").args(["--field", &deb]).output().unwrap());
    assert!(info.contains("Package: esgm\n"), "{info}");
    assert!(info.contains(&format!("Version: {}\n", env!("CARGO_PKG_VERSION"))), "{info}");
    assert!(info.contains("Depends: libc6 (>= 2."), "the glibc it needs: {info}");

    let contents = text(&Command::new("dpkg-deb").args(["--contents", &deb]).output().unwrap());
    let mut expected = vec![
        "./usr/bin/esgm",
        "./usr/share/man/man1/esgm.1.gz",
        "./usr/share/man/man1/esgm-latest.1.gz",
        "./usr/share/man/man1/esgm-traj-list.1.gz",
        "./usr/share/bash-completion/completions/esgm",
        "./usr/share/zsh/vendor-completions/_esgm",
        "./usr/share/fish/vendor_completions.d/esgm.fish",
        "./usr/share/doc/esgm/copyright",
    ];
    let everything_built =
        ["esgm-view", "esgm-ros2", "esgm-bridge"].iter().all(|f| bin_dir.join(f).exists())
            && ["libesgm_c.so", "deps/libesgm_c.so"].iter().any(|f| bin_dir.join(f).exists());
    if everything_built || ci {
        expected.extend([
            "./usr/bin/esgm-view",
            "./usr/bin/esgm-ros2",
            "./usr/bin/esgm-bridge",
            "/libesgm_c.so",
            "/libesgm_c.a",
            "./usr/include/esgm.h",
            "./usr/include/esgm/esgm.hpp",
            "/cmake/esgm/esgmConfig.cmake",
            "/pkgconfig/esgm.pc",
        ]);
    }
    for path in expected {
        assert!(contents.contains(path), "no {path} in\n{contents}");
    }
    assert!(contents.contains("root/root"), "files owned by root: {contents}");

    let root = tempfile::tempdir().unwrap();
    text(&Command::new("dpkg-deb").arg("-x").arg(&deb).arg(root.path()).output().unwrap());
    let esgm = root.path().join("usr/bin/esgm");
    let version = text(&Command::new(&esgm).arg("--version").output().unwrap());
    assert!(version.contains(env!("CARGO_PKG_VERSION")), "{version}");

    // The tutorial from the unpacked command: its workers are that executable too.
    let domain = esgm_shm::unique_domain("deb-demo");
    let mut demo = Command::new(&esgm)
        .args(["--domain", &domain, "demo", "--seconds", "3"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    while demo.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            demo.kill().unwrap();
            panic!("the packaged esgm demo did not end within 120 s");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let said = text(&demo.wait_with_output().unwrap());
    assert!(said.contains("image copies in all: 0"), "{said}");
    assert!(said.contains("stopped: coordinator and"), "{said}");
}
