//! Two hosts that share nothing but a network: two network namespaces joined by a veth
//! pair (private 10.x addresses this test gives them), each with its own `/dev/shm`
//! and `/tmp/iceoryx2` (a mount namespace; the rest of `/tmp` stays visible, because
//! a checkout and its test binaries may live there), so iceoryx2 cannot connect them
//! and only Zenoh can. Each "host" is this test binary run again inside its namespaces
//! ([`netns_host`]): a coordinator, a bridge (restarted when it dies, like a
//! supervisor would), and on host A a writer, on host B a checker.
//!
//! Faults: the exporter's bridge is killed with `kill -9` (and restarted), the veth
//! link is taken down and up; the importer resumes and every sample host A wrote is
//! either added on host B or counted as lost.
//!
//! Where namespaces cannot be created (not root, no `ip` or `unshare`), the test fails
//! in CI (`CI` set) and elsewhere is skipped with a note on the terminal.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

/// Skipped outside CI, failed in CI, without root, `ip` or `unshare` (the cli tests' helper).
#[path = "../../cli/tests/common/capability.rs"]
mod capability;
#[path = "../../cli/tests/common/netns.rs"]
mod loopback_netns;
use loopback_netns::ip;

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use common::{BRIDGE, Domain, one_at_a_time};
use esgm_core::esgm::TrajectorySpec;
use esgm_core::{
    CacheConstraint, EntityStructure, EntityTrajectoryStructure, Esgm, FluentStreamPolicy, Octets,
    Value,
};

const ROLE: &str = "ESGM_BRIDGE_NETNS_ROLE";
const DOMAIN_A: &str = "ESGM_BRIDGE_NETNS_DOMAIN_A";
const DOMAIN_B: &str = "ESGM_BRIDGE_NETNS_DOMAIN_B";
const ENDPOINT: &str = "ESGM_BRIDGE_NETNS_ENDPOINT";
const WAIT: Duration = Duration::from_secs(30);
/// Valid times of the structures host A writes: BASE + i * STEP, so host B can tell
/// which one it holds and check every value.
const BASE: i64 = 1_800_000_000_000_000_000;
const STEP: i64 = 20_000_000;

fn robot(i: i64) -> EntityStructure {
    EntityStructure::new("robot1", BASE + i * STEP, BASE + i * STEP + 3)
        .with("x", i as f64 * 0.25)
        .with("y", 2.0)
        .with("dir", (i % 360) as f64)
}

fn image(i: i64) -> EntityStructure {
    let pixels: Vec<u8> = (0..32 * 24).map(|p| ((p + i) % 253) as u8).collect();
    EntityStructure::new("camera", BASE + i * STEP, BASE + i * STEP)
        .with("width", 32i64)
        .with("height", 24i64)
        .with("format", 1i64)
        .with("image_data", Value::OctetSeq(Octets::from(pixels)))
}

/// Two namespaces and the veth pair between them, removed when dropped.
struct Network {
    ns: [String; 2],
    veth: [String; 2],
    addr: [String; 2],
}

