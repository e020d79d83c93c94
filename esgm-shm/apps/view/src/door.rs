//! The server's front door: the address clients connect to, in front of the Foxglove
//! SDK's server, so that both names of the Foxglove WebSocket protocol are accepted.
//!
//! The protocol's spec and the clients written to it (Lichtblick, older Foxglove
//! Studio, `@foxglove/ws-protocol`'s client, foxglove_bridge's clients) ask for the
//! subprotocol `foxglove.websocket.v1`; the SDK's server (the `foxglove` crate) knows the
//! same protocol only as `foxglove.sdk.v1` (and its schema-table variant `v1.1`), and
//! answers any other name with HTTP 400. The two are the same protocol under two names
//! (Foxglove's stance, and Lichtblick's, which accepts both). The door reads each
//! connection's HTTP upgrade request, offers the SDK's name too where the client asked
//! for the spec's, forwards the request to the SDK's server (on loopback, a port of its
//! own), and names the spec's protocol back in the answer when that is what the client
//! asked for; then it relays the connection's bytes both ways untouched.
//!
//! Cost: one more loopback hop per message, which a viewer's frame rate does not see.

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use anyhow::Context as _;

/// The subprotocol of the protocol's spec and the clients written to it.
pub const SPEC_V1: &str = "foxglove.websocket.v1";
/// The same protocol as the SDK's server names it.
pub const SDK_V1: &str = "foxglove.sdk.v1";

/// The longest upgrade request or answer header read (browsers send a few KiB).
const MAX_HEADER: usize = 64 * 1024;

/// The door: a listener on the public address and a thread accepting on it. Dropping
/// it closes the address; connections already through end with the server.
pub struct Door {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    accepting: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Door {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Door").field("addr", &self.addr).finish()
    }
}

impl Door {
    /// Listens on `host:port` (0: a free port) and relays every connection to the SDK's
    /// server at `server`.
    pub fn open(host: &str, port: u16, server: SocketAddr) -> anyhow::Result<Self> {
        let listener = TcpListener::bind((host, port))
            .with_context(|| format!("cannot listen on {host}:{port}"))?;
        let addr = listener.local_addr().context("the address listened on")?;
        let stop = Arc::new(AtomicBool::new(false));
        let accepting = {
            let stop = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("esgm-view-door".into())
                .spawn(move || accept(&listener, server, &stop))
                .context("starting the door's thread")?
        };
        Ok(Self { addr, stop, accepting: Some(accepting) })
    }

    /// The port clients connect to.
    pub fn port(&self) -> u16 {
        self.addr.port()
    }
}

impl Drop for Door {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        // Wake the accepting thread: it sees `stop` and closes the listener.
        let local = match self.addr {
            SocketAddr::V4(a) if a.ip().is_unspecified() => {
                SocketAddr::from(([127, 0, 0, 1], a.port()))
            }
            SocketAddr::V6(a) if a.ip().is_unspecified() => {
                SocketAddr::from((std::net::Ipv6Addr::LOCALHOST, a.port()))
            }
            a => a,
        };
        let _woken = TcpStream::connect(local);
        if let Some(t) = self.accepting.take() {
            let _ = t.join();
        }
    }
}

fn accept(listener: &TcpListener, server: SocketAddr, stop: &AtomicBool) {
    for client in listener.incoming() {
        if stop.load(Ordering::SeqCst) {
            return;
        }
        let client = match client {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!(error = %e, "cannot accept a viewer's connection");
                continue;
            }
        };
        let spawned = std::thread::Builder::new().name("esgm-view-relay".into()).spawn(move || {
            let peer = client.peer_addr().ok();
            if let Err(e) = relay(client, server) {
                tracing::debug!(?peer, error = %e, "a viewer's connection ended");
            }
        });
        if let Err(e) = spawned {
            tracing::warn!(error = %e, "cannot serve a viewer's connection");
        }
    }
}

