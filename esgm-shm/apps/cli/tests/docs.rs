//! `esgm completions` and `esgm man`: generated from the command's own definition,
//! with no system running. The bash script is checked by bash itself (`bash -n`) and
//! names the subcommands; the pages are roff with a page per visible subcommand, and
//! groff (with preconv, as man runs it) reads them without a warning where it is
//! installed.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Command;

const ESGM: &str = env!("CARGO_BIN_EXE_esgm");

fn run(args: &[&str]) -> String {
    let out = Command::new(ESGM).args(args).output().unwrap();
    assert!(out.status.success(), "esgm {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn completions_are_scripts_their_shell_reads_and_name_the_subcommands() {
    let bash = run(&["completions", "bash"]);
    for sub in ["latest", "record", "traj", "completions"] {
        assert!(bash.contains(sub), "no `{sub}` in the bash completions");
    }
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("esgm.bash");
    std::fs::write(&script, &bash).unwrap();
    let checked = Command::new("bash").arg("-n").arg(&script).output().unwrap();
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stderr));
    for shell in ["zsh", "fish", "elvish", "powershell"] {
        assert!(run(&["completions", shell]).contains("latest"), "{shell}");
    }
    let refused = Command::new(ESGM).args(["completions", "tcsh"]).output().unwrap();
    assert_eq!(refused.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("possible values"));
}

#[test]
fn manual_pages_cover_every_visible_subcommand() {
    let page = run(&["man"]);
    assert!(page.contains(".TH esgm 1"), "{page}");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("man1");
    run(&["man", "--out", out.to_str().unwrap()]);
    let mut pages: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    pages.sort();
    for expected in ["esgm.1", "esgm-latest.1", "esgm-traj-list.1", "esgm-record.1", "esgm-man.1"] {
        assert!(pages.iter().any(|p| p == expected), "no {expected} in {pages:?}");
    }
    assert!(!pages.iter().any(|p| p.contains("worker")), "hidden subcommands have no page");
    let latest = std::fs::read_to_string(out.join("esgm-latest.1")).unwrap();
    assert!(latest.contains(".TH esgm-latest 1") && latest.contains("TRAJECTORY"), "{latest}");
    let groff = Command::new("groff").arg("--version").output();
    if groff.is_ok_and(|o| o.status.success()) {
        for p in &pages {
            let r = Command::new("groff")
                .args(["-k", "-man", "-Tutf8", "-ww", "-z"])
                .arg(out.join(p))
                .output()
                .unwrap();
            assert!(
                r.status.success() && r.stderr.is_empty(),
                "{p}: {}",
                String::from_utf8_lossy(&r.stderr)
            );
        }
    }
}