impl Network {
    fn create() -> Result<Network, String> {
        let pid = std::process::id();
        let net = Network {
            ns: [format!("esgm{pid}a"), format!("esgm{pid}b")],
            veth: [format!("eb{pid}a"), format!("eb{pid}b")],
            // 10.213.<x>.<y>/30: private, owned by these two namespaces only.
            addr: [
                format!("10.213.{}.{}", (pid >> 6) % 256, (pid % 64) * 4 + 1),
                format!("10.213.{}.{}", (pid >> 6) % 256, (pid % 64) * 4 + 2),
            ],
        };
        for ns in &net.ns {
            ip(&["netns", "add", ns])?;
        }
        let [va, vb] = &net.veth;
        ip(&["link", "add", va, "type", "veth", "peer", "name", vb])?;
        for i in 0..2 {
            let (ns, v) = (&net.ns[i], &net.veth[i]);
            ip(&["link", "set", v, "netns", ns])?;
            ip(&["-n", ns, "addr", "add", &format!("{}/30", net.addr[i]), "dev", v])?;
            ip(&["-n", ns, "link", "set", v, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(net)
    }

    fn link(&self, up: bool) {
        ip(&["-n", &self.ns[0], "link", "set", &self.veth[0], if up { "up" } else { "down" }])
            .unwrap();
    }
}

impl Drop for Network {
    fn drop(&mut self) {
        for ns in &self.ns {
            // The veth pair goes with its namespaces.
            if let Err(e) = ip(&["netns", "del", ns]) {
                eprintln!("{e}");
            }
        }
    }
}

/// One host: this test binary as [`netns_host`], inside a namespace with its own
/// `/dev/shm` and `/tmp`. Lines it prints arrive on `lines`; commands go to `stdin`.
struct Host {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: mpsc::Receiver<String>,
    name: &'static str,
}

impl Host {
    fn start(net: &Network, index: usize, role: &'static str, envs: &[(&str, &str)]) -> Host {
        let me = std::env::current_exe().unwrap();
        let mut command = Command::new("ip");
        command
            .args([
                "netns",
                "exec",
                &net.ns[index],
                "unshare",
                "--mount",
                "--propagation",
                "private",
            ])
            .args([
                "sh",
                "-c",
                "mount -t tmpfs tmpfs /dev/shm && mkdir -p /tmp/iceoryx2 && mount -t tmpfs tmpfs /tmp/iceoryx2 && exec \"$@\"",
                "sh",
            ])
            .arg(&me)
            .args(["netns_host", "--exact", "--ignored", "--nocapture", "--test-threads", "1"])
            .env(ROLE, role)
            .envs(envs.iter().copied())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        let mut child = command.spawn().expect("start a host");
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                // libtest's own `test netns_host ... ` may start the first line.
                let line = match (line.find("@@ "), line.find('{')) {
                    (Some(i), _) => line[i + 3..].to_owned(),
                    (None, Some(i)) => line[i..].to_owned(),
                    (None, None) => line,
                };
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        Host { stdin: child.stdin.take(), child, lines, name: role }
    }

    fn send(&mut self, command: &str) {
        let stdin = self.stdin.as_mut().unwrap();
        writeln!(stdin, "{command}").unwrap();
        stdin.flush().unwrap();
    }

    /// Waits for a line `accept` takes.
    fn wait(&mut self, what: &str, accept: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + WAIT;
        let mut last = String::new();
        while Instant::now() < deadline {
            match self.lines.recv_timeout(Duration::from_millis(200)) {
                Ok(line) if accept(&line) => return line,
                Ok(line) => last = line,
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    panic!("host {} ended while waiting for {what}", self.name)
                }
            }
        }
        panic!("host {}: no {what} within {WAIT:?}; last line: {last}", self.name);
    }

    /// Waits for the import counters of `trajectory` that `accept` takes.
    fn counters(
        &mut self,
        trajectory: &str,
        accept: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let line = self.wait(&format!("counters of {trajectory}"), |l| {
            serde_json::from_str::<serde_json::Value>(l)
                .is_ok_and(|v| v["role"] == "import" && v["trajectory"] == trajectory && accept(&v))
        });
        serde_json::from_str(&line).unwrap()
    }
}

impl Drop for Host {
    fn drop(&mut self) {
        // Closing stdin ends the host; a host that does not end is killed.
        self.stdin.take();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn lost(v: &serde_json::Value) -> u64 {
    v["lost"].as_object().map_or(0, |m| m.values().filter_map(serde_json::Value::as_u64).sum())
}

#[test]
fn two_hosts_that_share_only_a_network() {
    if std::env::var_os(ROLE).is_some() {
        return;
    }
    let _one = one_at_a_time();
    // Each host runs in a mount namespace of its own too.
    let unshare = capability::runs("unshare", &["--mount", "true"]);
    if capability::needs("mount namespaces (unshare --mount)", unshare).is_none() {
        return;
    }
    let Some(net) = capability::needs("network namespaces (ip netns)", Network::create()) else {
        return;
    };
    let pid = std::process::id();
    let (domain_a, domain_b) = (format!("netns-a-{pid}"), format!("netns-b-{pid}"));
    let endpoint = format!("tcp/{}:7447", net.addr[0]);
    let envs =
        [(DOMAIN_A, domain_a.as_str()), (DOMAIN_B, domain_b.as_str()), (ENDPOINT, &endpoint)];
    let mut a = Host::start(&net, 0, "a", &envs);
    let line = a.wait("host A's bridge", |l| l.starts_with("bridge pid "));
    let bridge_pid = line.trim_start_matches("bridge pid ").to_owned();
    let mut b = Host::start(&net, 1, "b", &envs);

    // The first sample crosses, then host A writes on.
    a.send("write 1");
    b.counters("robot_state", |v| v["added"] == 1);
    a.send("go");
    b.counters("robot_state", |v| v["added"].as_u64() >= Some(40));
    b.counters("images", |v| v["added"].as_u64() >= Some(3));
    b.wait("intact samples on host B", |l| {
        l.starts_with("intact robot_state") && !l.ends_with(" 0")
    });

    // kill -9 of the exporting bridge; host A starts another.
    let status = Command::new("kill").args(["-9", &bridge_pid]).status().unwrap();
    assert!(status.success());
    a.wait("a restarted bridge", |l| l.starts_with("bridge pid ") && !l.ends_with(&bridge_pid));
    let c = b.counters("robot_state", |v| v["lost"]["exporter_restarted"].as_u64() > Some(0));
    let added = c["added"].as_u64().unwrap();
    b.counters("robot_state", |v| v["added"].as_u64() > Some(added + 20));

    // The link goes down and up.
    net.link(false);
    std::thread::sleep(Duration::from_secs(3));
    net.link(true);
    let c = b.counters("robot_state", |_| true);
    let added = c["added"].as_u64().unwrap();
    b.counters("robot_state", |v| v["added"].as_u64() > Some(added + 20));

    // Every sample written is added on host B or counted as lost.
    a.send("stop");
    let wrote: u64 = a
        .wait("the count written", |l| l.starts_with("wrote "))
        .trim_start_matches("wrote ")
        .parse()
        .unwrap();
    let c = b.counters("robot_state", |v| v["added"].as_u64().unwrap_or(0) + lost(v) == wrote);
    assert_eq!(c["malformed"], 0, "{c}");
    let check = b.wait("the final check", |l| l.starts_with("intact robot_state"));
    assert!(!check.contains("broken"), "{check}");
    b.counters("images", |v| v["added"].as_u64() >= Some(5));
}

/// Not a test of its own: the body of one host of
/// [`two_hosts_that_share_only_a_network`], run by it inside a namespace.
#[test]
#[ignore = "run by two_hosts_that_share_only_a_network inside a network namespace"]
fn netns_host() {
    let Ok(role) = std::env::var(ROLE) else { return };
    let endpoint = std::env::var(ENDPOINT).unwrap();
    let domain_a = std::env::var(DOMAIN_A).unwrap();
    let domain_b = std::env::var(DOMAIN_B).unwrap();
    let (commands, inbox) = mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines().map_while(Result::ok) {
            if commands.send(line).is_err() {
                return;
            }
        }
    });
    let say = |s: String| {
        let mut out = std::io::stdout().lock();
        writeln!(out, "@@ {s}").unwrap();
        out.flush().unwrap();
    };
    if role == "a" {
        let d = Domain::named(&domain_a);
        for (name, type_name, cache) in [("robot_state", "RobotState", 20), ("images", "Image", 4)]
        {
            d.esgm()
                .create_trajectory(
                    TrajectorySpec::primitive(name, type_name).policy(
                        FluentStreamPolicy::default().cache(CacheConstraint::Elements(cache)),
                    ),
                )
                .unwrap();
        }
        let states = d.esgm().get_entity_trajectory_structure("robot_state").unwrap();
        let images = d.esgm().get_entity_trajectory_structure("images").unwrap();
        let args = ["--domain", &domain_a, "--listen", &endpoint, "--export", "robot_state"];
        let start = || {
            let child = Command::new(BRIDGE)
                .args(args)
                .args(["--export", "images"])
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::inherit())
                .spawn()
                .unwrap();
            say(format!("bridge pid {}", child.id()));
            child
        };
        let mut bridge = start();
        let (mut i, mut writing) = (0i64, false);
        loop {
            match inbox.recv_timeout(Duration::from_millis(20)) {
                Ok(c) if c == "go" => writing = true,
                Ok(c) if c == "stop" => {
                    writing = false;
                    say(format!("wrote {i}"));
                }
                Ok(c) if c.starts_with("write ") => {
                    for _ in 0..c[6..].parse::<i64>().unwrap() {
                        states.add_blocking(robot(i)).unwrap();
                        i += 1;
                    }
                }
                Ok(_) | Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
            if writing {
                states.add_blocking(robot(i)).unwrap();
                if i % 10 == 0 {
                    images.add_blocking(image(i)).unwrap();
                }
                i += 1;
            }
            if let Ok(Some(_)) = bridge.try_wait() {
                bridge = start();
            }
        }
        let _ = bridge.kill();
        let _ = bridge.wait();
    } else {
        let d = Domain::named(&domain_b);
        let mut bridge = Command::new(BRIDGE)
            .args(["--domain", &domain_b, "--connect", &endpoint, "--report-every", "100ms"])
            .args(["--import", &format!("{domain_a}/robot_state")])
            .args(["--import", &format!("{domain_a}/images")])
            .stdin(Stdio::null())
            .stdout(Stdio::inherit())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut checked = Instant::now();
        loop {
            if let Err(mpsc::RecvTimeoutError::Disconnected) =
                inbox.recv_timeout(Duration::from_millis(100))
            {
                break;
            }
            if checked.elapsed() < Duration::from_millis(300) {
                continue;
            }
            checked = Instant::now();
            // Every sample on host B is the one host A wrote at its valid time.
            let Ok(t) = d.esgm().get_entity_trajectory_structure("robot_state") else { continue };
            let all = t.get_between(i64::MIN / 2, i64::MAX / 2).unwrap_or_default();
            let broken =
                all.iter().filter(|s| s.structure != robot((s.valid_time() - BASE) / STEP)).count();
            let images_ok = d
                .esgm()
                .get_entity_trajectory_structure("images")
                .ok()
                .and_then(|t| t.get_between(i64::MIN / 2, i64::MAX / 2).ok())
                .is_none_or(|all| {
                    all.iter().all(|s| s.structure == image((s.valid_time() - BASE) / STEP))
                });
            if broken > 0 || !images_ok {
                say(format!("intact robot_state broken {broken}, images ok {images_ok}"));
            } else {
                say(format!("intact robot_state {}", all.len()));
            }
        }
        let _ = bridge.kill();
        let _ = bridge.wait();
    }
}
