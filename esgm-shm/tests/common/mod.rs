//! Helpers shared by the esgm-shm integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use std::time::Duration;

use esgm_core::codec::{ArchivedEntityStructure, ArchivedValue};
use esgm_core::library::{Image, RobotState};
use esgm_core::{Entity, EntityStructure};
use esgm_shm::unstable::data_service_name;
use esgm_shm::{Block16, unstable::blocks_for};
use esgm_shm::{SampleHeader, ShmNode, type_id};
use iceoryx2::prelude::ServiceName;
use iceoryx2::prelude::{LogLevel, NodeBuilder, set_log_level};

/// Every wait in the tests: long enough for a loaded CI machine, short enough that a
/// lost sample fails the test instead of hanging it.
pub const TIMEOUT: Duration = Duration::from_secs(10);

/// A coordinator on a thread of this test process, in a domain of its own, which
/// ends when it is dropped ([`TestDomain`]).
pub fn coordinator(prefix: &str) -> TestDomain {
    node(); // quiet iceoryx2's config warning
    let domain = esgm_shm::unique_domain(prefix);
    let registry = esgm_shm::control::Registry::new(esgm_core::TypeRegistry::with_library());
    let coordinator =
        esgm_shm::control::Coordinator::spawn(&domain, registry).expect("start a coordinator");
    TestDomain { coordinator: Some(coordinator), domain }
}

/// A test's domain: its coordinator, and when dropped, the domain's end, as `esgm
/// down` ends it. A process the test killed stays counted as a user of the futex words
/// it mapped, and kept histories outlive their writers by design: without the end,
/// their files would stay in `/dev/shm` after the test.
pub struct TestDomain {
    coordinator: Option<esgm_shm::control::CoordinatorThread>,
    domain: String,
}

impl std::ops::Deref for TestDomain {
    type Target = esgm_shm::control::CoordinatorThread;

    fn deref(&self) -> &Self::Target {
        self.coordinator.as_ref().expect("the coordinator runs until the domain ends")
    }
}

impl Drop for TestDomain {
    fn drop(&mut self) {
        // The coordinator stops first; then the domain ends.
        drop(self.coordinator.take());
        esgm_shm::process::remove_domain_files(&self.domain);
    }
}

/// Polls `cond` until it holds or [`TIMEOUT`] passes; returns whether it held (the
/// test asserts on it, so a runtime that never gets there fails instead of hanging).
pub fn wait_for(mut cond: impl FnMut() -> bool) -> bool {
    let deadline = std::time::Instant::now() + TIMEOUT;
    while std::time::Instant::now() < deadline {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    cond()
}

pub fn node() -> ShmNode {
    // iceoryx2 warns that no config file exists; the defaults are what the tests want.
    set_log_level(LogLevel::Error);
    NodeBuilder::new()
        .config(esgm_shm::iceoryx2_config())
        .create::<esgm_shm::ShmService>()
        .expect("iceoryx2 node")
}

pub fn robot(i: i64) -> EntityStructure {
    RobotState { x: i as f64, y: 2.0 * i as f64, dir: 90.0 }.to_structure(
        "robot1",
        1_000 + i,
        2_000 + i,
    )
}

/// A pixel pattern that differs per frame and per position.
pub fn pixel(frame: u64, i: usize) -> u8 {
    (i as u64).wrapping_mul(31).wrapping_add(frame.wrapping_mul(7)) as u8
}

pub fn fill(pixels: &mut [u8], frame: u64) {
    for (i, p) in pixels.iter_mut().enumerate() {
        *p = pixel(frame, i);
    }
}

pub fn check_pattern(pixels: &[u8], frame: u64) {
    let bad = pixels.iter().enumerate().find(|(i, p)| **p != pixel(frame, *i));
    assert!(bad.is_none(), "pixel {bad:?} differs from frame {frame}'s pattern");
}

pub fn value<'a>(a: &'a ArchivedEntityStructure, name: &str) -> &'a ArchivedValue {
    &a.attributes
        .iter()
        .find(|p| p.name.as_str() == name)
        .unwrap_or_else(|| panic!("no attribute {name}"))
        .value
}

pub fn long(a: &ArchivedEntityStructure, name: &str) -> i64 {
    match value(a, name) {
        ArchivedValue::Long(v) => v.to_native(),
        other => panic!("{name} is {other:?}"),
    }
}

pub fn octets<'a>(a: &'a ArchivedEntityStructure, name: &str) -> &'a [u8] {
    match value(a, name) {
        ArchivedValue::OctetSeq(o) => o.as_slice(),
        other => panic!("{name} is {other:?}"),
    }
}

/// Width, height, format and pixels of an archived `Image`, read in place.
pub fn image(a: &ArchivedEntityStructure) -> (i64, i64, i64, &[u8]) {
    (long(a, "width"), long(a, "height"), long(a, "format"), octets(a, "image_data"))
}

pub const RGB8: i64 = Image::FORMAT_RGB8;

/// Re-runs this test binary as a child process that runs only the test `role_test`,
/// with `role_env=role` and `domain_env=domain` set (the child's role and its
/// iceoryx2 domain). Output is kept for the failure message.
pub fn spawn_child(
    role_test: &str,
    (role_env, role): (&str, &str),
    (domain_env, domain): (&str, &str),
) -> std::process::Child {
    use std::process::{Command, Stdio};
    let exe = std::env::current_exe().expect("test binary path");
    Command::new(exe)
        .args(["--exact", role_test, "--nocapture", "--test-threads=1"])
        .env(role_env, role)
        .env(domain_env, domain)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn the child process")
}

