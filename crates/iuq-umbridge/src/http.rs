//! The server side of HTTP/1.1, as much as UM-Bridge needs: requests with a `Content-Length` or
//! a chunked body, keep-alive, `Expect: 100-continue`, and responses with a `Content-Length`.
//!
//! Why not a server crate: hyper/axum bring an async runtime (tokio) and minutes of compile
//! time for a server that runs one blocking model call per request; tiny_http (the obvious
//! small blocking server) drains the unread rest of a refused body on drop by allocating a
//! buffer of the whole declared `Content-Length`, so one request claiming a 10¹⁴-byte body
//! aborts the process — the body-size limit could not be enforced safely. Parsing is done by
//! `httparse` (hyper's parser, no dependencies); this module adds the framing with hard limits
//! on every length read from the network:
//! - the request head (request line + headers) is at most [`Limits::max_head_bytes`], at most
//!   [`MAX_HEADERS`] headers (431 otherwise);
//! - a body larger than [`Limits::max_body_bytes`] is refused with 413 before it is read (a
//!   declared length) or as soon as the limit is passed (chunked), and the connection is closed
//!   without reading the rest;
//! - a request with both `Transfer-Encoding` and `Content-Length`, an unknown transfer coding,
//!   or an unparsable length is refused with 400 and the connection closed (no request
//!   smuggling: the framing is never guessed).

use std::io::{self, BufRead, Read, Write};

use crate::protocol::ErrorAnswer;

/// The most headers a request may have.
pub const MAX_HEADERS: usize = 64;

/// Size limits on what is read from a connection.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Request line and headers together.
    pub max_head_bytes: usize,
    /// The body.
    pub max_body_bytes: usize,
}

/// A request read from a connection.
#[derive(Debug)]
pub struct Request {
    /// The method (`GET`, `POST`…).
    pub method: String,
    /// The path without the query string.
    pub path: String,
    /// The body (empty when there is none).
    pub body: Vec<u8>,
    /// Whether the client keeps the connection open after the response.
    pub keep_alive: bool,
}

/// What reading the next request gave.
#[derive(Debug)]
pub enum Incoming {
    /// A complete request.
    Request(Request),
    /// The client closed the connection before starting another request.
    Closed,
    /// A request that is refused as read (too large, malformed framing); answer it with this
    /// error and close the connection.
    Refused(ErrorAnswer),
}

/// Reads one line (up to and including `\n`) of at most `limit` bytes; `None` at EOF before any
/// byte. A line longer than the limit gives `Ok(Some(line))` without its `\n`, which callers
/// detect.
fn read_line_limited<R: BufRead>(reader: &mut R, limit: usize) -> io::Result<Option<Vec<u8>>> {
    let mut line = Vec::new();
    let read = reader
        .by_ref()
        .take(limit as u64)
        .read_until(b'\n', &mut line)?;
    if read == 0 {
        return Ok(None);
    }
    Ok(Some(line))
}

fn too_large_head(limits: &Limits) -> ErrorAnswer {
    ErrorAnswer::invalid_input(format!(
        "request head larger than {} bytes or with more than {MAX_HEADERS} headers",
        limits.max_head_bytes
    ))
    .with_status(431)
}

fn body_too_large(limits: &Limits, length: Option<u64>) -> ErrorAnswer {
    let size = match length {
        Some(n) => format!("{n} bytes"),
        None => "more".to_string(),
    };
    ErrorAnswer::invalid_input(format!(
        "request body of {size} is larger than the limit of {} bytes",
        limits.max_body_bytes
    ))
    .with_status(413)
}

/// Reads the next request from `reader`. `interim` receives `100 Continue` when the client
/// asked for it and the declared body is within the limits.
pub fn read_request<R: BufRead, W: Write>(
    reader: &mut R,
    interim: &mut W,
    limits: &Limits,
) -> io::Result<Incoming> {
    let head = match read_head(reader, limits)? {
        Ok(head) => head,
        Err(incoming) => return Ok(incoming),
    };
    let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
    let mut parsed = httparse::Request::new(&mut headers);
    match parsed.parse(&head) {
        Ok(httparse::Status::Complete(_)) => {}
        Ok(httparse::Status::Partial) => {
            return Ok(Incoming::Refused(ErrorAnswer::invalid_input(
                "incomplete HTTP request head",
            )));
        }
        Err(httparse::Error::TooManyHeaders) => {
            return Ok(Incoming::Refused(too_large_head(limits)));
        }
        Err(e) => {
            return Ok(Incoming::Refused(ErrorAnswer::invalid_input(format!(
                "malformed HTTP request: {e}"
            ))));
        }
    }
    let method = parsed.method.unwrap_or("").to_string();
    let target = parsed.path.unwrap_or("/");
    let path = target.split(['?', '#']).next().unwrap_or("/").to_string();
    let http_1_1 = parsed.version == Some(1);
    let framing = match Framing::of(parsed.headers, http_1_1) {
        Ok(framing) => framing,
        Err(refusal) => return Ok(Incoming::Refused(refusal)),
    };
    let body = match framing.read_body(reader, interim, limits)? {
        Ok(body) => body,
        Err(refusal) => return Ok(Incoming::Refused(refusal)),
    };
    Ok(Incoming::Request(Request {
        method,
        path,
        body,
        keep_alive: framing.keep_alive,
    }))
}

