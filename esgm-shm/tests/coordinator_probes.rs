//! The probes of a hostile or careless local process against the coordinator, kept as
//! tests: it cannot be stalled (huge names, client churn, many nodes) or lied to
//! (another process's record). Unique domains; every wait has a deadline that fails
//! the test; durations are printed, never asserted.
// Test helpers: a failed expectation is a failed test with its message.
#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)]

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use esgm_core::TypeRegistry;
use esgm_shm::control::{
    ControlClient, ControlClientError, ControlError, Coordinator, Registry, Request, Response,
};
use esgm_shm::control::{ProcessSpec, ProcessStatus};
use esgm_shm::unique_domain;
use iceoryx2::prelude::{AllocationStrategy, NodeBuilder};

const DEADLINE: Duration = Duration::from_secs(10);

fn coordinator(domain: &str) -> esgm_shm::control::CoordinatorThread {
    Coordinator::spawn(domain, Registry::new(TypeRegistry::with_library())).unwrap()
}

fn ping(domain: &str) -> Duration {
    let started = Instant::now();
    let c = ControlClient::connect(domain, DEADLINE).unwrap();
    assert!(matches!(c.call(&Request::Ping).unwrap(), Response::Pong { .. }));
    started.elapsed()
}

/// The most clients the churn of the next test makes. It runs until the steady client
/// is done; only a coordinator that serves nobody else while clients churn lets it get
/// this far.
const CHURN_CAP: usize = 200;

/// How many clients the churn makes while the steady client is being answered.
const CHURNED_MEANWHILE: usize = 5;