/// One connection: the upgrade request and its answer, with the subprotocol's name
/// translated where the client asked for the spec's; then the bytes both ways.
fn relay(mut client: TcpStream, server: SocketAddr) -> anyhow::Result<()> {
    client.set_nodelay(true)?;
    let (request, early) = read_header(&mut client).context("the client's request")?;
    let (request, renamed) = offer_sdk_name(&request);
    let mut upstream = TcpStream::connect(server).context("the server")?;
    upstream.set_nodelay(true)?;
    upstream.write_all(request.as_bytes())?;
    upstream.write_all(&early)?;
    let (answer, early) = read_header(&mut upstream).context("the server's answer")?;
    let answer = if renamed { name_spec_protocol(&answer) } else { answer };
    client.write_all(answer.as_bytes())?;
    client.write_all(&early)?;

    let (mut from_client, mut to_server) = (client.try_clone()?, upstream.try_clone()?);
    let upward = std::thread::Builder::new()
        .name("esgm-view-relay-up".into())
        .spawn(move || {
            let _ended = std::io::copy(&mut from_client, &mut to_server);
            let _ = to_server.shutdown(Shutdown::Both);
            let _ = from_client.shutdown(Shutdown::Both);
        })
        .context("starting the relay's second thread")?;
    let _ended = std::io::copy(&mut upstream, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = upstream.shutdown(Shutdown::Both);
    let _ = upward.join();
    Ok(())
}

/// Reads up to the end of an HTTP header (`\r\n\r\n`): the header as text, and what
/// came after it in the same reads.
fn read_header(stream: &mut TcpStream) -> anyhow::Result<(String, Vec<u8>)> {
    let mut buf = Vec::with_capacity(2048);
    let mut chunk = [0_u8; 2048];
    loop {
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            anyhow::bail!("closed before the end of the header");
        }
        buf.extend_from_slice(&chunk[..n]);
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            let header = String::from_utf8(buf).context("a header that is not UTF-8")?;
            return Ok((header, rest));
        }
        if buf.len() > MAX_HEADER {
            anyhow::bail!("a header longer than {MAX_HEADER} bytes");
        }
    }
}

fn is_protocol_line(line: &str) -> bool {
    line.split_once(':')
        .is_some_and(|(k, _)| k.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
}

/// The request with [`SDK_V1`] offered where the client offered [`SPEC_V1`] and no
/// name of the SDK's, and whether it was.
fn offer_sdk_name(request: &str) -> (String, bool) {
    let offered: Vec<&str> = request
        .split("\r\n")
        .filter(|l| is_protocol_line(l))
        .filter_map(|l| l.split_once(':').map(|(_, v)| v))
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let spec = offered.contains(&SPEC_V1);
    let sdk = offered.iter().any(|p| p.starts_with("foxglove.sdk."));
    if !spec || sdk {
        return (request.to_owned(), false);
    }
    let lines: Vec<String> = request
        .split("\r\n")
        .map(|l| if is_protocol_line(l) { format!("{l}, {SDK_V1}") } else { l.to_owned() })
        .collect();
    (lines.join("\r\n"), true)
}

/// The answer with the SDK's v1 name given back as the spec's, which the client asked
/// for.
fn name_spec_protocol(answer: &str) -> String {
    answer
        .split("\r\n")
        .map(|l| match l.split_once(':') {
            Some((k, v)) if is_protocol_line(l) && v.trim() == SDK_V1 => format!("{k}: {SPEC_V1}"),
            _ => l.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str =
        "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn a_spec_client_is_offered_the_sdk_name_and_answered_with_its_own() {
        let (request, renamed) = offer_sdk_name(REQUEST);
        assert!(renamed);
        assert!(
            request.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1, foxglove.sdk.v1\r\n")
        );
        assert!(request.ends_with("\r\n\r\n"), "the header still ends: {request:?}");
        let answer =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert_eq!(
            name_spec_protocol(answer),
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.websocket.v1\r\n\r\n"
        );
    }

    #[test]
    fn sdk_clients_and_others_pass_unchanged() {
        for request in [
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n",
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.websocket.v1, foxglove.sdk.v1.1\r\n\r\n",
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: chat\r\n\r\n",
            "GET / HTTP/1.1\r\nHost: x\r\n\r\n",
        ] {
            assert_eq!(offer_sdk_name(request), (request.to_owned(), false));
        }
    }
}