/// Reads the request head: the lines up to the empty line, at most `max_head_bytes` in total
/// (empty lines before the request line skipped). `Ok(Err(incoming))` when there is no head to
/// parse: the connection closed before a request, or a head too large.
fn read_head<R: BufRead>(reader: &mut R, limits: &Limits) -> io::Result<Result<Vec<u8>, Incoming>> {
    let mut head = Vec::new();
    loop {
        let remaining = limits.max_head_bytes.saturating_sub(head.len());
        if remaining == 0 {
            return Ok(Err(Incoming::Refused(too_large_head(limits))));
        }
        let Some(line) = read_line_limited(reader, remaining)? else {
            if head.is_empty() {
                return Ok(Err(Incoming::Closed));
            }
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "connection closed inside a request head",
            ));
        };
        if !line.ends_with(b"\n") {
            // Longer than what is left of the limit (or EOF inside a line).
            if line.len() >= remaining {
                return Ok(Err(Incoming::Refused(too_large_head(limits))));
            }
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "connection closed inside a request head",
            ));
        }
        let blank = line == b"\r\n" || line == b"\n";
        if blank && head.is_empty() {
            // Robustness (RFC 9112 §2.2): ignore empty lines before the request line.
            continue;
        }
        head.extend_from_slice(&line);
        if blank {
            return Ok(Ok(head));
        }
    }
}

/// What a request's headers say about its body and its connection.
struct Framing {
    keep_alive: bool,
    content_length: Option<u64>,
    /// The transfer codings of every `Transfer-Encoding` header, comma-separated.
    transfer_encoding: Option<String>,
    expect_continue: bool,
}

impl Framing {
    /// Reads the framing headers (a connection is kept alive by default from HTTP/1.1 on);
    /// `Err` for an invalid or conflicting `Content-Length` or an unsupported `Expect`.
    fn of(headers: &[httparse::Header], http_1_1: bool) -> Result<Self, ErrorAnswer> {
        let mut framing = Self {
            keep_alive: http_1_1,
            content_length: None,
            transfer_encoding: None,
            expect_continue: false,
        };
        for h in headers {
            let value = String::from_utf8_lossy(h.value).trim().to_ascii_lowercase();
            if h.name.eq_ignore_ascii_case("connection") {
                for token in value.split(',').map(str::trim) {
                    if token == "close" {
                        framing.keep_alive = false;
                    } else if token == "keep-alive" {
                        framing.keep_alive = true;
                    }
                }
            } else if h.name.eq_ignore_ascii_case("content-length") {
                let length = if !value.is_empty() && value.bytes().all(|b| b.is_ascii_digit()) {
                    value.parse::<u64>().ok()
                } else {
                    None
                };
                match (length, framing.content_length) {
                    (None, _) => {
                        return Err(ErrorAnswer::invalid_input(format!(
                            "invalid Content-Length `{value}`"
                        )));
                    }
                    (Some(n), Some(m)) if n != m => {
                        return Err(ErrorAnswer::invalid_input(
                            "conflicting Content-Length headers",
                        ));
                    }
                    (Some(n), _) => framing.content_length = Some(n),
                }
            } else if h.name.eq_ignore_ascii_case("transfer-encoding") {
                framing.transfer_encoding = Some(match framing.transfer_encoding {
                    Some(previous) => format!("{previous}, {value}"),
                    None => value,
                });
            } else if h.name.eq_ignore_ascii_case("expect") {
                if value == "100-continue" {
                    framing.expect_continue = true;
                } else {
                    return Err(
                        ErrorAnswer::invalid_input(format!("unsupported Expect: {value}"))
                            .with_status(417),
                    );
                }
            }
        }
        Ok(framing)
    }