/// A churn once stalled the next ping for 1.8 s (iceoryx2 initialised a large list per
/// connecting client, on the coordinator's thread). The property, by order of events
/// rather than by a time limit: while one thread makes, pings and drops client after
/// client, another client is answered again and again, and the churn goes on while it
/// is. A coordinator that served the churn before the steady client (the steady ping
/// answered only once the churn ends at [`CHURN_CAP`]) or the steady client before the
/// churn (no churn progress until its deadline) fails. The stall itself, in time, is a
/// benchmark's to measure; durations here are printed, never asserted.
#[test]
fn another_client_is_served_while_clients_churn() {
    let d = unique_domain("probe-churn");
    let _c = coordinator(&d);
    let steady = ControlClient::connect(&d, DEADLINE).unwrap();
    let pong = |c: &ControlClient| {
        assert!(matches!(c.call(&Request::Ping).unwrap(), Response::Pong { .. }));
    };
    pong(&steady);

    let churned = Arc::new(AtomicUsize::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let churn = {
        let (d, churned, stop) = (d.clone(), Arc::clone(&churned), Arc::clone(&stop));
        std::thread::spawn(move || {
            let started = Instant::now();
            while !stop.load(Ordering::SeqCst) && churned.load(Ordering::SeqCst) < CHURN_CAP {
                let c = ControlClient::connect(&d, DEADLINE).unwrap();
                assert!(matches!(c.call(&Request::Ping).unwrap(), Response::Pong { .. }));
                drop(c);
                churned.fetch_add(1, Ordering::SeqCst);
            }
            started.elapsed()
        })
    };

    // The churn is under way (its first client made, pinged and dropped).
    let deadline = Instant::now() + Duration::from_secs(60);
    while churned.load(Ordering::SeqCst) == 0 {
        assert!(!churn.is_finished(), "the churn ended before its first client");
        assert!(Instant::now() < deadline, "the churn's first client was not answered");
        std::thread::sleep(Duration::from_millis(1));
    }

    // The steady client is answered while the churn goes on, until the churn has made
    // CHURNED_MEANWHILE more clients.
    let from = churned.load(Ordering::SeqCst);
    let mut answered_at = Vec::new();
    let steady_started = Instant::now();
    loop {
        pong(&steady);
        let now = churned.load(Ordering::SeqCst);
        answered_at.push(now);
        assert!(
            now < CHURN_CAP,
            "the steady client was answered only after the churn had made all its \
             {CHURN_CAP} clients: nobody else is served while clients churn"
        );
        if now >= from + CHURNED_MEANWHILE {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the churn made {} clients in 60 s while the steady client was answered \
             {} times: the churn is not served while another client is",
            now - from,
            answered_at.len()
        );
    }
    let steady_took = steady_started.elapsed();
    stop.store(true, Ordering::SeqCst);
    let churn_took = churn.join().unwrap();
    let total = churned.load(Ordering::SeqCst);
    // Answered during several of the churn's clients, not in one burst between two.
    let during = answered_at.iter().collect::<std::collections::BTreeSet<_>>().len();
    assert!(during > 1, "the steady client was answered only between two churned clients");
    eprintln!(
        "{} steady pings answered in {steady_took:?}, during {during} of the churn's \
         clients; the churn made {total} clients in {churn_took:?}",
        answered_at.len()
    );
    // The next call answers too.
    pong(&ControlClient::connect(&d, DEADLINE).unwrap());
}

#[test]
fn more_clients_than_iceoryx2s_default_node_limit_are_admitted() {
    let d = unique_domain("probe-nodes");
    let _c = coordinator(&d);
    // iceoryx2's default is 20 nodes per service; every client is a node.
    let clients: Vec<ControlClient> =
        (0..40).map(|_| ControlClient::connect(&d, DEADLINE).unwrap()).collect();
    for c in &clients {
        assert!(matches!(c.call(&Request::Ping).unwrap(), Response::Pong { .. }));
    }
}

#[test]
fn a_huge_unknown_name_is_refused_while_others_are_served() {
    let d = unique_domain("probe-names");
    let _c = coordinator(&d);
    let huge = "n".repeat(4 << 20);
    let asker = {
        let d = d.clone();
        std::thread::spawn(move || {
            let c = ControlClient::connect(&d, Duration::from_secs(30)).unwrap();
            let started = Instant::now();
            let answer = c.call(&Request::GetEntityStructureType { type_name: huge });
            (answer, started.elapsed())
        })
    };
    // Meanwhile another client is answered.
    let other = ping(&d);
    let (answer, took) = asker.join().unwrap();
    match answer {
        Err(ControlClientError::Remote(ControlError::TooLarge { bytes, .. })) => {
            assert!(bytes > 4 << 20);
        }
        other => panic!("a 4 MiB name must be refused as too large: {other:?}"),
    }
    // Within the request limit, a long name is refused by its length, before any
    // "did you mean" search.
    let c = ControlClient::connect(&d, DEADLINE).unwrap();
    let long = "m".repeat(200_000);
    let started = Instant::now();
    match c.call(&Request::GetEntityStructureType { type_name: long }) {
        Err(ControlClientError::Remote(ControlError::IllegalName { reason, .. })) => {
            assert!(
                matches!(reason, esgm_shm::control::NameRule::TooLong { len: 200_000, .. }),
                "{reason}"
            );
        }
        other => panic!("{other:?}"),
    }
    let long_took = started.elapsed();
    for bad in ["", "a/b", "has space"] {
        match c.call(&Request::GetEntityTrajectoryStructure { name: bad.into() }) {
            Err(ControlClientError::Remote(ControlError::IllegalName { .. })) => {}
            other => panic!("{bad:?}: {other:?}"),
        }
    }
    eprintln!(
        "4 MiB name refused in {took:?} (a ping meanwhile: {other:?}); 200 kB name in {long_took:?}"
    );
}

#[test]
fn a_request_in_another_protocol_is_named_a_protocol_mismatch() {
    let d = unique_domain("probe-protocol");
    let _c = coordinator(&d);
    let node = NodeBuilder::new()
        .config(esgm_shm::iceoryx2_config())
        .create::<esgm_shm::ShmService>()
        .unwrap();
    let service = node
        .service_builder(&esgm_shm::unstable::control_service(&d).unwrap())
        .request_response::<[u8], [u8]>()
        .max_active_requests_per_client(4)
        .open()
        .unwrap();
    let client = service
        .client_builder()
        .initial_max_slice_len(4096)
        .allocation_strategy(AllocationStrategy::PowerOfTwo)
        .create()
        .unwrap();
    // A request of a future esgm version.
    let bytes = br#"{"TeleportRobot":{"to":"mars"}}"#;
    let pending =
        client.loan_slice_uninit(bytes.len()).unwrap().write_from_slice(bytes).send().unwrap();
    let deadline = Instant::now() + DEADLINE;
    let answer = loop {
        if let Some(a) = pending.receive().unwrap() {
            break esgm_shm::control::decode::<Response>(a.payload()).unwrap();
        }
        assert!(Instant::now() < deadline, "no answer within {DEADLINE:?}");
        std::thread::sleep(Duration::from_millis(1));
    };
    match answer {
        Response::Error(ControlError::ProtocolMismatch { coordinator_version, reason }) => {
            assert_eq!(coordinator_version, env!("CARGO_PKG_VERSION"));
            assert!(reason.contains("TeleportRobot"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

/// The child half of the next test: run in another process, it tries to set a
/// process's pid to 1 (which once made `esgm down` wait for init).
#[test]
fn report_from_another_process_child() {
    let Ok(d) = std::env::var("ESGM_PROBE_DOMAIN") else { return };
    let c = ControlClient::connect(&d, DEADLINE).unwrap();
    let forged = Request::ReportProcess {
        name: "cam".into(),
        status: ProcessStatus { pid: Some(1), restarts: 0, last_exit: None },
    };
    match c.call(&forged) {
        Err(ControlClientError::Remote(ControlError::NotAllowed { .. })) => {}
        other => panic!("a forged report must be refused: {other:?}"),
    }
    // Reporting on itself is allowed.
    let own = Request::ReportProcess {
        name: "cam".into(),
        status: ProcessStatus { pid: Some(std::process::id()), restarts: 0, last_exit: None },
    };
    c.call(&own).unwrap();
}

#[test]
fn a_process_cannot_rewrite_another_ones_pid() {
    let d = unique_domain("probe-report");
    let _c = coordinator(&d);
    let c = ControlClient::connect(&d, DEADLINE).unwrap();
    let spec =
        ProcessSpec { name: "cam".into(), program: "true".into(), args: vec![], env: vec![] };
    c.call(&Request::DeclareProcess { spec }).unwrap();
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "report_from_another_process_child", "--nocapture"])
        .env("ESGM_PROBE_DOMAIN", &d)
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            panic!("the child probe did not finish");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(status.success(), "the child probe failed");
    let Response::Processes(list) = c.call(&Request::ListProcesses).unwrap() else {
        panic!("no process list")
    };
    let pid = list[0].status.pid;
    assert_eq!(pid, Some(child.id()), "only the child's report on itself counted");
}
