//! esgm-view against a real WebSocket client speaking Foxglove's protocol
//! (subprotocol `foxglove.sdk.v1`, the SDK's name for the v1 protocol): channels advertised for a domain's trajectories, a
//! subscription delivering an image at its valid time, decoded to its width, height and
//! first pixel, and an unsubscription stopping the flow. Every wait has a deadline.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::net::TcpStream;
use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectorySpec;
use esgm_core::library::{Image, RobotState};
use esgm_core::{Entity, EntityTrajectoryStructure, Esgm, TypeRegistry};
use esgm_view::ViewServer;
use serde_json::{Value, json};
use tungstenite::client::IntoClientRequest;
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

const DEADLINE: Duration = Duration::from_secs(30);

type Socket = WebSocket<MaybeTlsStream<TcpStream>>;

fn connect(port: u16) -> Socket {
    let mut request = format!("ws://127.0.0.1:{port}").into_client_request().unwrap();
    request.headers_mut().insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (mut socket, response) = tungstenite::connect(request).unwrap();
    assert_eq!(
        response.headers().get("Sec-WebSocket-Protocol").map(|v| v.to_str().unwrap()),
        Some("foxglove.sdk.v1")
    );
    if let MaybeTlsStream::Plain(s) = socket.get_mut() {
        s.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    }
    socket
}

/// The next message, or `None` after a read timeout.
fn next(socket: &mut Socket) -> Option<Message> {
    match socket.read() {
        Ok(m) => Some(m),
        Err(tungstenite::Error::Io(e))
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            None
        }
        Err(e) => panic!("websocket: {e}"),
    }
}

fn send(socket: &mut Socket, v: Value) {
    socket.send(Message::text(v.to_string())).unwrap();
}

/// Reads until the channel of `topic` is advertised (or finds it in `seen`, the
/// advertisements read so far); returns its advertisement.
fn advertised(socket: &mut Socket, seen: &mut Vec<Value>, topic: &str) -> Value {
    let deadline = Instant::now() + DEADLINE;
    loop {
        if let Some(c) = seen.iter().find(|c| c["topic"] == topic) {
            return c.clone();
        }
        assert!(Instant::now() < deadline, "`{topic}` was not advertised within {DEADLINE:?}");
        if let Some(Message::Text(t)) = next(socket) {
            let v: Value = serde_json::from_str(&t).unwrap();
            if v["op"] == "advertise" {
                seen.extend(v["channels"].as_array().unwrap().iter().cloned());
            }
        }
    }
}

/// A message data frame (opcode 1): subscription id, log time, payload.
fn message_data(socket: &mut Socket, subscription: u32, also: &mut dyn FnMut()) -> (u64, Vec<u8>) {
    let deadline = Instant::now() + DEADLINE;
    while Instant::now() < deadline {
        also();
        if let Some(Message::Binary(b)) = next(socket)
            && b.first() == Some(&1)
            && b.len() >= 13
        {
            let id = u32::from_le_bytes(b[1..5].try_into().unwrap());
            let time = u64::from_le_bytes(b[5..13].try_into().unwrap());
            if id == subscription {
                return (time, b[13..].to_vec());
            }
        }
    }
    panic!("no message for subscription {subscription} within {DEADLINE:?}");
}

