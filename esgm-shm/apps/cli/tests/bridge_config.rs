//! A bridge declared in a system's TOML file (`[[bridge]]`): `esgm apply` has the
//! supervisor run `esgm-bridge`, and a structure pushed in domain A is answered in
//! domain B, whose file imports it. Both domains on this host, over loopback TCP.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // a failure is a failed test

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::{ESGM, StopOnDrop, capability, esgm, ok};

/// `esgm-bridge` next to `esgm`: `cargo test --workspace` (what CI runs) builds it.
fn bridge_is_built() -> bool {
    let bridge = Path::new(ESGM).with_file_name("esgm-bridge");
    capability::needs("esgm-bridge (cargo build -p esgm-bridge)", capability::built(&bridge))
        .is_some()
}

#[test]
fn a_bridge_declared_in_toml_carries_a_trajectory_to_another_domain() {
    if !bridge_is_built() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (esgm_shm::unique_domain("cli-bridge-a"), esgm_shm::unique_domain("cli-bridge-b"));
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let file_a = dir.path().join("a.toml");
    std::fs::write(
        &file_a,
        format!(
            "[[trajectory]]\nname = \"robot_state\"\nprimitive = \"RobotState\"\n\n\
             [[bridge]]\nlisten = [\"tcp/127.0.0.1:{port}\"]\nexport = [\"robot_state\"]\n"
        ),
    )
    .unwrap();
    let file_b = dir.path().join("b.toml");
    std::fs::write(
        &file_b,
        format!(
            "[[bridge]]\nname = \"uplink\"\nconnect = [\"tcp/127.0.0.1:{port}\"]\n\
             import = [\"{a}/robot_state\"]\n"
        ),
    )
    .unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "\n[[bridge]]\nlisten = [\"7447\"]\nexport = [\"x\"]\n").unwrap();

    ok(&["--domain", &a, "up", "--detach"]);
    let _stop_a = StopOnDrop(a.clone());
    ok(&["--domain", &b, "up", "--detach"]);
    let _stop_b = StopOnDrop(b.clone());
    // A wrong endpoint is refused naming the line, before anything runs.
    let o = esgm(&["--domain", &a, "apply", bad.to_str().unwrap()], Duration::from_secs(60));
    assert_eq!(o.code, Some(1), "{}", o.stdout);
    assert!(
        o.stderr.contains("bad.toml:2:") && o.stderr.contains("<protocol>/<address>"),
        "{}",
        o.stderr
    );

    ok(&["--domain", &a, "apply", file_a.to_str().unwrap()]);
    ok(&["--domain", &b, "apply", file_b.to_str().unwrap()]);
    assert!(ok(&["--domain", &a, "ps"]).contains("bridge"));
    assert!(ok(&["--domain", &b, "ps"]).contains("uplink"));

    ok(&["--domain", &a, "push", "robot_state", "x=1.5", "y=2", "dir=90", "--valid-time", "1000"]);
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let o = esgm(&["--domain", &b, "--json", "latest", "robot_state"], Duration::from_secs(60));
        if o.code == Some(0) {
            let v: serde_json::Value = serde_json::from_str(o.stdout.trim()).unwrap();
            assert_eq!(
                (v["valid_time"].as_i64(), v["attributes"]["x"].as_f64()),
                (Some(1000), Some(1.5))
            );
            break;
        }
        assert!(Instant::now() < deadline, "domain B never answered: {}", o.stderr);
        std::thread::sleep(Duration::from_millis(250));
    }
}
