//! What the bridge tests share: coordinators in unique domains, bridge processes with
//! a watchdog on every wait, and free loopback ports.

// Test helpers outside #[test] fns: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use esgm_core::TypeRegistry;
use esgm_shm::ShmEsgm;
use esgm_shm::control::{Coordinator, CoordinatorThread, Registry};

pub const BRIDGE: &str = env!("CARGO_BIN_EXE_esgm-bridge");

/// One bridge system at a time: each test starts two coordinators and two bridges,
/// and a 2-core machine running several at once would measure the machine.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

pub fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A domain served by a coordinator on a thread of the test, and the test's own
/// connection to it.
pub struct Domain {
    pub name: String,
    pub esgm: Option<ShmEsgm>,
    _coordinator: CoordinatorThread,
}

impl Domain {
    pub fn start(prefix: &str) -> Domain {
        Self::named(&esgm_shm::unique_domain(prefix))
    }

    pub fn named(name: &str) -> Domain {
        let name = name.to_owned();
        let coordinator = Coordinator::spawn(&name, Registry::new(TypeRegistry::with_library()))
            .expect("start a coordinator");
        let esgm = ShmEsgm::builder()
            .domain(&name)
            .host(format!("test-{}", std::process::id()))
            .connect()
            .expect("connect to the coordinator");
        Domain { name, esgm: Some(esgm), _coordinator: coordinator }
    }

    pub fn esgm(&self) -> &ShmEsgm {
        self.esgm.as_ref().unwrap()
    }
}

impl Drop for Domain {
    fn drop(&mut self) {
        // The connection first, then the coordinator.
        self.esgm.take();
        // The domain ends here: the words a killed bridge kept counted go with it, as
        // at `esgm down`.
        esgm_shm::process::remove_domain_files(&self.name);
        // And the Zenoh segments of the bridges the test killed.
        zenoh::shm::cleanup_orphaned_shm_segments();
    }
}

/// A free TCP port on loopback.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// A running `esgm-bridge`, killed when dropped.
pub struct Bridge {
    pub child: Child,
    lines: mpsc::Receiver<String>,
    pub stderr: Arc<Mutex<String>>,
    pub args: Vec<String>,
}

impl Bridge {
    /// Starts `esgm-bridge --domain <domain> <args…> --report-every 100ms` and waits for
    /// its ready line.
    pub fn start(domain: &str, args: &[&str]) -> Bridge {
        Self::start_with(Command::new(BRIDGE), domain, args)
    }

    /// As [`Bridge::start`], through `command` (e.g. `ip netns exec … esgm-bridge`).
    pub fn start_with(mut command: Command, domain: &str, args: &[&str]) -> Bridge {
        let mut all: Vec<String> = vec!["--domain".into(), domain.into()];
        all.extend(args.iter().map(|s| (*s).to_owned()));
        all.extend(["--report-every".into(), "100ms".into()]);
        let mut child = command
            .args(&all)
            .env(
                "RUST_LOG",
                std::env::var("BRIDGE_LOG").unwrap_or_else(|_| "esgm_bridge=info,warn".into()),
            )
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("run esgm-bridge");
        let (tx, lines) = mpsc::channel();
        let stdout = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        let stderr = Arc::new(Mutex::new(String::new()));
        let err = child.stderr.take().unwrap();
        let keep = Arc::clone(&stderr);
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                let mut s = keep.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
        });
        let mut bridge = Bridge { child, lines, stderr, args: all };
        bridge.wait_line(Duration::from_secs(30), |l| l.starts_with("esgm-bridge: domain"));
        bridge
    }

    /// Waits for a stdout line `accept` takes; fails the test after `limit`.
    pub fn wait_line(&mut self, limit: Duration, accept: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + limit;
        let mut recent = std::collections::VecDeque::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left.min(Duration::from_millis(200))) {
                Ok(line) if accept(&line) => return line,
                Ok(line) => {
                    if recent.len() == 4 {
                        recent.pop_front();
                    }
                    recent.push_back(line);
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(Duration::from_millis(100));
                    panic!(
                        "esgm-bridge {:?} ended; stderr:\n{}",
                        self.args,
                        self.stderr.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
                    );
                }
            }
            if Instant::now() >= deadline {
                panic!(
                    "esgm-bridge {:?}: no expected line within {limit:?}; last lines:\n{}\nstderr:\n{}",
                    self.args,
                    Vec::from(recent).join("\n"),
                    self.stderr.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
                );
            }
        }
    }

    /// Waits until the bridge reports counters of `role`/`trajectory` that `accept`
    /// takes; returns them.
    pub fn wait_counters(
        &mut self,
        role: &str,
        trajectory: &str,
        limit: Duration,
        accept: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let line = self.wait_line(limit, |l| {
            serde_json::from_str::<serde_json::Value>(l)
                .is_ok_and(|v| v["role"] == role && v["trajectory"] == trajectory && accept(&v))
        });
        serde_json::from_str(&line).unwrap()
    }

    /// The last counters of `role`/`trajectory` reported within `limit`.
    pub fn counters(&mut self, role: &str, trajectory: &str) -> serde_json::Value {
        self.wait_counters(role, trajectory, Duration::from_secs(10), |_| true)
    }

    /// `kill -9`.
    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    pub fn stderr(&self) -> String {
        self.stderr.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone()
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        self.kill9();
        if std::thread::panicking() {
            eprintln!("--- esgm-bridge {:?} stderr:\n{}", self.args, self.stderr());
        }
    }
}

/// Polls `f` until it returns `Some`, failing the test with `what` after `limit`.
pub fn eventually<T>(limit: Duration, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(t) = f() {
            return t;
        }
        if Instant::now() >= deadline {
            panic!("{what}: not within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The output of a command run under a watchdog.
pub struct Output {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

/// Runs `command`, killing it (and failing the test) after `limit`.
pub fn run(mut command: Command, limit: Duration) -> Output {
    use std::io::Read as _;
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run a command");
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let reading = std::thread::spawn(move || {
        let (mut o, mut e) = (String::new(), String::new());
        let _ = out.read_to_string(&mut o);
        let _ = err.read_to_string(&mut e);
        (o, e)
    });
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{command:?} did not finish within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let (stdout, stderr) = reading.join().unwrap();
    Output { code: status.code(), stdout, stderr }
}