/// Waits for the child, killing it if it outlives `timeout`; returns its status and
/// output.
pub fn reap(
    mut child: std::process::Child,
    timeout: Duration,
) -> (std::process::ExitStatus, String) {
    use std::io::Read;
    let deadline = std::time::Instant::now() + timeout;
    loop {
        if let Some(status) = child.try_wait().expect("child status") {
            let mut output = String::new();
            if let Some(mut out) = child.stdout.take() {
                let _ = out.read_to_string(&mut output);
            }
            if let Some(mut err) = child.stderr.take() {
                let _ = err.read_to_string(&mut output);
            }
            return (status, output);
        }
        if std::time::Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("child process did not finish within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Raw iceoryx2 access to a trajectory's data service, to write what esgm never would.
pub struct RawPublisher {
    port: iceoryx2::port::publisher::Publisher<esgm_shm::ShmService, [Block16], SampleHeader>,
}

impl RawPublisher {
    /// Opens a publisher on a trajectory's existing data service.
    pub fn new(node: &esgm_shm::ShmNode, domain: &str, trajectory: &str) -> Self {
        Self::try_open(node, domain, trajectory).unwrap()
    }

    /// Opens a publisher on a trajectory's existing data service, or says why not.
    pub fn try_open(
        node: &esgm_shm::ShmNode,
        domain: &str,
        trajectory: &str,
    ) -> Result<Self, String> {
        let name = ServiceName::new(&data_service_name(domain, trajectory)).unwrap();
        let service = node
            .service_builder(&name)
            .publish_subscribe::<[Block16]>()
            .user_header::<SampleHeader>()
            .max_publishers(1)
            .open()
            .map_err(|e| format!("{e:?}"))?;
        let port = service
            .publisher_builder()
            .initial_max_slice_len(4096)
            .create()
            .map_err(|e| format!("{e:?}"))?;
        Ok(Self { port })
    }

    /// Creates the data service before esgm does, with room for more publishers and
    /// everything esgm's writer and readers ask of it: a process that comes first.
    pub fn create_first(node: &esgm_shm::ShmNode, domain: &str, trajectory: &str) -> Self {
        let name = ServiceName::new(&data_service_name(domain, trajectory)).unwrap();
        let service = node
            .service_builder(&name)
            .publish_subscribe::<[Block16]>()
            .user_header::<SampleHeader>()
            .history_size(4096)
            .subscriber_max_buffer_size(4096)
            .subscriber_max_borrowed_samples(4096)
            .max_publishers(4)
            .max_subscribers(16)
            .max_nodes(32)
            .enable_safe_overflow(true)
            .create()
            .unwrap();
        let port = service.publisher_builder().initial_max_slice_len(4096).create().unwrap();
        Self { port }
    }

    /// This port's id, as a writer would register it.
    pub fn id(&self) -> u128 {
        self.port.id().value()
    }

    /// Sends a well-formed structure with a header that matches it.
    pub fn send_structure(&self, es: &EntityStructure, type_name: &str, sequence: u64) {
        let bytes = esgm_core::codec::encode(es).unwrap();
        let header = SampleHeader {
            valid_time: es.valid_time,
            create_time: es.create_time,
            archive_len: bytes.len() as u64,
            type_id: type_id(type_name),
            kind: SampleHeader::KIND_STRUCTURE,
            sequence,
            ..SampleHeader::default()
        };
        self.send(&bytes, header);
    }

    /// Sends a reset marker, as a writer's reset would.
    pub fn send_reset(&self, type_name: &str, sequence: u64) {
        let header = SampleHeader {
            type_id: type_id(type_name),
            kind: SampleHeader::KIND_RESET,
            sequence,
            ..SampleHeader::default()
        };
        self.send(&[0; 16], header);
    }

    pub fn send(&self, payload: &[u8], header: SampleHeader) {
        let mut blocks = vec![Block16::default(); blocks_for(payload.len()).max(1)];
        bytemuck::cast_slice_mut::<Block16, u8>(&mut blocks)[..payload.len()]
            .copy_from_slice(payload);
        let mut sample =
            self.port.loan_slice_uninit(blocks.len()).unwrap().write_from_slice(&blocks);
        *sample.user_header_mut() = header;
        sample.send().unwrap();
    }
}

pub fn header_for(payload_len: usize, valid_time: i64, create_time: i64) -> SampleHeader {
    SampleHeader {
        valid_time,
        create_time,
        archive_len: payload_len as u64,
        type_id: type_id("RobotState"),
        kind: SampleHeader::KIND_STRUCTURE,
        ..SampleHeader::default()
    }
}

/// A connection to the coordinator `c` as the process `host` (two of them in one test
/// are two "processes" of the registry, each with its own ports and runtime).
pub fn location(c: &esgm_shm::control::CoordinatorThread, host: &str) -> esgm_shm::ShmEsgm {
    esgm_shm::ShmEsgm::builder().domain(c.domain()).host(host).connect().unwrap()
}

/// A RobotState valid (and created) at `vt` with `x`.
pub fn state(vt: esgm_core::Time, x: f64) -> EntityStructure {
    EntityStructure::new("robot1", vt, vt).with("x", x).with("y", 0.0).with("dir", 0.0)
}

/// The `x` of a RobotState sample.
pub fn x(s: &esgm_core::Sample) -> f64 {
    s.structure.get("x").and_then(|v| v.as_double()).unwrap()
}
