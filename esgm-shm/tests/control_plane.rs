//! The control plane end to end: a coordinator on its own thread (its own node), a
//! client on the test thread; unique domains, deadlines on every wait.
// Test helpers: a failed expectation is a failed test with its message.
#![allow(clippy::expect_used, clippy::unwrap_used, clippy::panic)]

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use esgm_core::esgm::{CreateError, TrajectorySpec};
use esgm_core::{EntityStructureType, TypeRegistry, ValueSort};
use esgm_shm::control::{
    ControlClient, ControlClientError, ControlError, Coordinator, Registry, Request, Response,
};
use esgm_shm::unique_domain;

const DEADLINE: Duration = Duration::from_secs(10);

/// Runs a coordinator for `domain` until the returned guard is dropped.
struct Running {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn start(domain: &str) -> Running {
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let d = domain.to_owned();
    let s = Arc::clone(&stop);
    let thread = std::thread::spawn(move || {
        let mut c = Coordinator::create(&d, Registry::new(TypeRegistry::with_library()))
            .expect("coordinator starts");
        ready_tx.send(()).expect("test is waiting");
        c.run(&s, Duration::from_secs(1)).expect("coordinator serves");
    });
    ready_rx.recv_timeout(DEADLINE).expect("coordinator ready in time");
    Running { stop, thread: Some(thread) }
}

/// A coordinator that saves its registry in a scratch directory (kept while the first
/// value lives), and a client of it.
fn saving(
    prefix: &str,
) -> (
    tempfile::TempDir,
    esgm_shm::control::StateDir,
    esgm_shm::control::CoordinatorThread,
    ControlClient,
) {
    let domain = unique_domain(prefix);
    let dir = tempfile::tempdir().unwrap();
    let state = esgm_shm::control::StateDir::at(dir.path());
    let (coordinator, _) = Coordinator::spawn_recovering(
        &domain,
        TypeRegistry::with_library(),
        state.clone(),
        esgm_shm::DomainLimits::default(),
    )
    .unwrap();
    let client = ControlClient::connect(&domain, DEADLINE).unwrap();
    (dir, state, coordinator, client)
}

#[test]
fn seed_operations_and_errors_cross_the_process_boundary() {
    let domain = unique_domain("control_ops");
    let _coordinator = start(&domain);
    let client = ControlClient::connect(&domain, DEADLINE).unwrap();

    assert!(matches!(client.call(&Request::Ping).unwrap(), Response::Pong { .. }));
    let t = EntityStructureType::new("Reading").attr("x", ValueSort::Double);
    client
        .call(&Request::CreateEntityStructureType { type_name: "Reading".into(), entity_type: t })
        .unwrap();
    let spec = TrajectorySpec::primitive("readings", "Reading");
    match client.call(&Request::CreateTrajectory { spec, host: "test".into() }).unwrap() {
        Response::Trajectory(r) => {
            assert_eq!((r.writer.as_str(), r.info.type_name.as_str()), ("test", "Reading"))
        }
        other => panic!("{other:?}"),
    }
    // The seed's error, typed, with the suggestion, from the other side.
    let err =
        client.call(&Request::GetEntityTrajectoryStructure { name: "reading".into() }).unwrap_err();
    assert_eq!(
        err.to_string(),
        "no entity trajectory structure `reading`; did you mean `readings`?"
    );
    let err = client
        .call(&Request::CreateTrajectory {
            spec: TrajectorySpec::primitive("x", "Readin"),
            host: "t".into(),
        })
        .unwrap_err();
    assert!(matches!(
        err,
        ControlClientError::Remote(ControlError::Create(
            CreateError::NoSuchEntityStructureType { .. }
        ))
    ));
    match client.call(&Request::ListTrajectories).unwrap() {
        Response::Trajectories(v) => assert_eq!(v.len(), 1),
        other => panic!("{other:?}"),
    }
}

#[test]
fn no_coordinator_is_a_clear_error() {
    let domain = unique_domain("control_none");
    let err = ControlClient::connect(&domain, Duration::from_millis(200)).unwrap_err();
    assert!(matches!(err, ControlClientError::NoCoordinator { .. }), "{err}");
    assert!(err.to_string().contains("esgm up"));
    // One line for a user, in esgm's words: no iceoryx2 type names.
    assert!(!err.to_string().contains("RequestResponse"), "{err}");
    assert!(std::error::Error::source(&err).is_none(), "{err}");
}

#[test]
fn a_second_coordinator_for_the_same_domain_is_refused() {
    let domain = unique_domain("control_twice");
    let _first = start(&domain);
    let second = Coordinator::create(&domain, Registry::default());
    assert!(second.is_err());
}

/// A change the coordinator cannot save is undone and refused, never acknowledged and
/// then lost in a crash; the failure is counted and shown in the answer to a ping
/// (`esgm ps`), and the next change that can be saved is saved (issue 24).
#[test]
fn a_change_that_cannot_be_saved_is_undone_refused_and_counted() {
    let (dir, state, _coordinator, client) = saving("control_unsaved");
    let create = |name: &str| Request::CreateEntityStructureType {
        type_name: name.into(),
        entity_type: EntityStructureType::new(name).attr("x", ValueSort::Double),
    };
    let get = |name: &str| Request::GetEntityStructureType { type_name: name.into() };
    let saves = |client: &ControlClient| match client.call(&Request::Ping).unwrap() {
        Response::Pong { saves, .. } => saves,
        other => panic!("{other:?}"),
    };
    client.call(&create("Saved")).unwrap();

    // Writing the registry's temporary file fails, for root too: it is a directory.
    let blocker = dir.path().join("registry.json.tmp");
    std::fs::create_dir(&blocker).unwrap();
    match client.call(&create("Unsaved")) {
        Err(ControlClientError::Remote(ControlError::NotSaved { reason })) => {
            assert!(reason.contains("registry.json.tmp"), "{reason}");
        }
        other => panic!("an unsaved change must be refused: {other:?}"),
    }
    assert!(
        matches!(
            client.call(&get("Unsaved")),
            Err(ControlClientError::Remote(ControlError::Type(_)))
        ),
        "the refused change was undone"
    );
    assert!(matches!(client.call(&get("Saved")).unwrap(), Response::Type(_)));
    let health = saves(&client);
    assert_eq!(health.failures, 1);
    assert!(health.failing.is_some());

    std::fs::remove_dir(&blocker).unwrap();
    client.call(&create("Later")).unwrap();
    let health = saves(&client);
    assert_eq!((health.failures, health.failing), (1, None));
    let on_disk = state.load().unwrap().expect("a saved registry");
    let names: Vec<&str> = on_disk.types.iter().map(|(n, _)| n.as_str()).collect();
    assert!(names.contains(&"Saved") && names.contains(&"Later"), "{names:?}");
    assert!(!names.contains(&"Unsaved"), "{names:?}");
}

/// The system-wide calls of the `Esgm` interface fail when the coordinator does not
/// answer, instead of listing this process's own view as if it were the system's
/// (issue 24: a listing that looks complete and is not).
#[test]
fn system_calls_without_a_coordinator_are_errors_not_a_partial_view() {
    use esgm_core::Esgm;
    use esgm_core::SystemError;

    let domain = unique_domain("control_gone");
    let coordinator =
        Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library())).unwrap();
    let esgm = esgm_shm::ShmEsgm::builder()
        .domain(&domain)
        .timeout(Duration::from_secs(2))
        .connect()
        .unwrap();
    esgm.create_trajectory(TrajectorySpec::primitive("mine", "RobotState")).unwrap();
    assert_eq!(esgm.trajectories().unwrap().len(), 1);
    drop(coordinator);

    // This process still holds `mine`: a fallback would list it and look complete.
    let unavailable = |r: Result<usize, SystemError>, what: &str| match r {
        Err(SystemError::Unavailable { operation, .. }) => assert!(operation.contains(what)),
        other => panic!("{what}: {other:?}"),
    };
    unavailable(esgm.trajectories().map(|t| t.len()), "trajectories");
    unavailable(esgm.sensors().map(|s| s.len()), "sensors");
    unavailable(esgm.comp_units().map(|u| u.len()), "units");
    unavailable(esgm.entity_structure_type_names().map(|n| n.len()), "types");
}

