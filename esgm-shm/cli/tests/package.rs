//! The Debian package (`packaging/deb.sh`), built from the `esgm` these tests built:
//! dpkg-deb reads its control file (the package, this version, the glibc the
//! executable needs) and its contents (the command, a manual page per subcommand,
//! bash, zsh and fish completions, the copyright), and the command unpacked from it
//! runs. Nothing is installed on the machine. Without dpkg-deb or objdump the test is
//! skipped, and fails in CI (`CI` set).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::Command;

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
    if !have("dpkg-deb", "--version") || !have("objdump", "--version") {
        assert!(std::env::var_os("CI").is_none(), "dpkg-deb and objdump are needed");
        eprintln!("skipped: no dpkg-deb or objdump");
        return;
    }
    let out = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("packaging/deb.sh");
    let built = Command::new(&script).arg(out.path()).env("ESGM_BIN", ESGM).output().unwrap();
    let deb = text(&built).trim().to_owned();
    assert!(
        deb.ends_with(&format!("esgm_{}_{}.deb", env!("CARGO_PKG_VERSION"), {
            text(&Command::new("dpkg").arg("--print-architecture").output().unwrap())
                .trim()
                .to_owned()
        })),
        "{deb}"
    );

    let info = text(&Command::new("dpkg-deb").args(["--field", &deb]).output().unwrap());
    assert!(info.contains("Package: esgm\n"), "{info}");
    assert!(info.contains(&format!("Version: {}\n", env!("CARGO_PKG_VERSION"))), "{info}");
    assert!(info.contains("Depends: libc6 (>= 2."), "the glibc it needs: {info}");

    let contents = text(&Command::new("dpkg-deb").args(["--contents", &deb]).output().unwrap());
    for path in [
        "./usr/bin/esgm",
        "./usr/share/man/man1/esgm.1.gz",
        "./usr/share/man/man1/esgm-latest.1.gz",
        "./usr/share/man/man1/esgm-traj-list.1.gz",
        "./usr/share/bash-completion/completions/esgm",
        "./usr/share/zsh/vendor-completions/_esgm",
        "./usr/share/fish/vendor_completions.d/esgm.fish",
        "./usr/share/doc/esgm/copyright",
    ] {
        assert!(contents.contains(path), "no {path} in\n{contents}");
    }
    assert!(contents.contains("root/root"), "files owned by root: {contents}");

    let root = tempfile::tempdir().unwrap();
    text(&Command::new("dpkg-deb").arg("-x").arg(&deb).arg(root.path()).output().unwrap());
    let version =
        text(&Command::new(root.path().join("usr/bin/esgm")).arg("--version").output().unwrap());
    assert!(version.contains(env!("CARGO_PKG_VERSION")), "{version}");
}