    /// Reads the body as framed (none without a length or coding), sending `100 Continue` to
    /// `interim` first where it was asked for; `Ok(Err(refusal))` for a body over the limit,
    /// an unsupported coding or ambiguous framing.
    fn read_body<R: BufRead, W: Write>(
        &self,
        reader: &mut R,
        interim: &mut W,
        limits: &Limits,
    ) -> io::Result<Result<Vec<u8>, ErrorAnswer>> {
        match (&self.transfer_encoding, self.content_length) {
            (Some(_), Some(_)) => Ok(Err(ErrorAnswer::invalid_input(
                "a request must not have both Transfer-Encoding and Content-Length",
            ))),
            (Some(coding), None) => {
                if coding.rsplit(',').next().map(str::trim) != Some("chunked")
                    || coding.split(',').count() != 1
                {
                    return Ok(Err(ErrorAnswer::invalid_input(format!(
                        "unsupported Transfer-Encoding `{coding}` (only chunked)"
                    ))));
                }
                if self.expect_continue {
                    send_continue(interim)?;
                }
                read_chunked(reader, limits)
            }
            (None, Some(length)) => {
                if length > limits.max_body_bytes as u64 {
                    return Ok(Err(body_too_large(limits, Some(length))));
                }
                if self.expect_continue && length > 0 {
                    send_continue(interim)?;
                }
                // length ≤ max_body_bytes, so it fits in memory as the operator allowed.
                let mut body = vec![0; length as usize];
                reader.read_exact(&mut body)?;
                Ok(Ok(body))
            }
            (None, None) => Ok(Ok(Vec::new())),
        }
    }
}

fn send_continue<W: Write>(writer: &mut W) -> io::Result<()> {
    writer.write_all(b"HTTP/1.1 100 Continue\r\n\r\n")?;
    writer.flush()
}

/// Reads a chunked body; `Ok(Err(refusal))` when it passes the size limit or is malformed.
fn read_chunked<R: BufRead>(
    reader: &mut R,
    limits: &Limits,
) -> io::Result<Result<Vec<u8>, ErrorAnswer>> {
    const MAX_LINE: usize = 4096;
    let malformed = |what: &str| {
        Ok(Err(ErrorAnswer::invalid_input(format!(
            "malformed chunked body: {what}"
        ))))
    };
    let mut body = Vec::new();
    loop {
        let Some(line) = read_line_limited(reader, MAX_LINE)? else {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "EOF in chunked body",
            ));
        };
        if !line.ends_with(b"\n") {
            return malformed("chunk-size line too long");
        }
        let text = String::from_utf8_lossy(&line);
        let size_text = text.split(';').next().unwrap_or("").trim();
        let Ok(size) = u64::from_str_radix(size_text, 16) else {
            return malformed("invalid chunk size");
        };
        if size == 0 {
            // Trailer fields, up to the empty line.
            let mut trailer = 0usize;
            loop {
                let Some(line) = read_line_limited(reader, MAX_LINE)? else {
                    return Err(io::Error::new(
                        io::ErrorKind::UnexpectedEof,
                        "EOF in trailer",
                    ));
                };
                trailer += line.len();
                if line == b"\r\n" || line == b"\n" {
                    return Ok(Ok(body));
                }
                if !line.ends_with(b"\n") || trailer > limits.max_head_bytes {
                    return malformed("trailer too long");
                }
            }
        }
        if (body.len() as u64).saturating_add(size) > limits.max_body_bytes as u64 {
            return Ok(Err(body_too_large(limits, None)));
        }
        let start = body.len();
        body.resize(start + size as usize, 0);
        reader.read_exact(&mut body[start..])?;
        let mut crlf = [0u8; 2];
        reader.read_exact(&mut crlf[..1])?;
        if crlf[0] == b'\r' {
            reader.read_exact(&mut crlf[1..])?;
        }
        if !(crlf == *b"\r\n" || crlf[0] == b'\n') {
            return malformed("missing CRLF after chunk data");
        }
    }
}

/// The reason phrase of the statuses this server answers with.
fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        413 => "Content Too Large",
        417 => "Expectation Failed",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "Unknown",
    }
}