/// The coordinator keeps the encoded listing between changes of the registry: each
/// change, made or undone because it could not be saved, shows in the next listing.
#[test]
fn every_listing_shows_the_registry_as_it_stands() {
    let (dir, _state, _coordinator, client) = saving("control_listing");
    let listed = || match client.call(&Request::ListTrajectories).unwrap() {
        Response::Trajectories(t) => t.into_iter().map(|i| i.name).collect::<Vec<_>>(),
        other => panic!("{other:?}"),
    };
    let create = |name: &str| Request::CreateTrajectory {
        spec: TrajectorySpec::primitive(name, "RobotState"),
        host: "test".into(),
    };
    assert!(listed().is_empty());
    client.call(&create("a")).unwrap();
    assert_eq!(listed(), ["a"]);
    assert_eq!(listed(), ["a"], "asked again, unchanged");
    client.call(&create("b")).unwrap();
    assert_eq!(listed(), ["a", "b"]);

    let blocker = dir.path().join("registry.json.tmp");
    std::fs::create_dir(&blocker).unwrap();
    assert!(client.call(&create("c")).is_err(), "an unsaved change is refused");
    assert_eq!(listed(), ["a", "b"], "the undone change is not listed");
    std::fs::remove_dir(&blocker).unwrap();

    client.call(&Request::DestroyEntityTrajectoryStructure { name: "a".into() }).unwrap();
    assert_eq!(listed(), ["b"]);
}
