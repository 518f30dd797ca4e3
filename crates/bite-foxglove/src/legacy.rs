//! The live view's front door: viewers that ask for the WebSocket
//! subprotocol by its older name, `foxglove.websocket.v1`, are let in.
//!
//! The Foxglove SDK's server accepts only `foxglove.sdk.v1` (and `.v1.1`)
//! and answers an older viewer's handshake with 400: Lichtblick before
//! December 2025, PlotJuggler, `roslibjs-foxglove`. The protocol is the
//! same under both names (the SDK's authors say so; Lichtblick's support
//! was adding the name). So the port the user is given is this front
//! door's: it reads each connection's HTTP upgrade request (at most
//! [`MAX_HEAD`] bytes, within [`HANDSHAKE_TIMEOUT`]), names the
//! subprotocol `foxglove.sdk.v1` when the viewer offered only the older
//! name, passes it to the SDK's server on a private loopback port, gives
//! the answer back under the name the viewer asked for, and from then on
//! copies bytes both ways untouched. A request it cannot read is passed on
//! as it is, for the SDK's server to answer.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

/// The older name of the subprotocol.
pub const LEGACY: &str = "foxglove.websocket.v1";
/// The name the SDK's server speaks.
const CURRENT: &str = "foxglove.sdk.v1";
/// An HTTP request or response head longer than this is not a handshake.
pub const MAX_HEAD: usize = 16 * 1024;
/// A viewer that has not sent its whole handshake by then is let go.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// Connections served at once; more are closed at once.
pub const MAX_CONNECTIONS: usize = 64;

/// The front door, listening.
pub struct Front {
    port: u16,
    stop: Arc<AtomicBool>,
}

impl Front {
    /// Listen on 127.0.0.1:`port` (0: any free port) and pass connections
    /// to the server at `inner`.
    pub fn start(port: u16, inner: SocketAddr) -> io::Result<Front> {
        let listener = TcpListener::bind(("127.0.0.1", port))?;
        let port = listener.local_addr()?.port();
        let stop = Arc::new(AtomicBool::new(false));
        let open = Arc::new(AtomicUsize::new(0));
        let stopping = stop.clone();
        std::thread::Builder::new()
            .name("foxglove-front".into())
            .spawn(move || {
                for conn in listener.incoming() {
                    if stopping.load(Ordering::Acquire) {
                        break;
                    }
                    let Ok(client) = conn else {
                        // Out of descriptors, say: wait for some to close.
                        std::thread::sleep(Duration::from_millis(10));
                        continue;
                    };
                    if open.load(Ordering::Acquire) >= MAX_CONNECTIONS {
                        continue; // dropped: closed
                    }
                    open.fetch_add(1, Ordering::AcqRel);
                    let done = open.clone();
                    let spawned = std::thread::Builder::new()
                        .name("foxglove-conn".into())
                        .spawn(move || {
                            let _ = serve(client, inner);
                            done.fetch_sub(1, Ordering::AcqRel);
                        });
                    if spawned.is_err() {
                        open.fetch_sub(1, Ordering::AcqRel);
                    }
                }
            })?;
        Ok(Front { port, stop })
    }

    /// The port viewers connect to.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Stop accepting viewers (those connected are ended by the SDK's
    /// server stopping).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Release);
        // Wake the accepting thread.
        let _ = TcpStream::connect(("127.0.0.1", self.port));
    }
}

impl Drop for Front {
    fn drop(&mut self) {
        if !self.stop.load(Ordering::Acquire) {
            self.stop();
        }
    }
}

/// One viewer's connection.
fn serve(client: TcpStream, inner: SocketAddr) -> io::Result<()> {
    client.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    let mut client_r = client.try_clone()?;
    let (head, rest) = read_head(&mut client_r)?;
    let (request, legacy) = match head.as_deref() {
        Some(h) => rename(h, true),
        None => (Vec::new(), false),
    };
    let server = TcpStream::connect(inner)?;
    server.set_nodelay(true)?;
    client.set_nodelay(true)?;
    let mut server_w = server.try_clone()?;
    // The request (none when unreadable), then what came after it.
    server_w.write_all(&request)?;
    server_w.write_all(&rest)?;
    // The answer's head, renamed back for a viewer that asked by the
    // older name.
    let mut server_r = server.try_clone()?;
    let mut client_w = client.try_clone()?;
    if legacy {
        server.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
        let (answer, after) = read_head(&mut server_r)?;
        server.set_read_timeout(None)?;
        if let Some(a) = answer {
            client_w.write_all(&rename(&a, false).0)?;
        }
        client_w.write_all(&after)?;
    }
    client.set_read_timeout(None)?;
    // Both ways, untouched, until either side ends.
    let up = std::thread::Builder::new()
        .name("foxglove-up".into())
        .spawn(move || {
            let _ = io::copy(&mut client_r, &mut server_w);
            let _ = server_w.shutdown(Shutdown::Write);
        })?;
    let _ = io::copy(&mut server_r, &mut client_w);
    let _ = client_w.shutdown(Shutdown::Both);
    let _ = server.shutdown(Shutdown::Both);
    let _ = up.join();
    Ok(())
}

/// Reads an HTTP head (through the blank line) from `r`: the head, and
/// what was read after it. `None` when the stream ended, or passed
/// [`MAX_HEAD`], before a blank line: everything read comes back as the
/// rest, to be passed on as it is.
fn read_head(r: &mut impl Read) -> io::Result<(Option<Vec<u8>>, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 4096];
    loop {
        let n = match r.read(&mut chunk) {
            Ok(0) => return Ok((None, buf)),
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        let from = buf.len().saturating_sub(3);
        buf.extend_from_slice(&chunk[..n]);
        if let Some(at) = (buf[from..].windows(4)).position(|w| w == b"\r\n\r\n") {
            let end = from + at + 4;
            let rest = buf.split_off(end);
            return Ok((Some(buf), rest));
        }
        if buf.len() > MAX_HEAD {
            return Ok((None, buf));
        }
    }
}