/// Writes a complete JSON response in one `write_all` (head and body together).
pub fn write_response<W: Write>(
    writer: &mut W,
    status: u16,
    body: &str,
    keep_alive: bool,
) -> io::Result<()> {
    let mut out = format!(
        "HTTP/1.1 {status} {}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: {}\r\n\r\n",
        reason(status),
        body.len(),
        if keep_alive { "keep-alive" } else { "close" }
    )
    .into_bytes();
    out.extend_from_slice(body.as_bytes());
    writer.write_all(&out)?;
    writer.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits {
        max_head_bytes: 1024,
        max_body_bytes: 64,
    };

    fn read(raw: &[u8]) -> (io::Result<Incoming>, Vec<u8>) {
        let mut reader = io::BufReader::new(raw);
        let mut interim = Vec::new();
        (read_request(&mut reader, &mut interim, &LIMITS), interim)
    }

    fn request(raw: &[u8]) -> Request {
        match read(raw).0 {
            Ok(Incoming::Request(r)) => r,
            other => panic!("{other:?}"),
        }
    }

    fn refused(raw: &[u8]) -> ErrorAnswer {
        match read(raw).0 {
            Ok(Incoming::Refused(e)) => e,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn requests_with_length_chunked_and_none() {
        let r = request(b"POST /Evaluate?x=1 HTTP/1.1\r\nHost: a\r\nContent-Length: 4\r\n\r\nabcd");
        assert_eq!((r.method.as_str(), r.path.as_str()), ("POST", "/Evaluate"));
        assert_eq!(r.body, b"abcd");
        assert!(r.keep_alive);
        let r = request(
            b"\r\nPOST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n3;x=y\r\nabc\r\n2\r\nde\r\n0\r\nT: v\r\n\r\n",
        );
        assert_eq!(r.body, b"abcde");
        let r = request(b"GET /Info HTTP/1.0\r\n\r\n");
        assert!(r.body.is_empty() && !r.keep_alive);
        let r = request(b"GET /Info HTTP/1.1\r\nConnection: close\r\n\r\n");
        assert!(!r.keep_alive);
        assert!(matches!(read(b"").0, Ok(Incoming::Closed)));
    }

    #[test]
    fn expect_continue_is_answered_only_for_acceptable_bodies() {
        let (r, interim) =
            read(b"POST / HTTP/1.1\r\nExpect: 100-continue\r\nContent-Length: 2\r\n\r\nab");
        assert!(matches!(r, Ok(Incoming::Request(_))));
        assert_eq!(interim, b"HTTP/1.1 100 Continue\r\n\r\n");
        let (r, interim) =
            read(b"POST / HTTP/1.1\r\nExpect: 100-continue\r\nContent-Length: 99999999999\r\n\r\n");
        assert!(matches!(r, Ok(Incoming::Refused(ref e)) if e.status == 413));
        assert!(interim.is_empty());
    }

    #[test]
    fn oversized_and_malformed_requests_are_refused() {
        assert_eq!(
            refused(b"POST / HTTP/1.1\r\nContent-Length: 100000000000000000\r\n\r\n").status,
            413
        );
        let mut chunked = b"POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n".to_vec();
        for _ in 0..10 {
            chunked.extend_from_slice(b"10\r\n0123456789abcdef\r\n");
        }
        assert_eq!(refused(&chunked).status, 413);
        let mut long = b"GET /".to_vec();
        long.extend(std::iter::repeat_n(b'a', 2000));
        long.extend_from_slice(b" HTTP/1.1\r\n\r\n");
        assert_eq!(refused(&long).status, 431);
        let mut many = b"GET / HTTP/1.1\r\n".to_vec();
        for i in 0..70 {
            many.extend_from_slice(format!("h{i}: v\r\n").as_bytes());
        }
        many.extend_from_slice(b"\r\n");
        assert_eq!(
            read_request(
                &mut io::BufReader::new(&many[..]),
                &mut Vec::new(),
                &Limits {
                    max_head_bytes: 1 << 16,
                    max_body_bytes: 64
                }
            )
            .map(|i| matches!(i, Incoming::Refused(e) if e.status == 431))
            .ok(),
            Some(true)
        );
        assert_eq!(
            refused(b"POST / HTTP/1.1\r\nContent-Length: 1\r\nTransfer-Encoding: chunked\r\n\r\n")
                .status,
            400
        );
        assert_eq!(
            refused(b"POST / HTTP/1.1\r\nContent-Length: -1\r\n\r\n").status,
            400
        );
        assert_eq!(
            refused(b"POST / HTTP/1.1\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\n").status,
            400
        );
        assert_eq!(
            refused(b"POST / HTTP/1.1\r\nTransfer-Encoding: gzip\r\n\r\n").status,
            400
        );
        assert_eq!(refused(b"NOT HTTP AT ALL\r\n\r\n").status, 400);
        assert_eq!(
            refused(b"POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n").status,
            400
        );
        assert!(
            read(b"POST / HTTP/1.1\r\nContent-Length: 10\r\n\r\nabc")
                .0
                .is_err()
        );
    }

    #[test]
    fn responses_carry_length_and_connection() {
        let mut out = Vec::new();
        write_response(&mut out, 413, "{}", false).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.starts_with("HTTP/1.1 413 Content Too Large\r\n"));
        assert!(text.contains("Content-Length: 2\r\n") && text.contains("Connection: close\r\n"));
        assert!(text.ends_with("\r\n\r\n{}"));
    }
}
