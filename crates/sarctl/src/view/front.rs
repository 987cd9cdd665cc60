//! The view's listening socket: a small TCP relay in front of the Foxglove
//! SDK's server, so that clients offering only the subprotocol
//! `foxglove.websocket.v1` are served too.
//!
//! The SDK's server accepts `foxglove.sdk.v1` and `foxglove.sdk.v1.1` and
//! answers HTTP 400 to anything else; `@foxglove/ws-protocol`'s client (its
//! default), Lichtblick up to 1.21 and open-source Foxglove Studio offer only
//! `foxglove.websocket.v1`, the same protocol under its published name. The
//! relay reads the client's HTTP upgrade request; when it offers
//! `foxglove.websocket.v1` and neither SDK name, it asks the server for
//! `foxglove.sdk.v1` and names the answer `foxglove.websocket.v1` again.
//! Every other request goes through unchanged. After the handshake it copies
//! bytes both ways (one thread per direction and connection); the server's
//! per-client queue still decides what a slow client loses.

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::time::Duration;

/// The published name of the Foxglove WebSocket protocol.
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The SDK server's name of the same protocol.
pub const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// The SDK server's names it accepts.
pub const SDK_SUBPROTOCOLS: [&str; 2] = [SDK_SUBPROTOCOL, "foxglove.sdk.v1.1"];
/// The most bytes of an HTTP head (request or response) the relay reads.
const MAX_HEAD: usize = 16 * 1024;
/// How long a client may take to send its upgrade request.
const HEAD_TIMEOUT: Duration = Duration::from_secs(10);

/// Listens on `bind` and relays every connection to the server at `backend`
/// (on its own thread). Returns the address it listens on.
pub fn start(bind: SocketAddr, backend: SocketAddr) -> std::io::Result<SocketAddr> {
    let listener = TcpListener::bind(bind)?;
    let local = listener.local_addr()?;
    std::thread::Builder::new()
        .name("view-front".into())
        .spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else {
                    // Out of descriptors or the like: wait, do not spin.
                    std::thread::sleep(Duration::from_millis(50));
                    continue;
                };
                let _ = std::thread::Builder::new()
                    .name("view-conn".into())
                    .spawn(move || {
                        if let Err(e) = relay(client, backend) {
                            tracing::debug!("view connection: {e}");
                        }
                    });
            }
        })?;
    Ok(local)
}

/// Reads an HTTP head (up to and including the blank line); returns it and
/// any bytes read after it.
fn read_head(stream: &mut TcpStream) -> std::io::Result<(Vec<u8>, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
        }
        if buf.len() > MAX_HEAD {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "HTTP head too long",
            ));
        }
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(chunk.get(..n).unwrap_or_default());
    }
}

/// The request head with the subprotocol offer rewritten for the SDK's
/// server, and whether it was.
pub fn rewrite_request(head: &str) -> (String, bool) {
    let mut rewritten = false;
    let lines: Vec<String> = head
        .split("\r\n")
        .map(|line| match line.split_once(':') {
            Some((name, value)) if name.trim().eq_ignore_ascii_case("sec-websocket-protocol") => {
                let offered: Vec<&str> = value.split(',').map(str::trim).collect();
                let sdk = offered.iter().any(|o| SDK_SUBPROTOCOLS.contains(o));
                if !sdk && offered.contains(&LEGACY_SUBPROTOCOL) {
                    rewritten = true;
                    format!("{name}: {}", SDK_SUBPROTOCOL)
                } else {
                    line.to_owned()
                }
            }
            _ => line.to_owned(),
        })
        .collect();
    (lines.join("\r\n"), rewritten)
}

/// The response head with the server's choice named as the client offered it.
pub fn rewrite_response(head: &str) -> String {
    head.split("\r\n")
        .map(|line| match line.split_once(':') {
            Some((name, value))
                if name.trim().eq_ignore_ascii_case("sec-websocket-protocol")
                    && value.trim() == SDK_SUBPROTOCOL =>
            {
                format!("{name}: {LEGACY_SUBPROTOCOL}")
            }
            _ => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

fn relay(mut client: TcpStream, backend: SocketAddr) -> std::io::Result<()> {
    client.set_nodelay(true)?;
    client.set_read_timeout(Some(HEAD_TIMEOUT))?;
    let (head, rest) = read_head(&mut client)?;
    let (head, legacy) = rewrite_request(&String::from_utf8_lossy(&head));
    let mut server = TcpStream::connect(backend)?;
    server.set_nodelay(true)?;
    server.write_all(head.as_bytes())?;
    server.write_all(&rest)?;
    server.set_read_timeout(Some(HEAD_TIMEOUT))?;
    let (answer, rest) = read_head(&mut server)?;
    let answer = String::from_utf8_lossy(&answer).into_owned();
    let answer = if legacy {
        rewrite_response(&answer)
    } else {
        answer
    };
    client.write_all(answer.as_bytes())?;
    client.write_all(&rest)?;
    client.set_read_timeout(None)?;
    server.set_read_timeout(None)?;
    let (mut client_in, mut server_out) = (client.try_clone()?, server.try_clone()?);
    let upstream = std::thread::Builder::new()
        .name("view-conn-up".into())
        .spawn(move || {
            let _ = std::io::copy(&mut client_in, &mut server_out);
            let _ = server_out.shutdown(Shutdown::Write);
        })?;
    let _ = std::io::copy(&mut server, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = server.shutdown(Shutdown::Both);
    let _ = upstream.join();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_legacy_offer_is_rewritten() {
        let req =
            "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";
        let (out, legacy) = rewrite_request(req);
        assert!(legacy);
        assert!(
            out.contains("\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n"),
            "{out}"
        );
        assert!(out.ends_with("\r\n\r\n"));
        for offer in [
            "foxglove.sdk.v1",
            "foxglove.websocket.v1, foxglove.sdk.v1.1",
            "other",
        ] {
            let req = format!("GET / HTTP/1.1\r\nsec-websocket-protocol: {offer}\r\n\r\n");
            assert_eq!(rewrite_request(&req), (req.clone(), false));
        }
        let resp =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert_eq!(
            rewrite_response(resp),
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.websocket.v1\r\n\r\n"
        );
    }
}