/// `head` with its `Sec-WebSocket-Protocol` header renamed, and whether
/// it was. A request (`to_current`) offering only the older name is
/// given the current one instead; an answer naming the current one is
/// given the older name back. Anything else is left as it is.
fn rename(head: &[u8], to_current: bool) -> (Vec<u8>, bool) {
    let Ok(text) = std::str::from_utf8(head) else {
        return (head.to_vec(), false);
    };
    let mut out = String::with_capacity(text.len() + 8);
    let mut renamed = false;
    for line in text.split_inclusive("\r\n") {
        let value = (line.split_once(':'))
            .filter(|(name, _)| name.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
            .map(|(_, v)| v.trim());
        let Some(value) = value else {
            out.push_str(line);
            continue;
        };
        let offered: Vec<&str> = value.split(',').map(str::trim).collect();
        let line_out = if to_current
            && offered.contains(&LEGACY)
            && !offered.iter().any(|p| p.starts_with("foxglove.sdk."))
        {
            let names: Vec<&str> = (offered.iter())
                .map(|&p| if p == LEGACY { CURRENT } else { p })
                .collect();
            Some(names.join(", "))
        } else if !to_current && offered == [CURRENT] {
            Some(LEGACY.to_string())
        } else {
            None
        };
        match line_out {
            Some(v) => {
                renamed = true;
                out.push_str("Sec-WebSocket-Protocol: ");
                out.push_str(&v);
                out.push_str("\r\n");
            }
            None => out.push_str(line),
        }
    }
    (out.into_bytes(), renamed)
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn the_older_name_is_renamed_both_ways_and_nothing_else() {
        let (req, legacy) = rename(REQUEST.as_bytes(), true);
        assert!(legacy);
        let req = String::from_utf8(req).expect("text");
        assert!(
            req.contains("Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n"),
            "{req}"
        );
        assert!(
            req.starts_with("GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n"),
            "{req}"
        );
        assert!(req.ends_with("\r\n\r\n"));
        // A viewer that offers the current name too is left as it is.
        let both = REQUEST.replace("websocket.v1", "websocket.v1, foxglove.sdk.v1");
        assert_eq!(
            rename(both.as_bytes(), true),
            (both.as_bytes().to_vec(), false)
        );
        // The answer gets the older name back.
        let answer =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        let (a, renamed) = rename(answer.as_bytes(), false);
        assert!(renamed);
        let a = String::from_utf8(a).expect("text");
        assert!(
            a.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n"),
            "{a}"
        );
        // Not text, or no such header: untouched.
        assert_eq!(rename(&[0xff, 0xfe], true), (vec![0xff, 0xfe], false));
        let plain = "GET / HTTP/1.1\r\n\r\n";
        assert!(!rename(plain.as_bytes(), true).1);
    }

    #[test]
    fn a_head_is_read_through_its_blank_line_and_no_further() {
        let mut input = REQUEST.as_bytes().to_vec();
        input.extend_from_slice(b"\x81\x02hi");
        let (head, rest) = read_head(&mut input.as_slice()).expect("reads");
        assert_eq!(head.as_deref(), Some(REQUEST.as_bytes()));
        assert_eq!(rest, b"\x81\x02hi");
        // Cut short, or far too long: no head, everything read kept.
        let (head, rest) = read_head(&mut &b"GET / HTTP/1.1\r\n"[..]).expect("reads");
        assert!(head.is_none());
        assert_eq!(rest, b"GET / HTTP/1.1\r\n");
        let long = vec![b'a'; MAX_HEAD + 5000];
        let (head, rest) = read_head(&mut long.as_slice()).expect("reads");
        assert!(head.is_none());
        assert!(rest.len() > MAX_HEAD);
    }

    #[test]
    fn the_front_door_passes_bytes_both_ways() {
        // A stand-in server: answers any head with a 101 naming the
        // current subprotocol, then echoes.
        let server = TcpListener::bind("127.0.0.1:0").expect("bind");
        let inner = server.local_addr().expect("addr");
        std::thread::spawn(move || {
            let (mut s, _) = server.accept().expect("accept");
            let (head, _) = read_head(&mut s).expect("head");
            let head = String::from_utf8(head.expect("a head")).expect("text");
            assert!(head.contains("foxglove.sdk.v1"), "{head}");
            s.write_all(b"HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\nhello")
                .expect("answer");
            let mut b = [0u8; 5];
            s.read_exact(&mut b).expect("frame");
            s.write_all(&b).expect("echo");
        });
        let front = Front::start(0, inner).expect("front");
        let mut c = TcpStream::connect(("127.0.0.1", front.port())).expect("connect");
        c.set_read_timeout(Some(Duration::from_secs(10)))
            .expect("timeout");
        c.write_all(REQUEST.as_bytes()).expect("request");
        let (head, mut after) = read_head(&mut c).expect("answer");
        let head = String::from_utf8(head.expect("a head")).expect("text");
        assert!(
            head.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1"),
            "{head}"
        );
        while after.len() < 5 {
            let mut b = [0u8; 16];
            let n = c.read(&mut b).expect("read");
            assert!(n > 0, "ended early");
            after.extend_from_slice(&b[..n]);
        }
        assert_eq!(after, b"hello");
        c.write_all(b"12345").expect("frame");
        let mut echo = [0u8; 5];
        c.read_exact(&mut echo).expect("echo");
        assert_eq!(&echo, b"12345");
        front.stop();
    }
}