fn wait_until(what: &str, mut f: impl FnMut() -> bool) {
    let deadline = Instant::now() + DEADLINE;
    while !f() {
        assert!(Instant::now() < deadline, "{what} did not happen within {DEADLINE:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn foxglove_client_subscribes_receives_an_image_and_unsubscribes() {
    let domain = esgm_shm::unique_domain("view");
    let registry = esgm_shm::control::Registry::new(TypeRegistry::with_library());
    let _coordinator = esgm_shm::control::Coordinator::spawn(&domain, registry).unwrap();
    let writer = esgm_shm::ShmEsgm::builder().domain(&domain).connect().unwrap();
    let camera = writer.create_trajectory(TrajectorySpec::primitive("camera", "Image")).unwrap();
    let robot = writer.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();

    let server = ViewServer::builder(&domain).port(0).start().unwrap();
    let mut socket = connect(server.port());
    let mut seen = Vec::new();
    let cam = advertised(&mut socket, &mut seen, "/camera");
    assert_eq!(cam["schemaName"], "foxglove.RawImage");
    assert_eq!(cam["encoding"], "protobuf");
    let rob = advertised(&mut socket, &mut seen, "/robot");
    assert_eq!(
        (rob["encoding"].as_str(), rob["schemaEncoding"].as_str()),
        (Some("json"), Some("jsonschema"))
    );
    let schema: Value = serde_json::from_str(rob["schema"].as_str().unwrap()).unwrap();
    assert_eq!(schema["properties"]["x"]["type"], json!(["number", "null"]), "plottable");
    assert!(server.forwarding().is_empty(), "nothing flows before a subscription");

    // Images keep coming: 4×2 rgb8, the first pixel (i, 20, 30), valid at t0 + i ms.
    let t0 = 1_700_000_000_000_000_000_i64;
    let mut i = 0_i64;
    let mut add_image = || {
        let mut pixels = vec![0_u8; 4 * 2 * 3];
        pixels[..3].copy_from_slice(&[i as u8, 20, 30]);
        let t = t0 + i * 1_000_000;
        let im =
            Image { width: 4, height: 2, format: Image::FORMAT_RGB8, image_data: pixels.into() };
        camera.add(im.to_structure("cam", t, t)).unwrap();
        i += 1;
    };
    add_image();
    send(
        &mut socket,
        json!({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": cam["id"]}]}),
    );
    let (time, payload) = message_data(&mut socket, 7, &mut || {});
    let image = esgm_recording::view::decode_raw_image(&payload).unwrap();
    assert_eq!((image.width, image.height, image.encoding), (4, 2, "rgb8"));
    assert_eq!(&image.data[1..3], &[20, 30], "the first pixel");
    let k = i64::from(image.data[0]);
    assert_eq!(time, (t0 + k * 1_000_000) as u64, "log time is the valid time");
    assert_eq!(image.timestamp_ns(), Some(t0 + k * 1_000_000));
    assert_eq!(server.forwarding(), ["camera"]);

    // A later image arrives as it is added.
    let (_, payload) = message_data(&mut socket, 7, &mut add_image);
    assert!(esgm_recording::view::decode_raw_image(&payload).unwrap().data[0] as i64 > k);

    // JSON of a structured type, at its valid time.
    send(
        &mut socket,
        json!({"op": "subscribe", "subscriptions": [{"id": 8, "channelId": rob["id"]}]}),
    );
    robot.add(RobotState { x: 1.5, y: -2.0, dir: 90.0 }.to_structure("r1", t0, t0)).unwrap();
    let (time, payload) = message_data(&mut socket, 8, &mut || {});
    let v: Value = serde_json::from_slice(&payload).unwrap();
    assert_eq!((v["x"].as_f64(), time), (Some(1.5), t0 as u64));

    // Unsubscribing stops the flow: no forwarder, and no more camera messages.
    send(&mut socket, json!({"op": "unsubscribe", "subscriptionIds": [7, 8]}));
    wait_until("forwarding stops", || server.forwarding().is_empty());
    let sent = server.sent();
    add_image();
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(server.sent(), sent, "an unwatched trajectory is not forwarded");

    // A trajectory destroyed is a channel removed; a new one is a channel added.
    drop(robot);
    writer.destroy_entity_trajectory_structure("robot").unwrap();
    wait_until("the robot channel closes", || server.channels() == ["camera"]);
    let _lidar =
        writer.create_trajectory(TrajectorySpec::primitive("later", "RobotState")).unwrap();
    advertised(&mut socket, &mut seen, "/later");
    drop(socket);

    // Dropping the server stops it: its port is closed.
    let port = server.port();
    drop(server);
    wait_until("the port closes", || std::net::TcpStream::connect(("127.0.0.1", port)).is_err());
}

/// A produced trajectory has a trace channel: each structure's inputs hop by hop, with
/// the end-to-end latency split by stage (issue 42), plottable in Foxglove.
#[test]
fn a_produced_trajectory_has_a_trace_channel_splitting_its_latency_by_stage() {
    let domain = esgm_shm::unique_domain("view-trace");
    let registry = esgm_shm::control::Registry::new(TypeRegistry::with_library());
    let _coordinator = esgm_shm::control::Coordinator::spawn(&domain, registry).unwrap();
    let writer = esgm_shm::ShmEsgm::builder().domain(&domain).connect().unwrap();
    let robot = writer.create_trajectory(TrajectorySpec::primitive("robot", "RobotState")).unwrap();
    let copy = |i: &[esgm_core::Sample], _: i64| Ok(i[0].structure.to_structure());
    let types = vec!["RobotState".into()];
    writer.add_comp_unit("copy", "RobotState", types.clone(), std::sync::Arc::new(copy)).unwrap();
    writer.create_trajectory(TrajectorySpec::computed("near", "copy", ["robot"])).unwrap();
    writer.create_trajectory(TrajectorySpec::computed("far", "copy", ["near"])).unwrap();

    let server = ViewServer::builder(&domain).port(0).start().unwrap();
    let mut socket = connect(server.port());
    let mut seen = Vec::new();
    let trace = advertised(&mut socket, &mut seen, "/far/trace");
    assert_eq!(
        (trace["schemaName"].as_str(), trace["encoding"].as_str()),
        (Some("esgm.Trace"), Some("json"))
    );
    advertised(&mut socket, &mut seen, "/far");
    assert!(
        !seen.iter().any(|c| c["topic"] == "/robot/trace"),
        "a pushed trajectory has no trace: {seen:?}"
    );
    send(
        &mut socket,
        json!({"op": "subscribe", "subscriptions": [{"id": 9, "channelId": trace["id"]}]}),
    );
    let t0 = 1_700_000_000_000_000_000_i64;
    let mut k = 0;
    let mut push = || {
        let t = t0 + k * 1_000_000;
        robot.add(RobotState { x: k as f64, y: 0.0, dir: 0.0 }.to_structure("r", t, t)).unwrap();
        k += 1;
    };
    // The first traces may find an input's history not yet here; a later one is whole.
    let deadline = Instant::now() + DEADLINE;
    let v = loop {
        let (time, payload) = message_data(&mut socket, 9, &mut push);
        let v: Value = serde_json::from_slice(&payload).unwrap();
        assert_eq!(v["valid_time"].as_u64(), Some(time), "log time is the valid time");
        if v["hops"].as_array().is_some_and(|h| h.len() == 3) && v["source"] == "robot" {
            break v;
        }
        assert!(Instant::now() < deadline, "no whole trace: {v:#}");
    };
    assert_eq!(v["trajectory"], "far");
    let hops: Vec<(&str, u64)> = v["hops"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| (h["trajectory"].as_str().unwrap(), h["depth"].as_u64().unwrap()))
        .collect();
    assert_eq!(hops, [("far", 0), ("near", 1), ("robot", 2)]);
    let stages = v["stages_ms"].as_object().unwrap();
    let (far, near) = (stages["far"].as_f64().unwrap(), stages["near"].as_f64().unwrap());
    let total = v["end_to_end_ms"].as_f64().unwrap();
    assert!(far >= 0.0 && near >= 0.0 && (far + near - total).abs() < 1e-6, "{v:#}");
    assert_eq!(server.forwarding(), ["far"]);
}
